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


def test_the_views_frame_a_turning_mesh_s_whole_sweep(tmp_path):
    """A 3 m blade turning about its middle with no walls around it: the box every view is
    framed on holds every point the blade reaches in a turn (it once held only the blade as
    it started, and the diff overlay cut the mesh off)."""
    from physdbg.api import ready_scene
    from physdbg.record.header import RecordingHeader
    from physdbg.record.view import scene_bounds

    scene = tmp_path / "blade.toml"
    scene.write_text('name = "blade"\ndt = "1/60"\nsteps = 10\n[[meshes]]\nname = "blade"\nshape = "paddle"\n'
                     'scale = [3.0, 1.0, 1.0]\nangular_velocity = [0.0, 360.0, 0.0]\n'
                     '[[particles]]\nposition = [0.0, 1.0, 0.0]\nradius = 0.05\n')
    header = RecordingHeader.from_scene(ready_scene(str(scene)))
    lo, hi = scene_bounds(header)
    meshes = header.walls.meshes
    reach = float(meshes.turn_radii()[0])
    for degrees in range(0, 360, 15):  # the blade's corners at every 15° of its turn
        corners = meshes.placed(degrees / 360.0)[0].reshape(-1, 3)
        assert np.all(corners >= lo - 1e-9) and np.all(corners <= hi + 1e-9), (degrees, reach)


def test_a_file_that_opens_at_a_finding_frames_the_finding_not_the_whole_scene(tmp_path, monkeypatch):
    """The plate of docs/examples/meshes: a ball at 1,000 m/s tunnels through a 2 m plate 25 m
    from where it starts. The Rerun file opens at the finding with the eye on the plate and
    the ball's path near it, not on the 25 m scene."""
    from pathlib import Path

    from physdbg import api
    from physdbg.record import rerun_sink, view

    seen = []
    original = rerun_sink.blueprint

    def spy(header, opening=None, search_empty=None, playing=False, focus=None):
        seen.append((opening, focus, rerun_sink.camera(header, 1.0, focus), rerun_sink.camera(header, 1.0)))
        return original(header, opening, search_empty, playing, focus)

    monkeypatch.setattr(rerun_sink, "blueprint", spy)
    scene = Path(__file__).resolve().parents[1] / "docs" / "examples" / "meshes" / "plate.toml"
    api.record(str(scene), mcap_path=str(tmp_path / "plate.mcap"), rrd=str(tmp_path / "plate.rrd"))
    opening, focus, framed, whole = seen[-1]  # (the one sent when the file is closed)
    assert opening[0] == rerun_sink.FIRST_FINDING_TIMELINE and focus is not None
    centre, extent = focus
    assert abs(centre[2]) < 1e-9 and 2.0 <= extent <= 10.0  # on the plate (z = 0), about its size

    def eye_distance(eye):
        return float(np.linalg.norm(np.subtract(eye.position.as_arrow_array().to_pylist()[0],
                                                eye.look_target.as_arrow_array().to_pylist()[0])))

    assert eye_distance(framed) < 0.5 * eye_distance(whole)
    import physdbg

    assert view.finding_frame(physdbg.open_recording(tmp_path / "plate.mcap").header, type(
        "F", (), {"position": None, "particles": [0], "evidence": {}})()) is None
