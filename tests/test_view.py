"""What both pictures (Rerun and Foxglove) say in words and colours: physdbg/record/view.py."""

from __future__ import annotations

import numpy as np

from physdbg.record.view import ASLEEP_COLOR, SLEEP_IDS_PER_LINE, describe_sleep, sleep_changed, sphere_colors


def test_sleep_lines_name_who_fell_asleep_and_who_woke_and_count_the_rest():
    n = 40
    before = np.zeros(n, dtype=bool)
    before[[1, 2]] = True
    after = np.zeros(n, dtype=bool)
    after[[2] + list(range(10, 10 + SLEEP_IDS_PER_LINE + 3))] = True
    lines = describe_sleep(7, before, after)
    fell = ", ".join(str(i) for i in range(10, 10 + SLEEP_IDS_PER_LINE))
    assert lines == [(f"step 7: {SLEEP_IDS_PER_LINE + 3} spheres fell asleep: {fell} and 3 more", "INFO"),
                     ("step 7: 1 sphere woke: 1", "INFO")]
    assert describe_sleep(8, after, after) == []
    assert describe_sleep(1, None, None) == []  # a run without sleeping says nothing


def test_sleep_changed_treats_no_mask_as_none_asleep():
    none_asleep, one = np.zeros(3, dtype=bool), np.array([False, True, False])
    assert not sleep_changed(None, None) and not sleep_changed(None, none_asleep)
    assert sleep_changed(None, one) and sleep_changed(one, None) and sleep_changed(one, none_asleep)
    assert not sleep_changed(one, one.copy())


def test_asleep_spheres_are_grey_blue_and_immovable_ones_stay_grey():
    inverse_mass = np.array([1.0, 1.0, 0.0])
    colors = sphere_colors(inverse_mass, np.array([False, True, True]))
    assert colors[0].tolist() == [240, 140, 50] and tuple(colors[1]) == ASLEEP_COLOR
    assert colors[2].tolist() == [140, 140, 140]
