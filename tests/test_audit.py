"""physdbg explain and the live audit: findings where there are problems, none where there are not."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from physdbg import api
from physdbg.analysis import explain
from physdbg.cli import app

ROOT = Path(__file__).resolve().parent.parent


def test_explain_finds_the_discrete_tunnelling_and_nothing_in_the_swept_run(tmp_path):
    discrete = tmp_path / "d.mcap"
    api.record("bullet-wall", ["detection=discrete"], mcap_path=str(discrete), rrd=False)
    report = explain(discrete)
    assert report.counts == {"tunnelling": 1}
    found = report.findings[0]
    assert found.step == 1 and found.particles == [0] and "went through wall 'thin wall'" in found.message
    assert found.position == pytest.approx([1.0, 0.0, 0.0])  # where the path met the wall
    assert "detection = swept" in found.advice
    swept = tmp_path / "s.mcap"
    api.record("bullet-wall", [], mcap_path=str(swept), rrd=False)
    assert explain(swept).clean


@pytest.mark.parametrize("scene", ["billiards", "bounce", "bullet-wall", "cradle", "gas", "rain", "rest"])
def test_no_false_alarms_on_the_builtin_scenes(scene):
    report = explain(ROOT / "recordings" / "ci" / f"{scene}.mcap")
    assert report.clean, report.lines()
    assert report.checked == report.steps > 0


def test_index_ordering_is_found_out_of_the_recording_alone(tmp_path):
    out = tmp_path / "c.mcap"
    api.record("cradle", ["ordering=index"], mcap_path=str(out), rrd=False)
    report = explain(out)
    assert report.counts.get("tunnelling") and report.findings[0].step == 44
    assert "ordering = time" in report.findings[0].advice


def test_the_run_summary_says_it_and_the_viewer_marks_it(tmp_path):
    result = CliRunner().invoke(app, ["run", "bullet-wall", "--set", "detection=discrete"])
    assert "audit       1 tunnelling" in result.output
    assert "step 1: sphere 0 went through wall 'thin wall'" in result.output
    clean = CliRunner().invoke(app, ["run", "bullet-wall"])
    assert "audit       clean" in clean.output
    rrd = tmp_path / "d.rrd"
    api.record("bullet-wall", ["detection=discrete"], mcap_path=str(tmp_path / "d.mcap"), rrd_path=str(rrd))
    from rerun.chunk import RrdReader

    paths = {str(chunk.entity_path) for chunk in RrdReader(rrd).stream()}
    assert "/world/findings" in paths


def test_explain_cli_exit_codes_and_formats(tmp_path):
    out = tmp_path / "d.mcap"
    api.record("bullet-wall", ["detection=discrete"], mcap_path=str(out), rrd=False)
    runner = CliRunner()
    found = runner.invoke(app, ["explain", str(out)])
    assert found.exit_code == 1 and "[tunnelling]" in found.output and "what to do:" in found.output
    assert '"tunnelling": 1' in runner.invoke(app, ["explain", str(out), "--json"]).output
    clean = runner.invoke(app, ["explain", str(ROOT / "recordings" / "ci" / "cradle.mcap")])
    assert clean.exit_code == 0 and "CLEAN" in clean.output
    bad = tmp_path / "bad.mcap"
    bad.write_text("not a recording")
    failed = runner.invoke(app, ["explain", str(bad)])
    assert failed.exit_code == 2 and "not an MCAP file" in failed.output
