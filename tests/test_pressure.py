"""Pressure and temperature from the collisions: the sums each step records, and the
equation of state read off a recording."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import api, open_recording
from physdbg.analysis.pressure import carnahan_starling, collision_sums, equation_of_state
from physdbg.cli import app
from physdbg.events import KIND_PAIR, KIND_WALL, Contacts


def _contacts(kind, a, other, impulse):
    c = Contacts.empty(0, len(kind))
    c.kind[:], c.a[:], c.other[:], c.impulse[:] = kind, a, other, impulse
    c.restitution[:] = c.closing_speed[:] = 1.0
    return c


def test_the_sums_are_r_dot_j_over_pairs_and_the_impulses_at_walls():
    radius = np.array([0.1, 0.2, 0.3])
    c = _contacts([KIND_PAIR, KIND_PAIR, KIND_WALL], [0, 1, 2], [1, 2, 0], [2.0, 3.0, 5.0])
    virial, wall, collisions = collision_sums(c, radius)
    assert virial == pytest.approx(0.3 * 2.0 + 0.5 * 3.0) and wall == 5.0 and collisions == 2
    assert collision_sums(_contacts([], [], [], []), radius) == (0.0, 0.0, 0)


def test_a_head_on_collision_records_its_virial(tmp_path):
    # two 1 kg spheres (r = 0.5) meet at 2 m/s closing, e = 1: j = 2 N·s, r_ab·J = 1 m × 2 N·s
    result = api.record("cradle", ["particles.2.position=[20.0, 0.0, 0.0]", "particles.3.position=[30.0, 0.0, 0.0]",
                                   "particles.4.position=[40.0, 0.0, 0.0]", "particles.1.velocity=[-1.0, 0.0, 0.0]",
                                   "particles.0.velocity=[1.0, 0.0, 0.0]"],
                        mcap_path=str(tmp_path / "two.mcap"), rrd=False, detail="state")
    stats = open_recording(result.mcap).stats()
    assert stats["virial"].sum() == pytest.approx(2.0, rel=1e-12)
    assert np.count_nonzero(stats["virial"]) == 1 and stats["wall_impulse"].sum() == 0
    assert np.allclose(stats["temperature"], 2 * stats["kinetic"] / (3 * 5))


def test_a_hard_sphere_gas_reads_close_to_carnahan_starling(tmp_path):
    """A loose check (walls and 500 spheres shift Z by a few %; the table in the docs is for
    periodic boxes, not built yet): Z from the collisions within 8 % of Carnahan–Starling."""
    result = api.record("gas", ["generate.count=500", "duration=3"], mcap_path=str(tmp_path / "gas.mcap"),
                        rrd=False, detail="state", view=False)
    eos = equation_of_state(open_recording(result.mcap))
    assert eos.packing_fraction == pytest.approx(0.1) and eos.z_carnahan_starling == pytest.approx(carnahan_starling(0.1))
    assert abs(eos.z_virial / eos.z_carnahan_starling - 1) < 0.08 and 0 < eos.z_virial_error < 0.05
    assert abs(eos.z_wall / eos.z_carnahan_starling - 1) < 0.15
    assert eos.kT == pytest.approx(1.0 / 3.0, rel=1e-9)  # e = 1, no gravity: every sphere's mean speed² is 1
    done = CliRunner().invoke(app, ["info", result.mcap])
    assert done.exit_code == 0 and "pressure    Z = PV/NkT = " in done.output
    assert "Carnahan–Starling at packing fraction 0.1: Z = 1.5213" in done.output


@pytest.mark.slow
def test_a_pile_that_fell_asleep_has_no_equation_of_state_and_info_says_nothing_of_one(tmp_path):
    """Nothing moves once a pile sleeps (engine/sleep.py): no temperature to divide by, so
    no Z (the ValueError says why) and no NaN or RuntimeWarning in `physdbg info`."""
    import warnings

    pile = ["generate.count=100", "box.max=[0.3,1,0.3]", "generate.speed=0", "generate.restitution=0.5",
            "box.restitution=0.5", "rapid_contact_rule=tc", "sleep_speed=0.05", "sleep_time=0.1", "steps=240"]
    result = api.record("rain", pile, mcap_path=str(tmp_path / "pile.mcap"), rrd=False, detail="state", view=False)
    assert result.summary.asleep_at_end == 100
    with pytest.raises(ValueError, match=r"nothing moves in steps \d+\.\.\d+: no temperature"):
        equation_of_state(open_recording(result.mcap))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning from a division by zero fails the test
        done = CliRunner().invoke(app, ["info", result.mcap])
    assert done.exit_code == 0 and "pressure" not in done.output and "nan" not in done.output
    assert "sleep       100 of 100 spheres asleep at the end (sleep_speed 0.05 m/s)" in done.output
