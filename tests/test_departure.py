"""check-run: a foreign run compared step by step with physdbg's exact run of the same scene
(analysis.departure), through the library and the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import api, open_recording
from physdbg.cli import app
from physdbg.api import load_scene
from physdbg.errors import ForeignRunError
from tests.student_engine import (EXAMPLES, MISTAKES, example_run, simulate, simulate_swept, write_blown_up,
                                  write_csv, write_jsonl)

ROOT = Path(__file__).resolve().parents[1]
HEAD_ON = ["particles.2.position=[20.0, 0.0, 0.0]", "particles.3.position=[30.0, 0.0, 0.0]",
           "particles.4.position=[40.0, 0.0, 0.0]"]


def kinds(report) -> list[str]:
    return [d.kind for d in report.departures]


@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_check_run_names_tunnelling_on_the_thin_wall(tmp_path, fmt):
    times, xs, vs = simulate(load_scene("bullet-wall"), 3, 0.1)
    run = tmp_path / f"student.{fmt}"
    (write_csv if fmt == "csv" else write_jsonl)(run, times, xs, vs)
    report = api.check_run(run, "bullet-wall").report
    assert report.exit_code == 1 and report.first.step == 1 and report.first.cause == "tunnelling"
    tunnel = report.departures[0]
    assert tunnel.kind == "tunnelling" and tunnel.wall == "thin wall" and tunnel.body == 0
    # physdbg's own swept test from the same state: the touch 0.9 m − 0.1 m away at 100 m/s
    assert tunnel.evidence["physdbg_time"] == pytest.approx(0.009, abs=1e-12)
    assert "carries it 10 m" in tunnel.text and "steps under 0.002 s" in tunnel.advice


@pytest.mark.parametrize("velocities", [True, False])
def test_check_run_names_the_late_bounce_and_the_integrator_on_bounce(tmp_path, velocities):
    scene = load_scene("bounce")
    times, xs, vs = simulate(scene, 60, 1 / 60)
    write_csv(tmp_path / "bounce.csv", times, xs, vs if velocities else None)
    report = api.check_run(tmp_path / "bounce.csv", scene).report
    # explicit Euler falls behind the exact parabola by g·dt²/2 in the very first step
    assert report.first.step == 1 and report.first.cause == "drift"
    assert report.first.position == pytest.approx(9.81 / 2 / 3600, rel=1e-9)
    assert report.integrator["name"] == "explicit-euler" and report.integrator["differs"]
    late = next(d for d in report.departures if d.kind == "bounce-time")
    # from the state at the step's start the exact ball touches the floor inside step 28; the
    # student's tests where the step ends, so it bounces at the step's end, already inside
    assert late.step == 28 and late.wall == "floor"
    assert late.evidence["time"] == pytest.approx(28 / 60, abs=1e-12)
    assert 0 < late.evidence["shift"] < 1 / 60 and late.evidence["depth"] > 0.02
    assert "tests for contact where each step ends" in late.advice
    assert "contact-energy" not in kinds(report)  # its restitution is the scene's
    assert "first contact that goes wrong: step 28, bounced at the wrong time" in report.headline


def test_check_run_names_the_energy_a_flipped_impulse_adds(tmp_path):
    scene = load_scene("cradle", HEAD_ON)
    times, xs, vs = simulate(scene, 60, 1 / 60, flip=True)
    write_jsonl(tmp_path / "flip.jsonl", times, xs, vs)
    report = api.check_run(tmp_path / "flip.jsonl", scene).report
    assert report.first.cause == "impulse-sign" and report.first.step == 44
    energy = report.departures[0]
    assert energy.kind == "impulse-sign" and {energy.body, energy.other} == {0, 1}
    # the flipped impulse adds (1 + e)·closing instead of removing it: they still approach at 3 m/s
    assert energy.evidence["restitution"] == pytest.approx(-3.0, rel=1e-9)
    assert "wrong way" in energy.advice and "−(2 + e)" in energy.text
    unflipped = tmp_path / "unflipped.jsonl"
    write_jsonl(unflipped, *simulate(scene, 60, 1 / 60))
    assert not {"impulse-sign", "contact-energy"} & set(kinds(api.check_run(unflipped, scene).report))


def test_physdbg_s_own_run_does_not_depart_and_its_index_order_does(tmp_path):
    for overrides, departs in (([], False), (["ordering=index"], True)):
        rec = open_recording(api.record("cradle", overrides, mcap_path=str(tmp_path / "c.mcap"), rrd=False,
                                        detail="state", force=True).mcap)
        states = list(rec.states())
        write_jsonl(tmp_path / "own.jsonl", np.array([s.time for s in states]),
                    np.array([s.positions for s in states]), np.array([s.velocities for s in states]))
        report = api.check_run(tmp_path / "own.jsonl", "cradle").report
        assert (report.exit_code == 1) == departs
        if not departs:
            assert report.first is None and report.departures == [] and "no departure" in report.headline
        else:  # index order passes the blow one ball a step, as physdbg's step with ordering = index does
            assert report.first.cause == "index-order"
            order = report.departures[0]
            assert order.kind == "index-order" and order.step == 44
            assert order.evidence["physdbg_order"][:2] == [[0, 1, 0], [1, 2, 0]]
            assert order.evidence["index_order"] == [[0, 1, 0]]


def test_a_gas_run_with_the_scene_s_steps_does_not_depart(tmp_path):
    """The run's time column sums dt; check-run steps with the scene's dt itself, so a
    chaotic gas does not part over the last bit of each step's length."""
    rec = open_recording(api.record("gas", mcap_path=str(tmp_path / "g.mcap"), rrd=False, detail="state").mcap)
    states = list(rec.states())
    times = np.cumsum([0.0] + [s.dt for s in states[1:]])
    write_jsonl(tmp_path / "gas.jsonl", times, np.array([s.positions for s in states]),
                np.array([s.velocities for s in states]))
    assert api.check_run(tmp_path / "gas.jsonl", "gas").report.first is None


