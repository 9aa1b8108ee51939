"""Runs of other engines: imported from CSV and JSON Lines, audited, refused clearly when
they do not fit the format or the scene."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import api, open_recording
from physdbg.analysis import explain
from physdbg.analysis.tunnel_words import FOREIGN_ADVICE
from physdbg.cli import app
from physdbg.api import load_scene
from tests.student_engine import simulate, write_csv, write_jsonl


@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_the_student_engine_tunnels_the_thin_wall_and_explain_says_so(tmp_path, fmt):
    scene = load_scene("bullet-wall")
    times, xs, vs = simulate(scene, 3, 0.1)
    run = tmp_path / f"student.{fmt}"
    (write_csv if fmt == "csv" else write_jsonl)(run, times, xs, vs)
    done = CliRunner().invoke(app, ["import", str(run), "--scene", "bullet-wall", "-o", str(tmp_path / "s.mcap")])
    assert done.exit_code == 0, done.output
    assert "imported    3 steps of 1 body" in done.output and "velocities given" in done.output
    again = CliRunner().invoke(app, ["import", str(run), "--scene", "bullet-wall", "-o", str(tmp_path / "s.mcap")])
    assert again.exit_code == 2 and "already exists; pass --force" in again.output
    forced = CliRunner().invoke(app, ["import", str(run), "--scene", "bullet-wall", "-o", str(tmp_path / "s.mcap"),
                                      "--force"])
    assert forced.exit_code == 0, forced.output
    rec = open_recording(tmp_path / "s.mcap")
    assert np.array_equal(rec.state(2).positions, xs[2]) and rec.meta["foreign"]["format"] == fmt
    report = explain(rec)
    tunnel = [f for f in report.findings if f.kind == "tunnelling"]
    assert tunnel and tunnel[0].step == 1 and "went through wall 'thin wall' with no contact" in tunnel[0].message
    # explain and check-run give another engine's tunnelling one piece of advice (tunnel_words)
    assert tunnel[0].advice == FOREIGN_ADVICE and FOREIGN_ADVICE.startswith("test for contacts along the path")


def test_a_late_bounce_leaves_an_overlap_and_a_flipped_impulse_gains_energy(tmp_path):
    bounce = load_scene("bounce")
    times, xs, vs = simulate(bounce, 120, 1 / 60)
    write_csv(tmp_path / "bounce.csv", times, xs)  # no velocities: estimated from positions
    result = api.import_run(tmp_path / "bounce.csv", bounce, mcap_path=tmp_path / "b.mcap")
    assert result.velocities == "estimated"
    kinds = {f.kind for f in explain(result.mcap).findings}
    assert "overlap" in kinds  # tested only where each step ends: the ball is found inside the floor
    head_on = load_scene("cradle", ["particles.2.position=[20.0, 0.0, 0.0]", "particles.3.position=[30.0, 0.0, 0.0]",
                                    "particles.4.position=[40.0, 0.0, 0.0]"])
    times, xs, vs = simulate(head_on, 120, 1 / 60, flip=True)
    write_jsonl(tmp_path / "flip.jsonl", times, xs, vs)
    found = explain(api.import_run(tmp_path / "flip.jsonl", head_on, mcap_path=tmp_path / "f.mcap").mcap).findings
    gain = [f for f in found if f.kind == "energy-gain"]
    assert gain and "wrong sign" in gain[0].advice and sorted(gain[0].particles) == [0, 1]


def test_explain_of_the_readme_s_student_run_blames_no_contact_for_euler_s_drift_in_flight(tmp_path):
    """The README's student bounce (explicit Euler, a bounce tested where the step ends):
    explain finds what check-run finds, the late bounce at step 28 (the ball 30 mm inside
    the floor), and no energy-gain in free flight, where Euler gains 0.1-0.2 % a step by
    design: that drift is a note naming the integrator."""
    from pathlib import Path

    csv = Path(__file__).resolve().parent.parent / "docs" / "examples" / "student-bounce.csv"
    done = CliRunner().invoke(app, ["import", str(csv), "--scene", "bounce", "-o", str(tmp_path / "s.mcap")])
    assert done.exit_code == 0, done.output
    report = explain(tmp_path / "s.mcap")
    assert report.counts == {"overlap": 1}
    assert report.findings[0].step == 28 and "30 mm" in report.findings[0].message
    assert any(note.startswith("in free flight (58 steps with no kick) the run gained") and "explicit Euler" in note
               for note in report.notes)
    checked = CliRunner().invoke(app, ["check-run", str(csv), "--scene", "bounce", "-s", "integrator=euler"])
    assert checked.exit_code == 1 and "step 28 [bounce-time]" in checked.output


def test_physdbg_s_own_run_exported_and_imported_is_clean(tmp_path):
    rec = open_recording(api.record("cradle", mcap_path=str(tmp_path / "c.mcap"), rrd=False, detail="state").mcap)
    states = list(rec.states())
    times = np.array([s.time for s in states])
    write_jsonl(tmp_path / "own.jsonl", times, np.array([s.positions for s in states]),
                np.array([s.velocities for s in states]))
    imported = open_recording(api.import_run(tmp_path / "own.jsonl", "cradle", mcap_path=tmp_path / "own.mcap").mcap)
    assert [imported.state(k).state_hash for k in range(imported.frames)] == [s.state_hash for s in states]
    assert explain(imported).findings == []
    with pytest.raises(api.PhysdbgError, match="a run of another engine"):
        api.verify(imported.path)


@pytest.mark.parametrize("text, message", [
    ("step,time,body,x,y\n", "line 1: the header lacks z"),
    ("step,time,body,x,y,z\n0,0,0,0,0,0\n0,0,1,0,0,0\n", "line 3: field 'body' is 1; the scene has 1 body (0..0)"),
    ("step,time,body,x,y,z\n0,0,0,0,0,0\n2,0.1,0,0,0,0\n", "line 3: field 'step' is 2; expected 1"),
    ("step,time,body,x,y,z\n0,0,0,0,0,0\n1,0,0,0,0,0\n", "line 3: field 'time' is 0.0, the same as the step before; "
                                                       "time must increase. A clock that counts whole milliseconds"),
    ("step,time,body,x,y,z\n0,0,0,0,0,0\n1,0.5,0,0,0,0\n2,0.25,0,0,0,0\n",
     "line 4: field 'time' is 0.25, not after the step before"),
    ("step,time,body,x,y,z\n0,0.5,0,0,0,0\n", "line 2: field 'time' is 0.5; step 0 is the initial state at time 0"),
    ("step,time,body,x,y,z\n0,0,0,0,zero,0\n", "line 2: field 'y' is 'zero', not a number"),
])
def test_a_run_that_does_not_fit_names_the_line_and_the_field(tmp_path, text, message):
    run = tmp_path / "bad.csv"
    run.write_text(text)
    done = CliRunner().invoke(app, ["import", str(run), "--scene", "bullet-wall", "-o", str(tmp_path / "bad.mcap")])
    assert done.exit_code == 2 and message in done.output and "Traceback" not in done.output, done.output
    assert not (tmp_path / "bad.mcap").exists()


def test_jsonl_errors_name_the_line_too(tmp_path):
    run = tmp_path / "bad.jsonl"
    run.write_text('{"step": 0, "time": 0, "positions": [[0, 0, 0]]}\n{"step": 1, "time": 0.1, "positions": []}\n')
    done = CliRunner().invoke(app, ["import", str(run), "--scene", "bullet-wall"])
    assert done.exit_code == 2 and "bad.jsonl, line 2: field 'positions' has 0 entries; the scene has 1 body" \
        in done.output
