"""physdbg diff: each cause built on purpose and recognised, with the right step and event."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest
from typer.testing import CliRunner

from physdbg import api
from physdbg.analysis import diff
from physdbg.cli import app

ROOT = Path(__file__).resolve().parent.parent


def _rec(tmp_path, name, scene, overrides=(), detail="contacts"):
    out = tmp_path / f"{name}.mcap"
    api.record(scene, list(overrides), mcap_path=str(out), rrd=False, detail=detail)
    return out


def _kinds(report):
    return [c.kind for c in report.causes]


def test_discrete_tunnelling_through_the_thin_wall(tmp_path):
    r = diff(_rec(tmp_path, "a", "bullet-wall"), _rec(tmp_path, "b", "bullet-wall", ["detection=discrete"]))
    assert r.exit_code == 1 and r.divergence.step == 1
    assert r.settings[0].name == "detection" and (r.settings[0].a, r.settings[0].b) == ("swept", "discrete")
    tunnel = next(c for c in r.causes if c.kind == "tunnelling")
    assert tunnel.evidence["run"] == "B" and "went through wall 'thin wall'" in tunnel.text
    assert "run A resolved a contact there at 0.090·dt" in tunnel.text


def test_index_against_time_ordering_is_a_collision_order(tmp_path):
    r = diff(_rec(tmp_path, "a", "cradle"), _rec(tmp_path, "b", "cradle", ["ordering=index"]))
    assert r.divergence.step == 44 and r.divergence.first_event["index"] == 1
    assert r.divergence.first_event["a"]["a"] == 1 and r.divergence.first_event["b"] is None
    order = next(c for c in r.causes if c.kind == "collision-order")
    assert "run A (ordering = time) resolved 0–1 (t = 0.80·dt), then 1–2" in order.text
    assert "From there sphere 1 leaves at 0.00 m/s in A and 1.00 m/s in B" in order.text


@pytest.mark.slow
def test_dt_is_aligned_by_time_drift_for_euler_and_equivalent_for_the_exact_integrator(tmp_path):
    r = diff(_rec(tmp_path, "a", "bounce", ["integrator=euler"]),
             _rec(tmp_path, "b", "bounce", ["integrator=euler", "dt=1/240"]))
    assert r.aligned_by == "time" and (r.divergence.step, r.divergence.step_b) == (1, 4)
    assert _kinds(r) == ["settings", "method-drift"] and r.growth.model in ("power", "exponential")
    # the exact path does not depend on dt: the same bounces within 1e-9
    exact = diff(_rec(tmp_path, "c", "bounce"), _rec(tmp_path, "d", "bounce", ["dt=1/240"]))
    assert exact.aligned_by == "time" and exact.equivalent and exact.exit_code == 0
    assert exact.compared == 301


def test_restitution_changes_the_outcome_of_the_same_contact(tmp_path):
    r = diff(_rec(tmp_path, "a", "bounce"), _rec(tmp_path, "b", "bounce", ["particles.0.restitution=0.9"]))
    assert r.divergence.step == 28 and r.divergence.first_event["index"] == 0
    assert [s.name for s in r.settings] == ["particles.0.restitution"]
    outcome = next(c for c in r.causes if c.kind == "contact-outcome")
    assert "e = 0.8 in A" in outcome.text and "e = 0.9 in B" in outcome.text


def test_exact_against_verlet_under_drag_is_method_drift_from_step_one(tmp_path):
    r = diff(_rec(tmp_path, "a", "billiards", ["duration=1"]),
             _rec(tmp_path, "b", "billiards", ["duration=1", "integrator=verlet"]))
    assert r.divergence.step == 1 and r.divergence.first_event is None
    assert _kinds(r) == ["settings", "method-drift"] and "integrator" in r.causes[1].text
    assert r.growth.steps_to_mm is not None and r.growth.steps_to_mm > 0


def test_a_nudge_of_one_picometre_is_an_outside_change_at_the_next_step(tmp_path):
    from physdbg.record.header import RecordingHeader
    from physdbg.record.mcap_sink import McapRecorder
    from physdbg.api import load_scene

    paths = []
    for name, nudge in (("plain", False), ("nudged", True)):
        scene = load_scene("gas", ["duration=1"])
        paths.append(tmp_path / f"{name}.mcap")
        with McapRecorder(paths[-1], RecordingHeader.from_scene(scene, "contacts")) as rec:
            world = scene.build_world(rec)
            for k, dt in enumerate(scene.step_lengths()):
                world.step(dt)
                if nudge and k == 49:  # after step 50: a script moves sphere 3 by 1e-12 m
                    world.state.positions[3, 0] += 1e-12
    r = diff(*paths)
    assert r.divergence.step == 51 and _kinds(r) == ["outside-change"]
    assert r.divergence.state.particles[0]["particle"] == 3
    assert r.growth.model == "exponential" and r.growth.rate > 0 and r.growth.chaotic
    assert "finite-time Lyapunov exponent" in r.growth.sentence()


def test_a_sphere_asleep_in_one_run_only_is_named_when_it_falls_asleep_and_when_it_is_hit(tmp_path):
    """Sleeping (engine/sleep.py) parts runs in two ways diff names from the recorded
    asleep masks: a sphere falls asleep in one run only (its velocity set to zero), or a
    sleeper that is exactly where the other run's awake sphere is gets hit."""
    pile = ["generate.count=100", "box.max=[0.3,1,0.3]", "generate.speed=0", "generate.restitution=0.5",
            "box.restitution=0.5", "rapid_contact_rule=tc", "steps=20", "sleep_speed=0.05"]
    r = diff(_rec(tmp_path, "a", "rain", pile + ["sleep_time=0.1"]), _rec(tmp_path, "b", "rain", pile + ["sleep_time=0.2"]))
    assert r.divergence.step == 15 and _kinds(r) == ["settings", "sleep"]
    assert ("sphere 10 fell asleep at the end of the step in run A and did not in run B (sleep_time: 0.1 in A, "
            "0.2 in B). Falling asleep sets its velocity to zero") in r.causes[1].text
    assert r.headline.startswith("the runs part in step 15: sphere 10 fell asleep")
    # the rest scene's row lies exactly still in both runs, asleep only in A, until a ball lands on it
    text = (ROOT / "physdbg" / "scenes" / "rest.toml").read_text()
    drop = tmp_path / "drop.toml"
    drop.write_text(text.replace("position = [4.0, 1.6, 0.0]", "position = [4.25, 2.5, 0.0]"))
    r = diff(_rec(tmp_path, "c", str(drop), ["sleep_speed=0.05", "sleep_time=0.1", "duration=1"]),
             _rec(tmp_path, "d", str(drop), ["duration=1"]))
    sleep = next(c for c in r.causes if c.kind == "sleep")
    assert r.divergence.step == 28 and _kinds(r)[:2] == ["settings", "sleep"]
    assert sleep.step == 28 and sleep.bodies == (3,)
    assert sleep.text.startswith("sphere 3 was asleep in run A and awake in run B when the step began")
    # sphere 3 sleeps on: only the sphere hit (4) is woken by the impact
    assert sleep.evidence == {"particle": 3, "asleep_at_start": [True, False], "asleep_at_end": [True, False]}


