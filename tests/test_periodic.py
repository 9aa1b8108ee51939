"""Periodic boundaries: minimum image, wrapping, the periodic broad phase, exact contacts
across a face, a hard-sphere gas against Carnahan–Starling and Enskog, scene errors, and
recordings that replay, verify and audit."""

from __future__ import annotations


import numpy as np
import pytest
from typer.testing import CliRunner

import physdbg
from physdbg import api
from physdbg.analysis.pressure import carnahan_starling, enskog_collision_rate, equation_of_state
from physdbg.analysis.tunnel import StepChecker
from physdbg.cli import app
from physdbg.engine import BruteForce, Settings, State, Walls, World
from physdbg.engine.broadphase.boxes import boxes_meet
from physdbg.engine.broadphase.periodic import PeriodicBroadPhase
from physdbg.engine.periodic import image, minimum_image, unwrap_near, wrap_positions
from physdbg.errors import SceneError
from physdbg.events import KIND_PAIR, Contacts
from physdbg.observe import ListObserver
from physdbg.api import load_scene

runner = CliRunner()


def periodic_walls(side: float, axes=(True, True, True)) -> Walls:
    """No walls; periodic with period ``side`` on ``axes`` (origin 0)."""
    return Walls([], np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool), np.zeros(0),
                 np.where(axes, side, 0.0), np.zeros(3))


def state_of(positions, velocities, radius=0.1) -> State:
    n = len(positions)
    return State(np.array(positions, dtype=float), np.array(velocities, dtype=float), np.ones(n),
                 np.full(n, radius), np.ones(n), np.ones(n))


# --------------------------------------------------------------------------- the image
def test_minimum_image_and_wrapping():
    assert image(0.9, 1.0) == pytest.approx(-0.1)
    assert image(-0.6, 1.0) == pytest.approx(0.4)
    assert image(0.9, 0.0) == 0.9  # not periodic
    d = minimum_image(np.array([[0.9, -0.9, 0.9]]), np.array([1.0, 1.0, 0.0]))
    np.testing.assert_allclose(d, [[-0.1, 0.1, 0.9]])
    x = np.array([[1.25, -0.25, 7.0], [0.0, 0.999, -3.0]])
    wrap_positions(x, np.zeros(3), np.array([1.0, 1.0, 0.0]))
    np.testing.assert_allclose(x, [[0.25, 0.75, 7.0], [0.0, 0.999, -3.0]])
    assert np.all((x[:, :2] >= 0) & (x[:, :2] < 1))
    tiny = np.array([[-1e-18, 0.0, 0.0]])  # rounds to the period itself: wrapped to 0, not to L
    wrap_positions(tiny, np.zeros(3), np.ones(3))
    assert 0.0 <= tiny[0, 0] < 1.0
    np.testing.assert_allclose(unwrap_near(np.array([0.05, 0.5, 0.5]), np.array([0.95, 0.5, 0.5]), np.ones(3)),
                               [1.05, 0.5, 0.5])


def test_the_periodic_broad_phase_finds_exactly_the_pairs_that_meet_through_a_face():
    rng = np.random.default_rng(3)
    period = np.array([1.0, 1.0, 0.0])
    for _ in range(20):
        centre = rng.uniform(0.0, 1.0, (60, 3))
        half = rng.uniform(0.01, 0.2, (60, 3))
        lo, hi = centre - half, centre + half
        pairs = PeriodicBroadPhase(BruteForce(), np.zeros(3), period).pairs(lo, hi)
        expected = {(i, j) for i in range(60) for j in np.nonzero(boxes_meet(lo, hi, lo[i], hi[i], period))[0]
                    if i < j}
        assert {tuple(p) for p in pairs.tolist()} == expected
        assert np.all(pairs[:, 0] < pairs[:, 1]) and len(np.unique(pairs, axis=0)) == len(pairs)
        # some of them only meet through a face
        assert any(not np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i])) for i, j in expected)


# --------------------------------------------------------------------------- exact motion
def test_a_free_sphere_leaves_through_one_face_and_comes_back_through_the_other():
    world = World(state_of([[0.5, 0.5, 0.5]], [[3.7, -1.3, 0.0]]), periodic_walls(1.0), Settings(gravity=(0, 0, 0)))
    for _ in range(100):
        world.step(0.01)
    exact = np.mod(np.array([0.5 + 3.7, 0.5 - 1.3, 0.5]), 1.0)
    np.testing.assert_allclose(world.state.positions[0], exact, atol=1e-12)
    assert np.all((world.state.positions >= 0) & (world.state.positions < 1))


