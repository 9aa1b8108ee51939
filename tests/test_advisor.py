"""The advisor (physdbg check, "auto" settings): every recommendation checked against a run,
and the failures it predicts seen in runs."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from physdbg import api
from physdbg.advisor import Decision, advise, decide
from physdbg.api import load_scene
from physdbg.cli import app
from physdbg.scene import parse_scene
from physdbg.scenes import builtin_names

BAD = {"tunnelling", "overlap", "non-finite", "energy-gain"}


@pytest.mark.parametrize("name", builtin_names())
@pytest.mark.slow
def test_the_recommended_settings_never_tunnel_overlap_or_blow_up(name):
    advice = advise(load_scene(name))
    overrides = [f"{k}={v}" for k, v in advice.recommended.items()]
    summary = api.run(name, overrides)
    assert not BAD & set(summary.finding_counts), (overrides, summary.findings)


@pytest.mark.parametrize("name", builtin_names())
@pytest.mark.slow
def test_no_sphere_outruns_the_speed_bound(name):
    """The speed bound holds in every built-in scene; where it cannot be a bound (a
    kinematic mesh pumps energy at every strike: paddle) the advice says it is an estimate,
    and the run shows why: a sphere goes faster than one strike can make it."""
    scene = load_scene(name)
    facts = advise(scene).facts
    bound = facts["speed_bound"]
    world = scene.build_world()
    fastest = 0.0
    for dt in scene.step_lengths():
        world.step(dt)
        fastest = max(fastest, float(np.linalg.norm(world.state.velocities, axis=1).max()))
    if scene.walls.meshes.moving.any():
        assert facts["speed_bound_why"].startswith("an estimate, not a bound (a kinematic mesh can add energy")
        assert fastest > bound
    else:
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
    return decide(parse_scene(f"""
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
    """))


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
    assert result.summary.auto["detection"].value == "swept"
    assert result.summary.auto["detection"].why.startswith("contacts can happen")
    assert api.verify(result.mcap).ok  # the recorded scene says auto; it decides the same again
    done = CliRunner().invoke(app, ["run", "bounce", "-s", "detection=auto"])
    assert done.exit_code == 0 and "auto        detection=swept: contacts can happen" in done.output
    # five steps (83 ms) cannot bring the ball down 1 m: no sweep needed
    done = CliRunner().invoke(app, ["run", "bounce", "-s", "detection=auto", "-s", "steps=5"])
    assert done.exit_code == 0 and "auto        detection=discrete: no contact can happen" in done.output
    scene = decide(parse_scene('''
        method = "auto"
        integrator = "verlet"
        dt = 0.01
        duration = 1.0
        [[particles]]
        position = [0.0, 0.5, 0.0]
        radius = 0.5
        [[planes]]
        normal = [0.0, 1.0, 0.0]
    '''))
    # integrator was given, so not decided; the pile rules are auto unless given (no pile here)
    assert set(scene.auto) == {"detection", "ordering", "rapid_contact_time", "rapid_contact_rule", "sleep_speed"}
    assert (scene.settings.rapid_contact_rule, scene.settings.sleep_speed) == ("hold", 0.0)
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


# the exact rules for a pile (hold, no sleeping), which rapid_contact_rule = sleep_speed = auto do not pick
ENGINE_RULES = ["rapid_contact_rule=hold", "sleep_speed=0"]


def _flags(overrides: list[str]) -> list[str]:
    """KEY=VALUE overrides as the CLI takes them (-s KEY=VALUE ...)."""
    return [part for item in overrides for part in ("-s", item)]


NARROW_PILE = ["generate.count=100", "box.max=[0.3,1,0.3]", "generate.speed=0", "generate.restitution=0.5",
               "box.restitution=0.5", "steps=240", *ENGINE_RULES]


@pytest.mark.slow
def test_a_pile_is_foreseen_and_each_rule_does_on_it_what_check_says():
    """100 spheres in a 0.3 m × 0.3 m box settle ~3 layers deep. hold churns (held contacts
    let go and held again, the swept tests of a step up a hundredfold), tc collapses (the
    event cap, then overlaps), tc with sleeping falls asleep exactly."""
    from physdbg.advisor import pile_choice

    scene = load_scene("rain", NARROW_PILE)
    advice = advise(scene)
    assert advice.facts["pile"]["layers"] == pytest.approx(
        100 * 4 / 3 * np.pi * 0.03**3 / 0.64 / 0.09 / 0.06, rel=1e-12)
    outcomes = {p.value: p.outcome for p in advice.predictions if p.setting == "pile"}
    assert outcomes == {"hold": "churns", "hold+sleep": "churns", "tc": "collapses", "tc+sleep": "settles"}
    assert pile_choice(scene.settings) == "hold"

    world = scene.build_world()
    stats = [world.step(scene.dt) for _ in range(70)]
    assert max(s.counts.released for s in stats) > 100
    assert max(s.counts.swept_tests for s in stats) > 100 * stats[9].counts.swept_tests

    world = load_scene("rain", NARROW_PILE + ["rapid_contact_rule=tc"]).build_world()
    stats = [world.step(1 / 120) for _ in range(60)]
    assert any("max_contacts_per_step" in [w.code for w in s.warnings] for s in stats)

    settled = api.run("rain", NARROW_PILE + ["rapid_contact_rule=tc", "sleep_speed=0.05", "sleep_time=0.1"])
    assert settled.asleep_at_end == 100 and settled.max_overlap <= 1e-9 and not settled.warning_counts


def test_a_rain_that_piles_up_gets_the_rules_check_recommends_for_a_pile():
    from physdbg.advisor import PILE_REMEDY, pile_choice

    settings = load_scene("rain", ["generate.count=500"]).settings  # rapid_contact_rule, sleep_speed: auto
    assert {name: getattr(settings, name) for name in PILE_REMEDY} == PILE_REMEDY
    assert pile_choice(settings) == "tc+sleep"


@pytest.mark.parametrize("overrides", [[], ["generate.count=500", "generate.restitution=1", "box.restitution=1"],
                                       ["generate.count=500", "gravity=[0,0,0]"]])
def test_no_pile_without_a_full_layer_without_losses_or_without_gravity(overrides):
    assert advise(load_scene("rain", overrides)).facts["pile"] is None  # rain's 100 spheres: 0.3 layers


def test_check_shows_the_pile_rules_marks_the_scene_s_own_and_keeps_its_exit_code():
    runner = CliRunner()
    done = runner.invoke(app, ["check", "rain", "-s", "generate.count=500", *_flags(ENGINE_RULES)])
    assert done.exit_code == 0
    assert "pile        500 spheres settle about 1.5 layers deep on a 1 m² floor (restitution 0.8 < 1)" in done.output
    assert " *hold           churns" in done.output and "  tc+sleep       settles" in done.output
    assert "to settle -s rapid_contact_rule=tc -s sleep_speed=0.1 -s sleep_time=0.1" in done.output
    done = runner.invoke(app, ["check", "rain", "-s", "generate.count=500"])  # the scene's own rules
    assert done.exit_code == 0 and " *tc+sleep       settles" in done.output and "to settle" not in done.output
    assert "pile        " not in runner.invoke(app, ["check", "rain"]).output  # 100 spheres: no pile


def test_run_and_record_say_before_they_start_that_the_pile_will_not_rest(tmp_path):
    """A user who types `physdbg run rain -s generate.count=500` is told at
    once (stderr) why the run will be slow and what lets the pile rest; --json stays JSON."""
    runner = CliRunner()
    done = runner.invoke(app, ["run", "rain", "-s", "generate.count=500", "-s", "steps=1", *_flags(ENGINE_RULES),
                               "--json"])
    assert done.exit_code == 0
    assert done.stderr.startswith("note: 500 spheres settle about 1.5 layers deep")
    assert "Under hold it churns" in done.stderr and "-s rapid_contact_rule=tc -s sleep_speed=0.1" in done.stderr
    assert json.loads(done.stdout)["steps"] == 1
    done = runner.invoke(app, ["record", "rain", "-s", "generate.count=500", "-s", "steps=1", "-s",
                               "rapid_contact_rule=tc", "-s", "sleep_speed=0", "-o", str(tmp_path / "r.mcap"),
                               "--no-rrd"])
    assert done.exit_code == 0 and "Under tc it collapses" in done.stderr
    quiet = runner.invoke(app, ["run", "rain", "-s", "generate.count=500", "-s", "steps=1"])  # rain's own rules
    assert quiet.exit_code == 0 and "note:" not in quiet.stderr


def test_the_pile_rules_default_to_auto_on_only_where_a_pile_forms():
    """The rapid-contact rule, the TC rule and sleeping where a pile forms; elsewhere the
    seed's model: no rapid-contact rule, held contacts exact, nothing asleep."""
    from physdbg.api import load_scene

    pile = load_scene("rain", ["generate.count=500"])
    assert (pile.settings.rapid_contact_time, pile.settings.rapid_contact_rule, pile.settings.sleep_speed,
            pile.settings.sleep_time) == (1e-4, "tc", 0.1, 0.1)
    assert pile.auto["rapid_contact_time"].value == 1e-4
    assert pile.auto["rapid_contact_time"].why.startswith("500 spheres settle about 1.5 layers deep")
    assert "the rapid-contact rule, the TC rule and sleeping let it fall asleep" in pile.auto["rapid_contact_time"].why
    assert pile.auto["rapid_contact_rule"] == Decision("tc", shared_with="rapid_contact_time")
    assert pile.auto["sleep_speed"] == Decision(0.1, shared_with="rapid_contact_time")
    thin = load_scene("rain", ["generate.count=100"])  # 0.29 of a layer on the floor
    assert (thin.settings.rapid_contact_time, thin.settings.rapid_contact_rule, thin.settings.sleep_speed) == \
        (0.0, "hold", 0.0)
    assert "not a pile" in thin.auto["rapid_contact_time"].why
    assert "no rapid-contact rule" in thin.auto["rapid_contact_time"].why
    for name in ("bounce", "cradle", "gas", "billiards"):  # no closed box under gravity: the seed's model
        scene = load_scene(name)
        assert (scene.settings.rapid_contact_time, scene.settings.rapid_contact_rule,
                scene.settings.sleep_speed) == (0.0, "hold", 0.0), name
    # asked for: kept, and a given sleep_time is kept too
    asked = load_scene("rain", ["generate.count=500", "rapid_contact_rule=hold", "sleep_time=0.3",
                                "rapid_contact_time=2e-4"])
    assert (asked.settings.rapid_contact_time, asked.settings.rapid_contact_rule, asked.settings.sleep_speed,
            asked.settings.sleep_time) == (2e-4, "hold", 0.1, 0.3)
    assert not {"rapid_contact_time", "rapid_contact_rule", "sleep_time"} & set(asked.auto)
    on = load_scene("billiards", ["rapid_contact_time=1e-4"])  # a scene may ask for the rule anywhere
    assert on.settings.rapid_contact_time == 1e-4 and "rapid_contact_time" not in on.auto
    done = CliRunner().invoke(app, ["check", "rain", "-s", "generate.count=500"])
    assert ("auto        rapid_contact_time=0.0001, rapid_contact_rule=tc, sleep_speed=0.1, sleep_time=0.1: 500 "
            "spheres settle" in done.output)
    done = CliRunner().invoke(app, ["run", "rain", "-s", "generate.count=500", "-s", "steps=2"])
    assert done.exit_code == 0 and ("auto        rapid_contact_time=0.0001, rapid_contact_rule=tc, sleep_speed=0.1, "
                                    "sleep_time=0.1:" in done.output)
    done = CliRunner().invoke(app, ["run", "billiards", "-s", "steps=2"])
    assert done.exit_code == 0 and "auto        rapid_contact_time=0.0, rapid_contact_rule=hold" in done.output


