"""check-run of a folder of submissions: one table, the causes counted, a bad file a row."""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from physdbg import api
from physdbg.analysis import classroom
from physdbg.cli import app
from tests.student_engine import simulate_swept, write_csv

ROOT = Path(__file__).resolve().parents[1]
MISTAKES = ROOT / "docs" / "examples" / "mistakes"
GLANCE = str(MISTAKES / "glance.toml")
ON_GLANCE = ("restitution-sign", "impulse-doubled", "wrong-normal", "one-missing", "impulse-loop")


def a_class(folder: Path, size: int) -> dict[str, str]:
    """``size`` runs of glance: the right run and the glance mistakes' example runs, copied in
    turn, and one file that is not a run; returns run name -> what it is."""
    from physdbg.api import load_scene

    folder.mkdir()
    scene = load_scene(GLANCE)
    write_csv(folder / "right.csv", *simulate_swept(scene, scene.steps or round(scene.duration / scene.dt), scene.dt))
    kinds = ["right", *ON_GLANCE]
    out = {}
    for k in range(size - 1):
        kind = kinds[k % len(kinds)]
        name = f"student-{k:03d}.csv"
        shutil.copy(folder / "right.csv" if kind == "right" else MISTAKES / f"{kind}.csv", folder / name)
        out[name] = kind
    (folder / "right.csv").unlink()
    (folder / "student-hostile.jsonl").write_text('{"step": 0, "time": 0, "positions": [[1e999, 0, 0]]\n\x00\x01')
    out["student-hostile.jsonl"] = "error"
    return out


@pytest.mark.slow
def test_a_class_of_200_runs_is_one_table_with_its_causes_counted_and_a_bad_file_as_a_row(tmp_path):
    expected = a_class(tmp_path / "class", 200)
    report = api.check_class(classroom.runs_in([tmp_path / "class"]), GLANCE)
    rows = list(csv.DictReader(io.StringIO(classroom.class_csv(report))))
    assert len(rows) == 200 and report.exit_code == 1
    for row in rows:
        kind = expected[Path(row["run"]).name]
        if kind == "right":
            assert (row["verdict"], row["cause"]) == ("SAME", ""), row
        elif kind == "error":
            assert row["verdict"] == "ERROR" and row["cause"] == "error" and "student-hostile.jsonl" in row["said"]
        else:
            assert (row["verdict"], row["step"], row["cause"]) == ("DEPARTS", "16", kind), row
    assert report.counts == {"same": 34, **{kind: 33 for kind in ON_GLANCE}, "error": 1}
    assert list(report.counts)[0] == "same"  # the most common first
    assert classroom.class_text(report).startswith("class      200 runs of glance: 34 same, 165 depart, 1 unreadable")
    markdown = classroom.class_markdown(report)
    assert "| one-missing | 33 |" in markdown and "| student-hostile.jsonl | ERROR |" in markdown


@pytest.mark.parametrize("fmt", ["text", "markdown", "csv", "json"])
def test_check_run_of_a_folder_prints_the_table_in_each_format(tmp_path, fmt):
    a_class(tmp_path / "class", 7)
    result = CliRunner().invoke(app, ["check-run", str(tmp_path / "class"), "--scene", GLANCE, "--format", fmt,
                                      "-j", "1"])
    assert result.exit_code == 1, result.output
    first = {"text": "class      7 runs of glance: 1 same, 5 depart, 1 unreadable",
             "markdown": "### physdbg check-run: 7 runs of glance", "csv": "run,verdict,step,body,cause,said",
             "json": "{"}[fmt]
    assert result.output.startswith(first), result.output
    if fmt == "json":
        assert json.loads(result.output)["counts"]["one-missing"] == 1


def test_a_folder_refuses_keep_and_passes_no_verify_to_every_run(tmp_path, monkeypatch):
    """--keep keeps one run's two recordings: with a folder it is refused, in one line, not
    ignored; --no-verify reaches every run's check-run."""
    a_class(tmp_path / "class", 3)
    kept = CliRunner().invoke(app, ["check-run", str(tmp_path / "class"), "--scene", GLANCE, "--keep",
                                    str(tmp_path / "kept")])
    assert kept.exit_code == 2 and "--keep keeps the two recordings of one run" in kept.output, kept.output
    assert kept.output.count("\n") == 1 and not (tmp_path / "kept").exists()
    seen = []
    real = api.check_run

    def check_run(*args, **kwargs):
        seen.append(kwargs.get("verify", True))
        return real(*args, **kwargs)

    monkeypatch.setattr(api, "check_run", check_run)
    done = CliRunner().invoke(app, ["check-run", str(tmp_path / "class"), "--scene", GLANCE, "-j", "1",
                                    "--no-verify"])
    assert done.exit_code == 1 and done.output.startswith("class      3 runs of glance"), done.output
    assert seen == [False, False, False]


@pytest.mark.slow
def test_the_same_table_from_a_dask_cluster(tmp_path):
    distributed = pytest.importorskip("distributed", reason="needs pip install 'physdbg[dask]'")
    a_class(tmp_path / "class", 24)
    runs = classroom.runs_in([tmp_path / "class"])
    here = api.check_class(runs, GLANCE, workers=1)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=50) as cluster:
        there = api.check_class(runs, GLANCE, dask=cluster.scheduler_address)
    assert classroom.class_csv(there) == classroom.class_csv(here)
    assert there.counts == here.counts


def test_a_folder_with_no_run_and_a_wrong_scene_are_clear_errors(tmp_path):
    (tmp_path / "empty").mkdir()
    none = CliRunner().invoke(app, ["check-run", str(tmp_path / "empty"), "--scene", GLANCE])
    assert none.exit_code == 2 and "no run (a .csv, .jsonl, .mcap file)" in none.output
    (tmp_path / "one").mkdir()
    shutil.copy(MISTAKES / "one-missing.csv", tmp_path / "one" / "a.csv")
    wrong = CliRunner().invoke(app, ["check-run", str(tmp_path / "one"), "--scene", "nope"])
    assert wrong.exit_code == 2 and "Traceback" not in wrong.output