def test_a_head_on_collision_across_the_face_is_exact():
    # centres 0.1 and 0.9 in a 1 m period: 0.2 apart through the face at x = 0 (not 0.8
    # through the middle); radii 0.05 each, closing at 2 m/s -> touch at t = 0.05 s
    obs = ListObserver()
    world = World(state_of([[0.1, 0.5, 0.5], [0.9, 0.5, 0.5]], [[-1.0, 0, 0], [1.0, 0, 0]], radius=0.05),
                  periodic_walls(1.0), Settings(gravity=(0, 0, 0)), obs)
    world.step(0.1)
    contacts = [e for e in obs.events if isinstance(e, Contacts)][0]
    assert len(contacts) == 1 and contacts.kind[0] == KIND_PAIR
    assert contacts.time_in_step[0] == pytest.approx(0.05, abs=1e-14)
    np.testing.assert_allclose(contacts.normal[0], [1.0, 0.0, 0.0], atol=1e-14)  # from b to a, through the face
    # equal masses, e = 1: the velocities swap; each goes back the way it came for 0.05 s
    np.testing.assert_allclose(world.state.velocities, [[1.0, 0, 0], [-1.0, 0, 0]], atol=1e-14)
    np.testing.assert_allclose(world.state.positions[:, 0], [0.1, 0.9], atol=1e-14)


def test_without_the_period_the_same_spheres_never_meet():
    world = World(state_of([[0.1, 0.5, 0.5], [0.9, 0.5, 0.5]], [[-1.0, 0, 0], [1.0, 0, 0]], radius=0.05),
                  periodic_walls(1.0, (False, True, True)), Settings(gravity=(0, 0, 0)))
    assert world.step(0.1).counts.contacts == 0


def test_a_step_whose_swept_box_is_half_a_period_wide_is_refused_with_a_warning():
    world = World(state_of([[0.5, 0.5, 0.5], [0.1, 0.1, 0.1]], [[30.0, 0, 0], [0, 0, 0]]), periodic_walls(1.0),
                  Settings(gravity=(0, 0, 0)))
    stats = world.step(0.1)
    assert [w.code for w in stats.warnings] == ["periodic"]
    assert "half the period" in stats.warnings[0].message


def test_a_dense_periodic_gas_keeps_energy_momentum_and_no_overlap():
    scene = load_scene("gas", ["box.periodic=true", "generate.count=200", "generate.packing_fraction=0.35",
                               "duration=0.5"])
    assert len(scene.walls) == 0 and scene.walls.periodic
    world = scene.build_world()
    first = None
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
        first = first or stats
        assert not stats.warnings and stats.max_overlap <= scene.settings.contact_tolerance
    assert stats.kinetic == pytest.approx(first.kinetic, rel=1e-12)
    assert np.abs(stats.momentum).max() < 1e-12
    assert np.all((world.state.positions >= 0) & (world.state.positions < scene.walls.period))


# --------------------------------------------------------------------------- the equation of state
def test_a_periodic_gas_gives_carnahan_starling_and_enskog_within_a_loose_bound(tmp_path):
    """The table in docs/pressure.md (benchmarks/eos.py) is within 0.5 %; here, small and short: 3 %."""
    out = tmp_path / "gas.mcap"
    api.record("gas", ["box.periodic=true", "generate.count=216", "generate.packing_fraction=0.3",
                               "duration=6", "dt=1/50"], mcap_path=str(out), rrd=False, detail="state", view=False)
    eos = equation_of_state(physdbg.open_recording(out), skip=0.2)
    assert eos.packing_fraction == pytest.approx(0.3, rel=1e-12)
    assert eos.z_wall is None  # no walls
    assert eos.z_virial == pytest.approx(carnahan_starling(0.3), rel=0.03)
    assert eos.collision_rate == pytest.approx(eos.collision_rate_enskog, rel=0.03)
    assert eos.collision_rate_enskog == pytest.approx(enskog_collision_rate(0.3, 0.1, eos.kT, 1.0))


def test_info_reads_the_equation_of_state_off_a_periodic_recording(tmp_path):
    out = tmp_path / "gas.mcap"
    api.record("gas", ["box.periodic=true", "generate.count=100", "duration=2"], mcap_path=str(out),
                       rrd=False, detail="contacts", view=True)
    result = runner.invoke(app, ["info", str(out)])
    assert result.exit_code == 0, result.output
    assert "0 walls" in result.output
    assert "collisions  " in result.output and "(Enskog: " in result.output
    assert "a periodic box has none" in result.output