def test_reading_a_scene_decides_nothing_and_a_world_refuses_what_is_still_auto():
    from physdbg.scene import read_scene

    scene = read_scene("bounce", ["detection=auto"])
    undecided = ["detection", "rapid_contact_time", "rapid_contact_rule", "sleep_speed"]
    assert scene.settings.undecided() == undecided and scene.auto == {}
    with pytest.raises(ValueError, match=f"{', '.join(undecided)} still 'auto': decide it"):
        scene.build_world()
    decide(scene)
    assert scene.settings.undecided() == [] and set(scene.auto) == set(undecided)
    assert api.run(read_scene("bounce", ["steps=3"])).steps == 3  # the api decides what it is given


def test_a_recorded_scene_comes_back_with_the_settings_the_run_used(tmp_path):
    path = tmp_path / "rain.mcap"
    api.record("rain", ["generate.count=60", "steps=2"], mcap_path=str(path), rrd=False)
    from physdbg import open_recording

    with open_recording(path) as rec:
        again = rec.scene
        used = rec.meta["settings"]
    assert again.settings.undecided() == []
    assert (again.settings.rapid_contact_rule, again.settings.sleep_speed, again.settings.sleep_time) == (
        used["rapid_contact_rule"], used["sleep_speed"], used["sleep_time"])
    assert again.auto["rapid_contact_rule"] == Decision(used["rapid_contact_rule"], "as recorded")


