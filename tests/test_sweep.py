"""Sweeps run here, on local cores, or on a Dask cluster, with the same results."""

from __future__ import annotations

import csv

import pytest
from typer.testing import CliRunner

from physdbg.analysis import accuracy, stability
from physdbg.analysis.sweep import run_jobs
from physdbg.cli import app


def _outcomes(cells):
    return [(c.map, c.method, c.x, c.y, c.outcome, c.detail) for c in cells]


@pytest.mark.slow
def test_local_cores_give_the_serial_results_in_order():
    serial = stability.maps(quick=True, workers=1)
    pooled = stability.maps(quick=True, workers=2)
    assert _outcomes(serial) == _outcomes(pooled)
    jobs = [("bounce", "euler", "swept", "time", dt) for dt in accuracy.QUICK_DTS]
    errors = [r.error for r in run_jobs(accuracy.run_named, jobs, workers=2)]
    assert errors == [accuracy.run_named(*job).error for job in jobs]


@pytest.mark.slow
def test_a_dask_cluster_runs_the_same_sweep(tmp_path):
    distributed = pytest.importorskip("distributed", reason="needs pip install 'physdbg[dask]'")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=50) as cluster:
        runner = CliRunner()
        done = runner.invoke(app, ["bench", "stability", "--quick", "--no-chart", "--dask", cluster.scheduler_address,
                                   "-o", str(tmp_path / "dask")])
        assert done.exit_code == 0, done.output
        done = runner.invoke(app, ["bench", "accuracy", "--quick", "--problem", "cradle", "--no-chart", "--dask",
                                   cluster.scheduler_address, "-o", str(tmp_path / "acc")])
        assert done.exit_code == 0, done.output
    rows = list(csv.DictReader((tmp_path / "dask" / "stability.csv").open()))
    serial = stability.maps(quick=True, workers=1)
    assert [(r["map"], r["integrator"], r["detection"], r["outcome"]) for r in rows] == [
        (c.map, c.integrator, c.detection, c.outcome) for c in serial]
    errors = [float(r["error"]) for r in csv.DictReader((tmp_path / "acc" / "accuracy.csv").open())]
    assert errors == [r.error for r in accuracy.run_all(["cradle"], quick=True, workers=1)]


@pytest.mark.slow
def test_an_unreachable_scheduler_is_a_clear_error(tmp_path):
    pytest.importorskip("distributed", reason="needs pip install 'physdbg[dask]'")
    done = CliRunner().invoke(app, ["bench", "stability", "--quick", "--no-chart", "--dask", "tcp://127.0.0.1:9",
                                    "-o", str(tmp_path)])
    assert done.exit_code == 2 and "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in done.output
    assert "Traceback" not in done.output
    done = CliRunner().invoke(app, ["bench", "stability", "--quick", "--no-chart", "--dask", "notanaddress",
                                    "-o", str(tmp_path)])
    assert done.exit_code == 2 and "cannot reach the Dask scheduler at notanaddress" in done.output
