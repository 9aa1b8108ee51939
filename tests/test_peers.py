"""record-peer: a scene run in pybullet and MuJoCo, recorded as a foreign run that opens,
replays, diffs and check-runs against physdbg's."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import api, open_recording
from physdbg.cli import app
from physdbg.peers import PeerError, run_peer
from physdbg.api import load_scene


def _need(module: str) -> None:
    try:
        __import__(module)
    except ImportError:
        pytest.skip(f"{module} is not installed (pip install 'physdbg[peers]'); the adapter cannot be run")


@pytest.mark.slow
@pytest.mark.parametrize("peer", ["pybullet", "mujoco"])
def test_a_peer_s_bounce_opens_replays_diffs_and_check_runs(tmp_path, peer):
    _need(peer)
    runner = CliRunner()
    out = tmp_path / f"bounce-{peer}.mcap"
    done = runner.invoke(app, ["record-peer", peer, "bounce", "-o", str(out)])
    assert done.exit_code == 0, done.output
    assert "build time" not in done.output and f"ran         300 steps of 1 body in {peer}" in done.output
    rec = open_recording(out)
    assert rec.meta["foreign"]["format"] == peer and rec.meta["foreign"]["notes"]
    start, fall = rec.state(0), rec.state(20)
    assert np.array_equal(start.positions, load_scene("bounce").state.positions)
    # free fall for 1/3 s from rest: every engine gets g·t within its integrator's step
    assert fall.velocities[0, 1] == pytest.approx(-9.81 * 20 / 60, rel=1e-9)
    assert fall.positions[0, 1] == pytest.approx(1.1 - 9.81 / 2 * (20 / 60) ** 2, abs=9.81 * 20 / 3600)
    assert min(s.positions[0, 1] for s in rec.states()) > 0.0  # the floor holds the ball up
    assert runner.invoke(app, ["replay", str(out), "--rrd", str(tmp_path / "peer.rrd")]).exit_code == 0
    assert "foreign     another engine's run" in runner.invoke(app, ["info", str(out)]).output
    reference = api.record("bounce", mcap_path=str(tmp_path / "ref.mcap"), rrd=False, detail="contacts").mcap
    diffed = runner.invoke(app, ["diff", reference, str(out)])
    assert diffed.exit_code == 1 and "run B (another engine's) departs from run A in step 1" in diffed.output
    report = api.check_run(out, "bounce").report
    assert report.integrator["name"] == "semi-implicit-euler"  # both step v first, then x
    late = next(d for d in report.departures if d.kind == "bounce-time")
    # both find the floor where a step ends: the first bounce comes late, from inside it
    assert late.step in (27, 28) and late.evidence["shift"] > 0 and late.evidence["depth"] > 0.01


def test_a_peer_is_refused_clearly(tmp_path):
    with pytest.raises(PeerError, match="unknown peer 'bullet'; choose one of pybullet, mujoco"):
        run_peer("bullet", load_scene("bounce"))
    with pytest.raises(PeerError, match='dt = "real"'):
        run_peer("pybullet", load_scene("bounce", ['dt="real"']))
    done = CliRunner().invoke(app, ["record-peer", "pybullet", "bounce", "-s", "duration=500000",
                                    "-o", str(tmp_path / "x.mcap")])
    assert done.exit_code == 2 and "more than a peer run may take" in done.output


@pytest.mark.parametrize("setup", ["pybullet", "pybullet +ccd", "mujoco"])
def test_a_peer_collides_with_the_scene_s_meshes(setup):
    """record-peer and the benchmarks translate fixed meshes too: a static triangle mesh in
    pybullet, its convex hull in MuJoCo. A ball dropped on a ramp lands on it, above the floor."""
    from physdbg.peers import PeerSetup, build

    _need(setup.split()[0])
    peer_setup = PeerSetup(setup.split()[0], ccd=setup.endswith("+ccd"))
    scene = load_scene("ramp", ["duration=0.7"])  # long enough that a free fall would end below 0
    peer = build(scene, peer_setup)
    try:
        for _ in range(scene.steps):
            peer.step()
        heights = peer.positions()[:, 1]
        assert np.all(heights > 0.2)  # on the ramps (the floor would leave them at 0.1 m)
        assert "mesh" in peer.notes[-1]
    finally:
        peer.close()


def test_pybullet_s_continuous_collision_acts_on_a_sphere_against_a_mesh():
    """A ball at 250 m/s (50 radii a step) toward a plate of two triangles of no thickness:
    with ccd pybullet's continuous collision bounces it back at full speed (it ends 75 m
    up, 0.1 s down and 0.3 s back up). Its CCD acts only on a rigid body
    (useMaximalCoordinates); the highspeed benchmark's 4,903 escapes with and without CCD
    were spheres created as multibodies, which ignore it and move no faster than 100 m/s."""
    from physdbg.peers import PeerSetup, build

    _need("pybullet")
    scene = load_scene("docs/examples/meshes/plate.toml", ["particles.0.velocity=[0, 0, -250]",
                                                          "particles.0.radius=0.05", "steps=40"])
    peer = build(scene, PeerSetup("pybullet", ccd=True))
    try:
        for _ in range(scene.steps):
            peer.step()
        z = float(peer.positions()[0, 2])
    finally:
        peer.close()
    assert z > 60.0, z  # bounced, and at more than 100 m/s