TROUGH = "v -1 0.5 -1\nv -0.3 0 -1\nv 0.3 0 -1\nv 1 0.5 -1\nv -1 0.5 1\nv -0.3 0 1\nv 0.3 0 1\nv 1 0.5 1\n" \
         "f 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\n"


def _trough_scene(tmp_path, second_ball: str) -> str:
    (tmp_path / "trough.obj").write_text(TROUGH)
    scene = tmp_path / "trough.toml"
    scene.write_text('name = "trough"\ndt = "1/60"\nduration = 1.0\ngravity = [0.0, -9.81, 0.0]\n'
                     '[[meshes]]\nname = "trough"\nfile = "trough.obj"\n'
                     '[[particles]]\nposition = [0.0, 1.0, 0.0]\nradius = 0.05\n'
                     f'[[particles]]\nposition = {second_ball}\nradius = 0.05\n')
    return str(scene)


def test_a_sphere_starting_inside_a_mesh_is_named_by_check_and_by_the_run(tmp_path):
    """check names the sphere, the triangle and the depth, says what the run will do about
    it, and fails (exit 1); the run says the same before its first step."""
    scene = _trough_scene(tmp_path, "[0.3, 0.02, 0.3]")
    result = CliRunner().invoke(app, ["check", scene])
    assert result.exit_code == 1, result.output
    assert ("start       sphere 1 starts 33.7 mm inside mesh 'trough' triangle 5; physdbg does not push bodies apart"
            in result.output), result.output
    assert "predicted to fail: it starts with a sphere inside another body (start, above)" in result.output
    summary = api.run(scene, ["steps=2"])
    assert summary.start_notes and summary.start_notes[0].startswith("sphere 1 starts 33.7 mm inside mesh 'trough'")
    # and spheres inside each other, or behind a wall, are named the same way
    api_check = api.check(scene, ["particles.1.position=[0.0, 1.06, 0.0]"])
    assert [p.why.split(";")[0] for p in api_check.problems] == ["sphere 0 starts 40 mm inside sphere 1"]