def test_check_run_from_the_command_line(tmp_path):
    times, xs, vs = simulate(load_scene("bullet-wall"), 3, 0.1)
    write_csv(tmp_path / "s.csv", times, xs, vs)
    runner = CliRunner()
    done = runner.invoke(app, ["check-run", str(tmp_path / "s.csv"), "--scene", "bullet-wall", "--keep",
                               str(tmp_path / "kept")])
    assert done.exit_code == 1, done.output
    assert "result     DEPARTS: the run departs from physdbg's in step 1, sphere 0: tunnelling" in done.output
    assert "what to do: test for contacts along the path" in done.output
    assert (tmp_path / "kept" / "run.mcap").exists() and (tmp_path / "kept" / "reference.mcap").exists()
    again = runner.invoke(app, ["check-run", str(tmp_path / "s.csv"), "--scene", "bullet-wall", "--keep",
                                str(tmp_path / "kept")])
    assert again.exit_code == 2 and "already exists; pass --force" in again.output
    as_json = runner.invoke(app, ["check-run", str(tmp_path / "s.csv"), "--scene", "bullet-wall", "--json"])
    data = json.loads(as_json.output)
    assert data["exit_code"] == 1 and data["departures"][0]["kind"] == "tunnelling"
    markdown = runner.invoke(app, ["check-run", str(tmp_path / "s.csv"), "--scene", "bullet-wall", "--markdown"])
    assert markdown.output.startswith("### ❌ physdbg check-run: departs") and "| 1 | tunnelling |" in markdown.output
    wrong = runner.invoke(app, ["check-run", str(tmp_path / "s.csv"), "--scene", "cradle"])
    assert wrong.exit_code == 2 and "field 'body' is 0" not in wrong.output and "line 2" in wrong.output
    only_start = tmp_path / "start.csv"
    only_start.write_text("step,time,body,x,y,z\n0,0,0,0,0,0\n")
    short = runner.invoke(app, ["check-run", str(only_start), "--scene", "bullet-wall"])
    assert short.exit_code == 2 and "only its initial state" in short.output


def test_an_mcap_run_is_read_like_the_others_and_a_bad_one_is_refused(tmp_path):
    from physdbg.record.foreign import write_mcap_run

    times, xs, vs = simulate(load_scene("bullet-wall"), 3, 0.1)
    write_mcap_run(tmp_path / "s.mcap", times, xs, vs)
    report = api.check_run(tmp_path / "s.mcap", "bullet-wall").report
    assert report.first.cause == "tunnelling" and report.velocities == "given"
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file")
    done = CliRunner().invoke(app, ["check-run", str(tmp_path / "junk.mcap"), "--scene", "bullet-wall"])
    assert done.exit_code == 2 and "junk.mcap: not a readable MCAP file" in done.output
    own = api.record("bullet-wall", mcap_path=str(tmp_path / "own.mcap"), rrd=False, detail="state").mcap
    assert api.check_run(own, "bullet-wall").report.first is None  # a physdbg recording is a run too