# --------------------------------------------------------------------------- scenes
@pytest.mark.parametrize("override, field, words", [
    ("box.periodic=3", "box.periodic", "expected true, false or [x, y, z]"),
    ("box.periodic=[true, false]", "box.periodic", "expected true, false or [x, y, z]"),
    ("box.min=[0, 0, 0]", "box.min", "a [box] with a gas sets only periodic and restitution"),
    ("generate.radius=0.2", "box.periodic", "less than 4 diameters"),
])
def test_a_wrong_periodic_box_names_the_field(override, field, words):
    with pytest.raises(SceneError) as err:
        load_scene("gas", ["box.periodic=true", "generate.count=8", override])
    assert err.value.field == field and words in str(err.value)


def test_a_plane_across_a_periodic_axis_is_refused(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('steps = 1\ndt = 0.01\n[box]\nmin = [0, 0, 0]\nmax = [1, 1, 1]\nperiodic = [true, false, false]\n'
                    '[[planes]]\nnormal = [1, 1, 0]\noffset = 0.5\n')
    with pytest.raises(SceneError) as err:
        load_scene(str(path))
    assert err.value.field == "planes.0.normal" and "axis x is periodic" in str(err.value)
    path.write_text('steps = 1\ndt = 0.01\n[box]\nmin = [0, 0, 0]\nmax = [1, 1, 1]\nperiodic = [true, false, true]\n')
    walls = load_scene(str(path)).walls
    assert walls.names == ["y-", "y+"]
    np.testing.assert_array_equal(walls.period, [1.0, 0.0, 1.0])


def test_the_cli_reports_a_bad_periodic_value_in_one_line():
    result = runner.invoke(app, ["run", "gas", "-s", "box.periodic=yes"])
    assert result.exit_code == 2
    assert "box.periodic" in result.output and "Traceback" not in result.output


def test_record_peer_and_check_run_refuse_a_periodic_scene(tmp_path):
    result = runner.invoke(app, ["record-peer", "pybullet", "gas", "-s", "box.periodic=true", "-o",
                                 str(tmp_path / "p.mcap")])
    assert result.exit_code == 2 and "periodic box" in result.output
    run = tmp_path / "run.csv"
    run.write_text("step,time,body,x,y,z\n0,0,0,0,0,0\n")
    result = runner.invoke(app, ["check-run", str(run), "--scene", "gas", "-s", "box.periodic=true"])
    assert result.exit_code == 2 and "periodic box" in result.output


# --------------------------------------------------------------------------- recordings
def test_a_periodic_recording_replays_verifies_audits_and_diffs_clean(tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    args = ["box.periodic=true", "generate.count=64", "generate.packing_fraction=0.2", "duration=1"]
    api.record("gas", args, mcap_path=str(a), rrd=False, detail="contacts")
    api.record("gas", args, mcap_path=str(b), rrd=False, detail="contacts")
    rec = physdbg.open_recording(a)
    np.testing.assert_allclose(rec.header.walls.period, rec.header.walls.period[0])
    assert rec.header.walls.period[0] > 0
    for command in (["replay", str(a), "--verify"], ["explain", str(a)], ["diff", str(a), str(b)]):
        result = runner.invoke(app, command)
        assert result.exit_code == 0, (command, result.output)
    # the spheres did wrap, and the audit followed them across the faces
    start, end = rec.state(0).positions, rec.state(rec.frames - 1).positions
    assert np.any(np.abs(end - start) > 0.5 * rec.header.walls.period[0])


def test_the_audit_follows_a_sphere_that_wraps_and_finds_its_crossing():
    """Sphere 0 passes through sphere 1 with no contact and then leaves through the face at
    x = 4; the recorded end is wrapped to x = 0.5. Without unwrapping, its rebuilt path
    (ending at 4.5) would not match the record and it would not be checked at all."""
    walls = periodic_walls(4.0)
    checker = StepChecker(np.full(2, 0.1), np.ones(2), np.ones(2), walls, {"gravity": (0, 0, 0)})
    x0 = np.array([[3.5, 2.0, 2.0], [3.9, 2.0, 2.0]])
    v0 = np.array([[10.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    x1 = np.array([[0.5, 2.0, 2.0], [3.9, 2.0, 2.0]])
    found = checker.check(x0, v0, x1, 0.1, None)
    assert [(c.kind, c.a, c.other) for c in found] == [(KIND_PAIR, 0, 1)]
    assert found[0].time == pytest.approx((3.9 - 0.2 - 3.5) / 10.0, abs=1e-9)
    far = np.array([[3.5, 2.0, 2.0], [2.0, 0.5, 0.5]])  # the same flight past nothing: clean
    assert checker.check(far, v0, np.array([[0.5, 2.0, 2.0], [2.0, 0.5, 0.5]]), 0.1, None) == []


def test_the_rerun_view_draws_the_faces_and_unwrapped_paths(tmp_path):
    rerun_chunk = pytest.importorskip("rerun.chunk")
    out = tmp_path / "g.rrd"
    api.record("gas", ["box.periodic=true", "generate.count=27", "duration=2"],
                       mcap_path=str(tmp_path / "g.mcap"), rrd_path=str(out))
    rec = physdbg.open_recording(tmp_path / "g.mcap")
    side = float(rec.header.walls.period[0])
    static, strips = set(), []
    for chunk in rerun_chunk.RrdReader(out).stream():
        if chunk.is_static:
            static.add(chunk.entity_path)
        elif chunk.entity_path == "/world/paths":
            batch = chunk.to_record_batch()
            if "LineStrips3D:strips" in batch.schema.names:
                strips += [s for row in batch.column("LineStrips3D:strips").to_pylist() if row for s in row]
    assert {f"/world/periodic/{axis}{side_}" for axis in "xyz" for side_ in ("-", "\\+")} <= static
    # a path never jumps across the box (a wrap drawn as a line would be nearly a period long)
    longest = max(float(np.linalg.norm(np.diff(np.array(s), axis=0), axis=1).max()) for s in strips)
    assert longest < 0.25 * side
    # and some sphere did leave the box in a step: its path ends outside it
    assert any(np.any((np.array(s)[-1] < 0) | (np.array(s)[-1] >= side)) for s in strips)


def test_the_advisor_says_whether_a_step_fits_half_a_period_and_the_run_agrees():
    fits = runner.invoke(app, ["check", "gas", "-s", "box.periodic=true"])
    assert fits.exit_code == 0 and "under half the period" in fits.output
    too_long = runner.invoke(app, ["check", "gas", "-s", "box.periodic=true", "-s", "dt=0.1"])
    assert too_long.exit_code == 1
    assert "not under half the period" in too_long.output and "use dt < " in too_long.output
    # the run: steps with a too-wide swept box are refused with the warning the advice names
    scene = load_scene("gas", ["box.periodic=true", "dt=0.1", "steps=5"])
    world = scene.build_world()
    codes = [w.code for _ in range(scene.steps) for w in world.step(scene.dt).warnings]
    assert "periodic" in codes
    longest = float(too_long.output.split("use dt < ")[1].split(" s")[0])
    scene = load_scene("gas", ["box.periodic=true", f"dt={longest * 0.9}", "steps=20"])
    world = scene.build_world()
    assert not [w for _ in range(scene.steps) for w in world.step(scene.dt).warnings]


def test_a_box_that_a_contact_grows_past_half_a_period_is_reported():
    """A heavy sphere drives a chain of lighter ones (masses 100, 10, 1): the last leaves
    at about 3.3 times the first's speed: their paths outgrow every box the step began
    with, and past half the period; the step says which sphere."""
    state = State(np.array([[1.0, 1.0, 1.0], [1.11, 1.0, 1.0], [1.22, 1.0, 1.0]]),
                  np.array([[10.0, 0, 0], [0, 0, 0], [0, 0, 0]]), np.array([0.01, 0.1, 1.0]), np.full(3, 0.05),
                  np.ones(3), np.ones(3))
    world = World(state, periodic_walls(5.2), Settings(gravity=(0, 0, 0)))
    stats = world.step(0.1)
    assert stats.counts.contacts == 2
    assert [w.code for w in stats.warnings] == ["periodic"]
    assert "sphere 1's later contacts" in stats.warnings[0].message  # the first box to outgrow it
    calm = World(state_of([[1.0, 1.0, 1.0], [1.11, 1.0, 1.0]], [[10.0, 0, 0], [0, 0, 0]], radius=0.05),
                 periodic_walls(5.2), Settings(gravity=(0, 0, 0)))
    assert not calm.step(0.1).warnings  # equal masses: nothing outgrows the step's boxes