def test_a_mesh_no_sphere_can_reach_is_a_note(tmp_path):
    scene = _trough_scene(tmp_path, "[50.0, 1.0, 0.0]")
    far = ["particles.0.position=[60.0, 1.0, 0.0]"]
    result = CliRunner().invoke(app, ["check", scene, *[a for o in far for a in ("-s", o)]])
    assert result.exit_code == 0, result.output
    assert ("note        mesh 'trough' is out of every sphere's reach in this run: the nearest, sphere 1, starts 49 m "
            "from it") in result.output, result.output
    assert any("out of every sphere's reach" in note for note in api.run(scene, [*far, "steps=2"]).mesh_notes)
    assert api.check(scene).advice.facts["notes"] == []  # the ball above the trough reaches it


def test_check_notes_a_kinematic_mesh_s_work_and_a_sphere_riding_it(tmp_path):
    """The elevator: a ball resting on a platform rising at 0.5 m/s. check notes that the
    platform's motion does work (the energy line will rise) and that the ball is carried."""
    (tmp_path / "platform.obj").write_text("v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 1 3 2\nf 1 4 3\n")
    scene = tmp_path / "elevator.toml"
    scene.write_text('name = "elevator"\ndt = "1/60"\nduration = 2.0\ngravity = [0.0, -9.81, 0.0]\n'
                     '[[meshes]]\nname = "platform"\nfile = "platform.obj"\nvelocity = [0.0, 0.5, 0.0]\n'
                     '[[particles]]\nposition = [0.0, 0.1, 0.0]\nradius = 0.1\nrestitution = 0.5\n')
    result = CliRunner().invoke(app, ["check", str(scene)])
    assert result.exit_code == 0, result.output
    assert ("note        mesh 'platform' moves at 0.5 m/s: its prescribed motion does work on every sphere it strikes"
            in result.output), result.output
    assert "note        sphere 0 starts resting on mesh 'platform' triangle 0, which moves: it is carried" in result.output
    lifted = CliRunner().invoke(app, ["check", str(scene), "-s", "particles.0.position=[0.0, 0.5, 0.0]"]).output
    assert "starts resting" not in lifted and "does work on every sphere" in lifted


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(2, 40), periodic=st.booleans(), reach=st.floats(0.0, 0.6))
def test_whether_two_spheres_reach_each_other_is_the_brute_force_answer(seed, n, periodic, reach):
    """The grid's answer equals every pair measured, in an open and in a periodic box
    (where a pair meets through its nearest images)."""
    from physdbg.advisor import _two_reach_each_other
    from physdbg.engine.periodic import minimum_image
    from physdbg.engine.state import Walls

    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, 4.0, (n, 3))
    extent = rng.uniform(0.0, 0.05, n) + reach * (rng.random(n) < 0.5)
    walls = Walls(period=np.array([4.0, 0.0, 4.0]) if periodic else np.zeros(3))
    d = np.linalg.norm(minimum_image(x[:, None] - x[None], walls.period), axis=2)
    np.fill_diagonal(d, np.inf)
    brute = bool(np.any(d <= extent[:, None] + extent[None]))
    if periodic and 2 * extent.max() >= 2.0:
        assert _two_reach_each_other(x, extent, walls)  # reaching half the box round: yes, unmeasured
    else:
        assert _two_reach_each_other(x, extent, walls) == brute


def test_check_of_a_hundred_thousand_spheres_needs_no_n_by_n_matrix():
    """check's estimates come from the broad phase's grid: at 100,000 spheres an N x N
    matrix of distances would be 80 GB; numpy's allocations stay under 200 MB."""
    import tracemalloc

    scene = load_scene("rain", ["generate.count=100000", "generate.radius=0.004"])
    tracemalloc.start()
    try:
        advice = advise(scene)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert advice.facts["contacts_possible"]
    assert peak < 200e6, f"{peak / 1e6:.0f} MB"