# ----------------------------------------------------------------------------- the textbook mistakes
# One example run per mistake (docs/examples/mistakes/, written by tests/student_engine.py's
# swept student engine, which with integrator = euler is physdbg's own run), so the mistake
# is the first departure: (its step, its sphere).
FIRST = {"drag-per-step": (1, 0), "tangent-reversed": (28, 0), "restitution-sign": (16, 0),
         "impulse-doubled": (16, 0), "wrong-normal": (16, 0), "immovable-moved": (25, 0), "skipped-rest": (28, 0),
         "index-order": (44, 1), "one-missing": (16, 0), "impulse-loop": (16, 0)}
EXAMPLES_FOLDER = ROOT / "docs" / "examples" / "mistakes"


def same_numbers(fresh: str, kept: str, rtol: float = 1e-9) -> bool:
    """Two runs' text (CSV or JSON Lines of numbers) say the same: the same fields and rows,
    NaN and infinities in the same places, every finite number within rtol of the other
    (another CPU or numpy release may round a run that blows up, near 1e153, differently
    in its last digits: compared by what the numbers mean, never by those digits)."""
    import re

    def numbers(text: str) -> tuple[list[str], np.ndarray]:
        words = re.split(r"[-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|inf|nan|NaN|Infinity)", text)
        values = re.findall(r"[-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|inf|nan|NaN|Infinity)", text)
        return words, np.array([float(v.replace("Infinity", "inf")) for v in values])

    (words_a, a), (words_b, b) = numbers(fresh), numbers(kept)
    if words_a != words_b or a.shape != b.shape:
        return False
    finite = np.isfinite(a)
    if not np.array_equal(finite, np.isfinite(b)) or not np.array_equal(np.isnan(a), np.isnan(b)):
        return False
    return bool(np.all(a[~finite & ~np.isnan(a)] == b[~finite & ~np.isnan(b)])
                and np.allclose(a[finite], b[finite], rtol=rtol, atol=1e-12))


def test_the_example_runs_in_the_docs_are_the_student_engine_s(tmp_path):
    for mistake in MISTAKES:
        _, times, xs, vs = example_run(ROOT, mistake)
        write_csv(tmp_path / "fresh.csv", times, xs, vs)
        assert same_numbers((tmp_path / "fresh.csv").read_text(), (EXAMPLES_FOLDER / f"{mistake}.csv").read_text()), \
            mistake
    write_blown_up(ROOT, tmp_path / "blown-up.jsonl")
    assert same_numbers((tmp_path / "blown-up.jsonl").read_text(), (EXAMPLES_FOLDER / "blown-up.jsonl").read_text())


def test_the_example_runs_compare_by_meaning_not_by_last_digits():
    """impulse-loop.csv blows up to about 1e154: a last digit rounded otherwise (as on another
    CPU) is the same run; a change in the sixth digit, a finite number turned NaN, or a row
    less is not."""
    kept = (EXAMPLES_FOLDER / "impulse-loop.csv").read_text()
    big = next(word for word in kept.replace("\n", ",").split(",") if "e+15" in word)
    digit = big.index("e") - 1
    perturbed = big[:digit] + str((int(big[digit]) + 1) % 10) + big[digit + 1:]
    assert same_numbers(kept.replace(big, perturbed, 1), kept)
    sixth = big.replace(big[:8], big[:7] + str((int(big[7]) + 1) % 10), 1) if big[7].isdigit() else big
    assert not same_numbers(kept.replace(big, sixth, 1), kept)
    assert not same_numbers(kept.replace(big, "nan", 1), kept)
    assert not same_numbers(kept.rsplit("\n", 2)[0] + "\n", kept)


def test_the_swept_student_engine_done_right_does_not_depart(tmp_path):
    for name, overrides in {str(v): v for v in EXAMPLES.values()}.values():
        scene = load_scene(str(ROOT / name) if name.endswith(".toml") else name, overrides)
        steps = scene.steps or round(scene.duration / scene.dt)
        write_csv(tmp_path / "right.csv", *simulate_swept(scene, steps, scene.dt))
        report = api.check_run(tmp_path / "right.csv", scene).report
        assert report.exit_code == 0, (scene.name, report.headline)