def test_the_event_cap_hit_in_one_run_only(tmp_path):
    r = diff(_rec(tmp_path, "a", "rain"), _rec(tmp_path, "b", "rain", ["max_contacts_per_step=20"]))
    limits = next(c for c in r.causes if c.kind == "engine-limits")
    assert "run B hit the max_contacts_per_step budget in step" in limits.text
    assert f"step {r.divergence.step}" in limits.text


def test_two_broad_phases_are_equivalent_and_say_why_the_setting_cannot_matter(tmp_path):
    r = diff(_rec(tmp_path, "a", "rain", ["broad_phase=grid"]), _rec(tmp_path, "b", "rain", ["broad_phase=bvh-sah"]))
    assert r.equivalent and r.exit_code == 0 and r.atol == 0
    assert r.settings[0].name == "broad_phase" and not r.settings[0].matters


def test_a_tampered_file_is_an_error_naming_the_frame_or_the_damage(tmp_path):
    a = _rec(tmp_path, "a", "cradle")
    b = _rec(tmp_path, "b", "cradle")
    data = bytearray(b.read_bytes())
    data[len(data) // 2] ^= 0xFF
    b.write_bytes(bytes(data))
    result = CliRunner().invoke(app, ["diff", str(a), str(b)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert str(b) in result.output


@pytest.mark.slow
def test_bit_identical_states_with_an_edited_contact_record_are_different_records(tmp_path):
    """Every state agrees bit for bit, but one recorded contact's impulse was edited: not
    the same record, and never "equivalent" (the states alone cannot show it)."""
    from . import tamper

    a = _rec(tmp_path, "a", "bounce")
    from physdbg import open_recording

    with open_recording(a) as rec:
        frame = next(k for k in range(1, rec.frames) if len(rec.contacts(k)))
        impulse = float(rec.contacts(frame).impulse[0])
    b = tamper.edit_contact(a, tmp_path / "b.mcap", frame, impulse=impulse * 1.5)
    report = diff(a, b)
    assert report.exit_code == 1 and _kinds(report) == ["records"] and report.divergence is None
    assert report.headline == (f"different records: every state is bit-identical, but the contacts recorded for step "
                               f"{frame} differ: contact 1 (0–wall 'floor') has another impulse")
    assert diff(a, a).exit_code == 0  # the same file is the same record


def test_cli_formats_and_exit_codes(tmp_path):
    a, b = _rec(tmp_path, "a", "cradle"), _rec(tmp_path, "b", "cradle", ["ordering=index"])
    runner = CliRunner()
    text = runner.invoke(app, ["diff", str(a), str(b)])
    assert text.exit_code == 1 and "DIFFERENT" in text.output and "collision-order" in text.output
    as_json = runner.invoke(app, ["diff", str(a), str(b), "--json"])
    report = json.loads(as_json.output)
    assert report["exit_code"] == 1 and report["divergence"]["step"] == 44
    assert runner.invoke(app, ["diff", str(a), str(b), "--markdown"]).output.startswith("### ❌ physdbg diff")
    same = runner.invoke(app, ["diff", str(a), str(a)])
    assert same.exit_code == 0 and "EQUIVALENT" in same.output
    loose = runner.invoke(app, ["diff", str(a), str(b), "--atol", "1", "--rtol", "0", "--format", "json"])
    assert json.loads(loose.output)["atol"] == 1.0
    bad_format = runner.invoke(app, ["diff", str(a), str(b), "--format", "yaml"])
    assert bad_format.exit_code == 2 and "--format must be text, json or markdown" in bad_format.output
    no_golden = runner.invoke(app, ["record", "cradle", "--no-rrd", "-o", str(tmp_path / "c.mcap"),
                                    "--check-against", str(tmp_path / "none.mcap")])
    assert no_golden.exit_code == 2 and "no such recording to check against" in no_golden.output
    missing = runner.invoke(app, ["diff", str(a), str(tmp_path / "nope.mcap")])
    assert missing.exit_code == 2 and "nope.mcap" in missing.output


@pytest.mark.slow
def test_the_overlay_holds_both_runs_under_two_roots(tmp_path):
    from rerun.chunk import RrdReader  # rerun's own reader

    a, b = _rec(tmp_path, "a", "cradle"), _rec(tmp_path, "b", "cradle", ["ordering=index"])
    out = tmp_path / "overlay.rrd"
    result = CliRunner().invoke(app, ["diff", str(a), str(b), "--rrd", str(out)])
    assert result.exit_code == 1 and out.exists(), result.output
    chunks = list(RrdReader(out).stream())
    paths = {str(chunk.entity_path) for chunk in chunks}
    for root in ("/a", "/b"):
        assert {f"{root}/world/spheres", f"{root}/stats/energy/total", f"{root}/world/diverging/rings",
                f"{root}/world/diverging/gap"} <= paths, paths
    assert "/divergence" in paths
    # the blueprint opens on the "diverged" timeline, paused, and a paused viewer opens at its
    # first time: the rows on it begin at the diverging step
    opening = [t for chunk in chunks if "diverged" in chunk.timeline_names
               for t in chunk.to_record_batch().column("diverged").to_pylist() if t is not None]
    assert min(opening) == 44
    again = CliRunner().invoke(app, ["diff", str(a), str(b), "--rrd", str(out)])
    assert again.exit_code == 2 and "--force" in again.output


@pytest.mark.parametrize("scene", ["billiards", "bounce", "bullet-wall", "cradle", "funnel", "gas", "rain", "ramp", "rest"])
@pytest.mark.slow
def test_every_builtin_scene_still_matches_its_ci_golden(tmp_path, scene):
    """Every built-in scene but highspeed (5,000 spheres for 600 steps: a golden of tens of
    MB and half a minute a run; tests/test_mesh_runs.py runs it small)."""
    golden = ROOT / "recordings" / "ci" / f"{scene}.mcap"
    result = CliRunner().invoke(app, ["record", scene, "--no-rrd", "--detail", "contacts", "-o",
                                      str(tmp_path / "new.mcap"), "--check-against", str(golden)])
    assert result.exit_code == 0, result.output
    assert "EQUIVALENT" in result.output


# ----------------------------------------------------------------------------- verdicts a CI can stake a merge on
def test_runs_of_different_sizes_are_a_structure_difference_never_equivalent(tmp_path):
    a = _rec(tmp_path, "a", "rain", ["generate.count=100", "steps=20"], detail="state")
    b = _rec(tmp_path, "b", "rain", ["generate.count=101", "steps=20"], detail="state")
    r = diff(a, b)
    assert r.exit_code == 1 and not r.equivalent and r.causes[0].kind == "structure"
    assert "100 in A, 101 in B" in r.causes[0].text and r.headline.startswith("different structure")
    result = CliRunner().invoke(app, ["diff", str(a), str(b)])
    assert result.exit_code == 1 and "DIFFERENT" in result.output and "EQUIVALENT" not in result.output


def test_spheres_of_another_radius_or_kind_are_a_structure_difference(tmp_path):
    a = _rec(tmp_path, "a", "cradle", ["steps=5"])
    bigger = diff(a, _rec(tmp_path, "b", "cradle", ["steps=5", "particles.4.radius=0.2"]))
    assert bigger.exit_code == 1 and bigger.causes[0].kind == "structure"
    assert "sphere 4: 0.5 m in A, 0.2 m in B" in bigger.causes[0].text
    pinned = diff(a, _rec(tmp_path, "c", "cradle", ["steps=5", "particles.4.inverse_mass=0"]))
    assert pinned.exit_code == 1 and "sphere 4 is movable in A and immovable in B" in pinned.causes[0].text
    other = diff(_rec(tmp_path, "d", "bounce", ["steps=5"]), _rec(tmp_path, "e", "bullet-wall", ["steps=5"]))
    assert other.exit_code == 1 and "different scenes ('bounce' in A, 'bullet-wall' in B)" in other.causes[0].text


def test_runs_that_differ_from_the_start_are_an_initial_state_difference_without_a_crash(tmp_path):
    a = _rec(tmp_path, "a", "bounce")
    b = _rec(tmp_path, "b", "bounce", ["particles.0.position=[0, 1.101, 0]"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy warning reaches the user either
        r = diff(a, b)
    assert r.exit_code == 1 and r.divergence.step == 0
    start = next(c for c in r.causes if c.kind == "initial-state")
    assert "at frame 0, before any step, 1 sphere differs (sphere 0 by 0.001 m" in start.text
    assert r.headline.startswith("the runs differ from the start")
    result = CliRunner().invoke(app, ["diff", str(a), str(b), "--json"])
    assert result.exit_code == 1 and json.loads(result.output)["divergence"]["step"] == 0


def test_a_shorter_run_says_how_much_longer_the_other_goes_on(tmp_path):
    r = diff(_rec(tmp_path, "a", "bounce", ["steps=300"]), _rec(tmp_path, "b", "bounce", ["steps=200"]))
    length = next(c for c in r.causes if c.kind == "length")
    assert r.exit_code == 1
    assert length.text == "the runs agree for the 200 steps both have; run A goes on for 100 more steps"


def test_a_run_that_turns_nan_is_named_without_a_numpy_warning(tmp_path, monkeypatch):
    from physdbg.errors import NonFiniteRunError

    from .conftest import nan_in_step

    good = _rec(tmp_path, "good", "cradle", ["steps=10"])
    nan_in_step(monkeypatch)  # sphere 1's velocity turns NaN as step 3 begins
    with pytest.raises(NonFiniteRunError):
        _rec(tmp_path, "nan", "cradle", ["steps=10"])
    monkeypatch.undo()
    bad = tmp_path / "nan.mcap"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = diff(good, bad)
        audit = api.explain(bad)
    assert r.exit_code == 1 and r.divergence.step == 3 and r.causes[0].kind == "non-finite"
    assert "cannot be measured from step 3 on" in r.growth.sentence()
    assert audit.counts == {"non-finite": 1}
    result = CliRunner().invoke(app, ["diff", str(good), str(bad), "--json"])
    assert result.exit_code == 1 and "Warning" not in result.output
    json.loads(result.output)


def test_a_one_ball_drift_between_integrators_is_not_called_chaotic(tmp_path):
    """No two spheres collide: however fast the gap grows, it is a drift, not chaos."""
    scene = tmp_path / "coast.toml"
    scene.write_text('name = "coast"\ndescription = "a ball thrown up under drag"\ndt = "1/60"\nduration = 5.0\n'
                     'gravity = [0.0, -9.81, 0.0]\ndrag = 0.5\n[[particles]]\nposition = [0.0, 0.0, 0.0]\n'
                     'velocity = [1.0, 5.0, 0.0]\nradius = 0.1\nmass = 1.0\n')
    r = diff(_rec(tmp_path, "a", str(scene)), _rec(tmp_path, "b", str(scene), ["integrator=verlet"]))
    assert r.exit_code == 1 and not r.growth.chaotic
    assert "chaotic" not in r.headline and "not chaos: no two spheres collide" in r.growth.sentence()


@pytest.mark.slow
def test_the_overlay_opens_on_the_divergence_in_two_colours_in_the_real_viewer(tmp_path, virtual_display):
    """A screenshot of the overlay as it opens: run A's spheres blue on the left, run B's
    orange on the right, the diverging spheres ringed in magenta in both."""
    import os
    import subprocess

    import numpy as np
    from PIL import Image

    from physdbg.record.rerun_sink import viewer_binary

    a, b = _rec(tmp_path, "a", "cradle"), _rec(tmp_path, "b", "cradle", ["ordering=index"])
    out = tmp_path / "overlay.rrd"
    assert CliRunner().invoke(app, ["diff", str(a), str(b), "--rrd", str(out)]).exit_code == 1
    shot = tmp_path / "overlay.png"
    done = subprocess.run([viewer_binary(), str(out), "--new", "--screenshot-to", str(shot),
                           "--window-size", "1200x750"],
                          env=dict(os.environ, DISPLAY=virtual_display, CI="1"), capture_output=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    image = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    height, width, _ = image.shape
    top = image[int(height * 0.08): int(height * 0.45)]
    left, right = top[:, : width // 2], top[:, width // 2:]

    def count(part, rgb, slack=45):
        return int((np.abs(part - np.array(rgb)).max(axis=2) < slack).sum())

    from physdbg.analysis.overlay import COLOR_A, COLOR_B, RING_COLOR

    assert count(left, COLOR_A) > 300 and count(left, COLOR_B) < count(left, COLOR_A) / 5
    assert count(right, COLOR_B) > 300 and count(right, COLOR_A) < count(right, COLOR_B)
    assert count(left, RING_COLOR) > 50 and count(right, RING_COLOR) > 50


def test_the_header_says_which_frames_were_compared(tmp_path):
    """Two 120-step runs that part in step 1 are compared up to that step, and the header
    says so against the frames both hold (it once said only "compared 2 frames"); a run
    against itself is compared in full."""
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    api.record("bounce", ["steps=120"], mcap_path=str(a), rrd=False)
    api.record("bounce", ["steps=120", "integrator=euler"], mcap_path=str(b), rrd=False)
    out = CliRunner().invoke(app, ["diff", str(a), str(b)]).output
    assert ("compared 2 of the 121 frames both runs hold, aligned by step: frame 0 to the first difference (step 1), "
            "where the comparison stops") in out, out
    same = CliRunner().invoke(app, ["diff", str(a), str(a)]).output
    assert "compared all 121 frames both runs hold, aligned by step" in same, same
