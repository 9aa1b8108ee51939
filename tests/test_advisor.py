"""The advisor (physdbg check, "auto" settings): every recommendation checked against a run,
and the failures it predicts seen in runs."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import api
from physdbg.analysis.advisor import advise
from physdbg.cli import app
from physdbg.scene import load_scene, parse_scene
from physdbg.scenes import builtin_names

BAD = {"tunnelling", "overlap", "non-finite", "energy-gain"}


@pytest.mark.parametrize("name", builtin_names())
def test_the_recommended_settings_never_tunnel_overlap_or_blow_up(name):
    advice = advise(load_scene(name))
    overrides = [f"{k}={v}" for k, v in advice.recommended.items()]
    summary = api.run(name, overrides)
    assert not BAD & set(summary.finding_counts), (overrides, summary.findings)


@pytest.mark.parametrize("name", builtin_names())
def test_no_sphere_outruns_the_speed_bound(name):
    scene = load_scene(name)
    bound = advise(scene).facts["speed_bound"]
    world = scene.build_world()
    fastest = 0.0
    for dt in scene.step_lengths():
        world.step(dt)
        fastest = max(fastest, float(np.linalg.norm(world.state.velocities, axis=1).max()))
    assert fastest <= bound * (1 + 1e-9), (fastest, bound)


def test_predicted_failures_happen():
    advice = advise(load_scene("bullet-wall"))
    assert [p.outcome for p in advice.fails("detection", "discrete")] == ["tunnels"]
    assert "tunnelling" in api.run("bullet-wall", ["detection=discrete"]).finding_counts
    advice = advise(load_scene("cradle"))
    assert [p.outcome for p in advice.fails("ordering", "index")] == ["overlap left"]
    found = set(api.run("cradle", ["ordering=index"]).finding_counts)
    assert found & {"overlap", "order"}, found


def _two_spheres(second_position: str, second_velocity: str):
    """Two spheres (r = 0.1, no gravity, 1 s): one at the origin moving +x at 1 m/s."""
    return parse_scene(f"""
        name = "two"
        dt = 0.01
        duration = 1.0
        gravity = [0.0, 0.0, 0.0]
        [[particles]]
        position = [0.0, 0.0, 0.0]
        velocity = [1.0, 0.0, 0.0]
        radius = 0.1
        [[particles]]
        position = {second_position}
        velocity = {second_velocity}
        radius = 0.1
    """)


def test_where_no_contact_can_happen_it_needs_no_sweep():
    scene = _two_spheres("[0.0, 5.0, 0.0]", "[-1.0, 0.0, 0.0]")
    advice = advise(scene)
    assert not advice.facts["contacts_possible"] and advice.recommended["detection"] == "discrete"
    assert api.run(scene).contacts == 0
    # within reach of each other they can touch: swept again
    assert advise(_two_spheres("[1.5, 0.0, 0.0]", "[0.0, 0.0, 0.0]")).recommended["detection"] == "swept"


def test_auto_settings_are_decided_said_and_repeat_on_replay(tmp_path):
    result = api.record("bounce", ["integrator=auto", "detection=auto", "ordering=auto", "steps=30"],
                        mcap_path=str(tmp_path / "auto.mcap"), rrd=False)
    assert result.summary.integrator == "exact" and result.summary.detection == "swept"
    assert result.summary.auto["detection"].startswith("swept: contacts can happen")
    assert api.verify(result.mcap).ok  # the recorded scene says auto; it decides the same again
    done = CliRunner().invoke(app, ["run", "bounce", "-s", "detection=auto"])
    assert done.exit_code == 0 and "auto        detection=swept: contacts can happen" in done.output
    # five steps (83 ms) cannot bring the ball down 1 m: no sweep needed
    done = CliRunner().invoke(app, ["run", "bounce", "-s", "detection=auto", "-s", "steps=5"])
    assert done.exit_code == 0 and "auto        detection=discrete: no contact can happen" in done.output
    scene = parse_scene('''
        method = "auto"
        integrator = "verlet"
        dt = 0.01
        duration = 1.0
        [[particles]]
        position = [0.0, 0.5, 0.0]
        radius = 0.5
        [[planes]]
        normal = [0.0, 1.0, 0.0]
    ''')
    assert set(scene.auto) == {"detection", "ordering"}  # integrator was given, so not decided
    assert (scene.settings.integrator, scene.settings.detection) == ("verlet", "swept")
    done = CliRunner().invoke(app, ["run", "bounce", "-s", "detection=automatic"])
    assert done.exit_code == 2 and "allowed: swept, sampled, discrete, auto" in done.output


def test_check_exits_1_when_the_scene_s_own_settings_are_predicted_to_fail():
    runner = CliRunner()
    done = runner.invoke(app, ["check", "bullet-wall", "-s", "detection=discrete"])
    assert done.exit_code == 1
    assert "predicted to fail: detection=discrete tunnels" in done.output
    assert "can tunnel through wall 'thin wall' (t/2 + r = 0.1 m): up to 10 m a step at 100 m/s" in done.output
    done = runner.invoke(app, ["check", "cradle", "--json"])
    assert done.exit_code == 0
    data = json.loads(done.output)
    assert data["ok"] and data["recommended"]["detection"] == "swept"
    assert {p["outcome"] for p in data["predictions"] if p["setting"] == "ordering"} == {"safe", "overlap left"}