@pytest.mark.parametrize("mistake", MISTAKES)
def test_each_textbook_mistake_is_named_with_its_step_sphere_and_code(mistake):
    name, overrides = EXAMPLES[mistake]
    scene = str(ROOT / name) if name.endswith(".toml") else name
    result = CliRunner().invoke(app, ["check-run", str(EXAMPLES_FOLDER / f"{mistake}.csv"), "--scene", scene,
                                      "--json", *[f"--set={o}" for o in overrides]])
    assert result.exit_code == 1, result.output
    report = json.loads(result.output)
    step, sphere = FIRST[mistake]
    assert (report["first"]["step"], report["first"]["body"], report["first"]["cause"]) == (step, sphere, mistake)
    named = next(d for d in report["departures"] if d["kind"] == mistake)
    assert named["step"] == step and named["advice"]


def test_the_drag_mistake_says_the_decay_it_measured_against_the_seed_s():
    report = api.check_run(EXAMPLES_FOLDER / "drag-per-step.csv", str(EXAMPLES_FOLDER / "coast.toml")).report
    drag = report.departures[0]
    assert kinds(report) == ["drag-per-step"]  # not an extra contact in every step, nor a drift
    assert drag.evidence["measured"] == pytest.approx(0.5)
    assert drag.evidence["expected"] == pytest.approx(0.5 ** (1 / 60))
    assert "depend on the frame rate" in drag.text and "drag ** dt" in drag.advice


def test_a_reflection_of_the_whole_velocity_names_the_seed_s_formula():
    report = api.check_run(EXAMPLES_FOLDER / "tangent-reversed.csv", str(EXAMPLES_FOLDER / "slide.toml")).report
    reflect = report.departures[0]
    assert reflect.kind == "tangent-reversed" and reflect.wall == "floor"
    assert reflect.evidence["tangential_before"] == pytest.approx(1.0)
    assert reflect.evidence["tangential_after"] == pytest.approx(-0.8)
    assert "R = Ri − 2N(Ri·N)" in reflect.advice and "chaotic" not in report.headline


def test_a_chaotic_gas_is_called_chaos_only_with_a_lyapunov_exponent(tmp_path):
    """A run of the gas with restitution 1 − 1e-9: every step ends within the tolerance of
    physdbg's, and the difference grows exponentially while spheres collide."""
    rec = open_recording(api.record("gas", ["generate.restitution=0.999999999", "duration=3"],
                                    mcap_path=str(tmp_path / "g.mcap"), rrd=False, detail="state").mcap)
    states = list(rec.states())
    write_jsonl(tmp_path / "gas.jsonl", np.array([s.time for s in states]), np.array([s.positions for s in states]),
                np.array([s.velocities for s in states]))
    report = api.check_run(tmp_path / "gas.jsonl", "gas", ["duration=3"]).report
    assert report.first.cause == "chaos" and kinds(report) == ["chaos"]
    assert report.departures[0].evidence["efolds"] >= 3 and "finite-time Lyapunov exponent" in report.headline


def test_a_slow_drift_with_no_cause_is_unexplained_not_chaos(tmp_path):
    """One ball under a gravity with a sideways part of 2e-5 m/s² the scene has not: each
    step ends within the tolerance, the gap grows smoothly, no two spheres collide."""
    scene = load_scene("bounce", ["integrator=euler", "steps=27"])
    off = load_scene("bounce", ["integrator=euler", "steps=27", "gravity=[2e-5, -9.81, 0]"])
    write_csv(tmp_path / "off.csv", *simulate_swept(off, 27, scene.dt))
    report = api.check_run(tmp_path / "off.csv", scene).report
    assert report.exit_code == 1 and report.first.cause == "unexplained"
    assert "physdbg cannot say why" in report.headline and "chao" not in report.headline.replace("not as chaos", "")


def test_a_javascript_engine_s_nan_arrives_as_null_and_is_named_by_step_and_body(tmp_path):
    """JSON.stringify(NaN) is "null": a blown-up JavaScript engine writes null coordinates."""
    scene = load_scene("bounce", ["integrator=euler", "steps=40"])
    times, xs, vs = simulate_swept(scene, 40, scene.dt)
    xs[30:, 0, 1] = np.nan
    vs[30:, 0, 1] = np.nan
    run = tmp_path / "js.jsonl"
    with open(run, "w") as f:
        for k, t in enumerate(times):
            f.write(json.dumps({"step": k, "time": float(t),
                                "positions": [[None if q != q else q for q in p] for p in xs[k].tolist()],
                                "velocities": [[None if q != q else q for q in p] for p in vs[k].tolist()]}) + "\n")
    assert "null" in run.read_text()
    report = api.check_run(run, scene).report
    assert report.exit_code == 1 and report.first.step == 30 and report.first.cause == "non-finite"
    nan = next(d for d in report.departures if d.kind == "non-finite")
    assert nan.step == 30 and nan.body == 0 and "position is NaN or infinite" in nan.text


# ----------------------------------------------------------------------------- physdbg's own rules
@pytest.mark.slow
def test_a_right_engine_s_break_shot_is_same_and_physdbg_s_rapid_contact_rule_is_named(tmp_path):
    """The seed's engine (earliest contact first, the rest of the step finished) on
    billiards: SAME, with nothing set aside, since no pile forms and the rapid-contact rule
    is off (rapid_contact_time = "auto"). With the rule on, as a scene may ask: in the
    break sphere 2 meets 3 16 µs after the cue ball, inside rapid_contact_time, where the
    rule makes that contact elastic; check-run says the run is the seed's model and names
    the rule, instead of blaming the engine."""
    scene = load_scene("billiards", ["integrator=euler"])
    steps = round(scene.duration / scene.dt)
    write_csv(tmp_path / "right.csv", *simulate_swept(scene, steps, scene.dt))
    plain = CliRunner().invoke(app, ["check-run", str(tmp_path / "right.csv"), "--scene", "billiards",
                                     "--set", "integrator=euler", "--json"])
    assert plain.exit_code == 0, plain.output
    plain = json.loads(plain.output)
    assert plain["first"] is None and plain["set_aside"] == [] and plain["headline"].startswith("no departure")
    result = CliRunner().invoke(app, ["check-run", str(tmp_path / "right.csv"), "--scene", "billiards",
                                      "--set", "integrator=euler", "--set", "rapid_contact_time=1e-4", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["first"] is None and report["departures"] == []
    (rule,) = report["set_aside"]
    assert (rule["rule"], rule["setting"], rule["value"], rule["step"]) == ("rapid-contact", "rapid_contact_time",
                                                                            0.0, 22)
    assert [2, 3, 0] in rule["contacts"]
    headline = report["headline"]
    assert headline.startswith("same as the seed's model") and "for all 480 steps" in headline
    assert "rapid-contact rule made the contact 2–3 in step 22 elastic instead of e = 0.95" in headline
    assert "µs after 0–2, within rapid_contact_time = 0.0001 s" in headline and "-s rapid_contact_time=0" in headline
    text = CliRunner().invoke(app, ["check-run", str(tmp_path / "right.csv"), "--scene", "billiards",
                                    "--set", "integrator=euler", "--set", "rapid_contact_time=1e-4"])
    assert text.exit_code == 0 and "result     SAME: same as the seed's model" in text.output


def test_a_real_mistake_after_physdbg_s_rule_is_still_named(tmp_path):
    """Compared without the rule, a run with a mistake still departs, at the mistake, and
    the headline says which rule was set aside."""
    scene = load_scene("billiards", ["integrator=euler", "rapid_contact_time=1e-4"])
    times, xs, vs = simulate_swept(scene, 120, scene.dt)
    xs[100:, 8] += 0.01  # a body moved by hand from step 100 on
    write_csv(tmp_path / "moved.csv", times, xs, vs)
    report = api.check_run(tmp_path / "moved.csv", scene).report
    assert report.exit_code == 1 and report.first.step == 100 and report.first.body == 8
    assert [a["rule"] for a in report.set_aside] == ["rapid-contact"]
    assert "compared against physdbg without its own rule" in report.headline


def test_diff_of_two_physdbg_runs_names_the_rapid_contact_rule_as_the_cause(tmp_path):
    a = api.record("billiards", ["integrator=euler", "steps=30", "rapid_contact_time=1e-4"],
                   mcap_path=str(tmp_path / "a.mcap"), rrd=False, detail="contacts").mcap
    b = api.record("billiards", ["integrator=euler", "steps=30", "rapid_contact_time=0"],
                   mcap_path=str(tmp_path / "b.mcap"), rrd=False, detail="contacts").mcap
    result = CliRunner().invoke(app, ["diff", a, b])
    assert result.exit_code == 1
    assert "e = 1 in A is physdbg's rapid-contact rule" in result.output
    assert "rapid_contact_time: 0.0001 (A)  0 (B)" in result.output


SLIDE = """
name = "slide"
dt = "1/60"
duration = 1.0
gravity = [0.0, -9.81, 0.0]
sleep_speed = 0.1
sleep_time = 0.1
[[planes]]
name = "floor"
normal = [0.0, 1.0, 0.0]
[[particles]]
position = [0.0, 0.1, 0.0]
velocity = [0.05, 0.0, 0.0]
radius = 0.1
restitution = 0.5
"""


def test_physdbg_s_sleeping_is_named_and_set_aside_where_it_froze_a_sphere_the_run_keeps_moving(tmp_path):
    """A ball sliding at 0.05 m/s on a floor, under sleep_speed = 0.1: physdbg freezes it
    after sleep_time, a run with no sleeping keeps it moving. Every step from the run's
    state ends where the run's does (a step starts with every sphere awake), so this is
    physdbg's rule: named, and the run compared again without sleeping: SAME."""
    (tmp_path / "slide.toml").write_text(SLIDE)
    run = api.record(str(tmp_path / "slide.toml"), ["sleep_speed=0"], mcap_path=str(tmp_path / "awake.mcap"),
                     rrd=False).mcap
    result = CliRunner().invoke(app, ["check-run", run, "--scene", str(tmp_path / "slide.toml"), "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    (rule,) = report["set_aside"]
    assert (rule["rule"], rule["setting"], rule["value"], rule["step"]) == ("sleeping", "sleep_speed", 0.0, 7)
    assert ("physdbg's sleeping rule put sphere 0 to sleep (frozen from step 7, once slower than sleep_speed = "
            "0.1 m/s for sleep_time = 0.1 s), where your run keeps it moving (0.05 m/s at step 7)") in report["headline"]
    assert "`-s sleep_speed=0` compares without it" in report["headline"]
    assert "unexplained" not in result.output and "chaos" not in result.output


def test_a_run_longer_than_check_run_compares_at_once_is_refused_before_the_reference_is_recorded(tmp_path,
                                                                                                 monkeypatch):
    from physdbg.analysis import departure_records  # where too_long reads its limit

    scene = load_scene("bounce", ["integrator=euler", "steps=60"])
    write_csv(tmp_path / "run.csv", *simulate_swept(scene, 60, scene.dt))
    monkeypatch.setattr(departure_records, "MAX_BODY_STEPS", 50)
    result = CliRunner().invoke(app, ["check-run", str(tmp_path / "run.csv"), "--scene", "bounce", "--set",
                                      "integrator=euler", "--set", "steps=60", "--keep", str(tmp_path / "kept")])
    assert result.exit_code == 2, result.output
    assert "61 frames of 1 body is 61 body-steps; check-run compares at most 50 at once" in result.output
    assert not (tmp_path / "kept" / "reference.mcap").exists()


# ----------------------------------------------------------------------------- ties
TIE = ROOT / "docs" / "examples" / "mistakes" / "tie.toml"


def test_a_tie_taken_in_another_order_is_named_a_tie_and_the_run_is_same(tmp_path):
    """Two balls meet a heavier one from both sides at one instant (docs/examples/mistakes/
    tie.toml). A right engine that takes the last-found of tied contacts first ends the
    step elsewhere than physdbg, which takes 0–1 first; check-run takes physdbg's step
    again in the run's order, names the tie, and goes on from there: SAME."""
    scene = load_scene(str(TIE))
    times, xs, vs = simulate_swept(scene, scene.steps, scene.dt, ties="last")
    first_taken = simulate_swept(scene, scene.steps, scene.dt)[1]
    assert np.abs(xs[-1] - first_taken[-1]).max() > 0.4  # the order changes the outcome
    write_csv(tmp_path / "last.csv", times, xs, vs)
    result = CliRunner().invoke(app, ["check-run", str(tmp_path / "last.csv"), "--scene", str(TIE), "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["first"] is None and report["departures"] == [] and report["set_aside"] == []
    (tie,) = report["ties"]
    assert tie["step"] == 20 and tie["time"] == pytest.approx(0.32, abs=1e-12)
    assert tie["physdbg_order"][0] == [0, 1, 0] and sorted(tie["run_order"][0][:2]) == [1, 2]
    assert "collision-order" not in result.output and "collision order" not in result.output
    headline = report["headline"]
    assert headline.startswith("same as the seed's model") and "for all 60 steps" in headline
    assert "in step 20 the contacts 0–1 and 1–2 happen at one instant (t = 0.32 s)" in headline
    assert "your run takes 1–2 first" in headline and "taken in your run's order" in headline
    from physdbg.analysis.classroom import row_of

    row = row_of("last.csv", api.check_run(tmp_path / "last.csv", scene).report)  # a class's table says it too
    assert (row.verdict, row.cause) == ("SAME", "tie (either order)")
    # the engine that takes ties as physdbg does: no tie to name
    write_csv(tmp_path / "first.csv", times, first_taken, simulate_swept(scene, scene.steps, scene.dt)[2])
    plain = api.check_run(tmp_path / "first.csv", scene).report
    assert plain.exit_code == 0 and plain.ties == [] and plain.headline.startswith("no departure")


def test_a_tie_in_a_step_that_departs_for_another_reason_later_is_still_a_tie(tmp_path):
    """After the tie, a body moved by hand: the run departs there, and the headline says
    the tie before it was taken in the run's order."""
    scene = load_scene(str(TIE))
    times, xs, vs = simulate_swept(scene, scene.steps, scene.dt, ties="last")
    xs[40:, 2] += 0.01
    write_csv(tmp_path / "moved.csv", times, xs, vs)
    report = api.check_run(tmp_path / "moved.csv", scene).report
    assert report.exit_code == 1 and report.first.step == 40 and report.first.body == 2
    assert [t["step"] for t in report.ties] == [20]
    assert "tie" not in kinds(report) and "collision-order" not in kinds(report)
    assert "(before it, in step 20 the contacts 0–1 and 1–2 happen at one instant" in report.headline


def test_diff_of_two_physdbg_runs_names_a_tie_as_the_cause(tmp_path):
    """The tie scene with its spheres listed right to left: the given numbering takes 0–1
    (the right-hand pair) first, the Morton numbering the left-hand one: diff names the
    tie and the numbering, never a missed contact or collision order."""
    text = TIE.read_text()
    head, *spheres = text.split("[[particles]]")
    (tmp_path / "tie.toml").write_text(head + "".join("[[particles]]" + p.rstrip("\n") + "\n\n"
                                                      for p in reversed(spheres)))
    runs = [api.record(str(tmp_path / "tie.toml"), [f"space_order={order}"], mcap_path=str(tmp_path / f"{order}.mcap"),
                       rrd=False, detail="contacts").mcap for order in ("given", "morton")]
    result = CliRunner().invoke(app, ["diff", *runs])
    assert result.exit_code == 1
    assert "the contacts 0–1 and 1–2 happen at one instant (t = 0.20·dt) in both runs" in result.output
    assert "This is a tie" in result.output and "space_order: given in A, morton in B" in result.output
    assert "[tie] the main cause" in result.output
    assert "missed-contact" not in result.output and "collision-order" not in result.output


# ----------------------------------------------------------------------------- units
def test_a_time_column_in_milliseconds_is_named_and_read_with_time_unit_ms(tmp_path):
    scene = load_scene("bounce", ["integrator=euler", "steps=60"])
    times, xs, vs = simulate_swept(scene, 60, scene.dt)
    write_csv(tmp_path / "ms.csv", times * 1000.0, xs, vs)  # Date.now()
    args = ["check-run", str(tmp_path / "ms.csv"), "--scene", "bounce", "--set", "integrator=euler", "--set", "steps=60"]
    refused = CliRunner().invoke(app, args)
    assert refused.exit_code == 2
    assert refused.output.count("\n") == 1, refused.output  # one line
    assert "time column counts milliseconds: its steps are 16.6667 where the scene's dt is 0.0166667 s" in refused.output
    assert "Date.now()" in refused.output and "--time-unit ms" in refused.output
    read = CliRunner().invoke(app, [*args, "--time-unit", "ms"])
    assert read.exit_code == 0 and "result     SAME" in read.output, read.output


@pytest.mark.parametrize("unit, factor", [("cm", 100.0), ("mm", 1000.0)])
def test_positions_in_centimetres_or_millimetres_are_named_and_read_with_length_unit(tmp_path, unit, factor):
    scene = load_scene("bounce", ["integrator=euler", "steps=60"])
    times, xs, vs = simulate_swept(scene, 60, scene.dt)
    write_jsonl(tmp_path / "run.jsonl", times, xs * factor, vs * factor)
    with pytest.raises(ForeignRunError, match=f"positions are in {'centimetres' if unit == 'cm' else 'millimetres'}"):
        api.check_run(tmp_path / "run.jsonl", scene)
    assert api.check_run(tmp_path / "run.jsonl", scene, length_unit=unit).report.exit_code == 0
    imported = api.import_run(tmp_path / "run.jsonl", scene, mcap_path=tmp_path / "run.mcap", length_unit=unit)
    assert open_recording(imported.mcap).state(60).positions == pytest.approx(xs[60])


def test_an_unknown_unit_is_a_clear_error():
    result = CliRunner().invoke(app, ["check-run", str(EXAMPLES_FOLDER / "one-missing.csv"), "--scene",
                                      str(EXAMPLES_FOLDER / "glance.toml"), "--length-unit", "km"])
    assert result.exit_code == 2 and "length unit 'km': not one physdbg reads (one of m, cm, mm)" in result.output


# ----------------------------------------------------------------------------- impulse mistakes
def test_the_missing_one_of_one_plus_e_is_named_with_energy_lost_not_gained():
    report = api.check_run(EXAMPLES_FOLDER / "one-missing.csv", str(EXAMPLES_FOLDER / "glance.toml")).report
    named = report.departures[0]
    assert named.kind == "one-missing" and named.evidence["restitution"] == pytest.approx(-0.1, abs=1e-3)
    assert '"1 +" is missing' in named.text and "energy lost, not gained" in named.advice
    assert "energy gained" not in report.headline


def test_a_flipped_impulse_that_loops_to_nan_is_named_at_its_start(tmp_path):
    """No once-a-step guard: the pair, pushed together, meets again at once, and again,
    until the numbers overflow; the run holds NaN from that step on."""
    scene, times, xs, vs = example_run(ROOT, "impulse-loop")
    xs[16:], vs[16:] = np.nan, np.nan
    write_jsonl(tmp_path / "nan.jsonl", times, xs, vs)
    report = api.check_run(tmp_path / "nan.jsonl", scene).report
    assert report.first.step == 16 and report.first.cause == "impulse-loop"
    loop = next(d for d in report.departures if d.kind == "impulse-loop")
    assert (loop.step, loop.body, loop.other) == (16, 0, 1)
    assert "NaN or infinite" in loop.text and "(2 + e) = 2.9 times" in loop.text
    assert "missed-contact" not in kinds(report)


def test_each_cause_of_check_run_is_named_by_the_judgements_its_table_row_lists():
    """departure.DEPARTURE_KINDS is check-run's one table of causes: every method a row
    lists exists and names that kind (in its source, or, for a restitution mistake, through
    restitution_mistake or step_with_mistake), and every kind a judgement names has its row."""
    import inspect
    import re

    from physdbg.analysis import departure

    restitution = {code for code, *_ in departure.RESTITUTION_MISTAKES}
    named_by: dict[str, set[str]] = {}
    for name, method in inspect.getmembers(departure._Comparison, inspect.isfunction):
        source = inspect.getsource(method)
        kinds = {k for k in departure.DEPARTURE_KINDS if f'"{k}"' in source}
        if "restitution_mistake(" in source or "step_with_mistake(" in source:
            kinds |= restitution
        for kind in kinds:
            named_by.setdefault(kind, set()).add(name)
    for kind, (_, methods) in departure.DEPARTURE_KINDS.items():
        assert all(getattr(departure._Comparison, m.__name__) is m for m in methods), kind  # its own methods
        names = {m.__name__ for m in methods}
        assert names <= named_by.get(kind, set()), (kind, names, named_by.get(kind))
    # every kind made with a literal in an _add or a Departure(...) has its row
    from physdbg.analysis import departure_contacts, departure_flight, departure_steps

    judges = "".join(inspect.getsource(module) for module in (departure, departure_contacts, departure_flight,
                                                              departure_steps))
    made = set(re.findall(r'(?:_add\(|Departure\(\s*)"([a-z-]+)"', judges))
    assert made and made <= set(departure.DEPARTURE_KINDS)
