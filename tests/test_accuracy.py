"""physdbg bench accuracy: the closed forms, what each method gets right and wrong on them,
and the command's files."""

from __future__ import annotations

import builtins
import csv
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg.analysis import accuracy as acc
from physdbg import api
from physdbg.cli import app
from physdbg.errors import PhysdbgError


# ----------------------------------------------------------------------------- closed forms
def test_free_flight_with_drag_solves_its_equation():
    """dv/dt = g - k v, integrated with many small RK4 steps, against the closed form."""
    drag, g = 0.5, np.array([0.0, -9.81, 0.0])
    k = -math.log(drag)
    x, v = np.zeros(3), np.array([3.0, 4.0, 0.0])
    h = 1e-4
    for _ in range(10_000):
        def f(state):
            return np.concatenate([state[3:], g - k * state[3:]])
        s = np.concatenate([x, v])
        k1 = f(s)
        k2 = f(s + h / 2 * k1)
        k3 = f(s + h / 2 * k2)
        k4 = f(s + h * k3)
        s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        x, v = s[:3], s[3:]
    assert np.allclose(acc.free_flight((0, 0, 0), (3, 4, 0), 1.0, drag), x, atol=1e-12)


def test_the_bounce_loses_height_by_e_squared_and_is_continuous():
    t1 = math.sqrt(2 * 1.0 / 9.81)
    assert acc.bounce_height(t1, 1.1, 0.1, 0.8) == pytest.approx(0.1)
    apex = t1 + 0.8 * 9.81 * t1 / 9.81
    assert acc.bounce_height(apex, 1.1, 0.1, 0.8) == pytest.approx(0.1 + 0.64 * 1.0)
    eps = 1e-9
    assert acc.bounce_height(t1 - eps, 1.1, 0.1, 0.8) == pytest.approx(acc.bounce_height(t1 + eps, 1.1, 0.1, 0.8),
                                                                        abs=1e-7)


def test_two_spheres_keep_momentum_and_with_e_1_energy():
    p, v, r, m = [(-1.0, 0.3, 0), (1.0, 0, 0)], [(1.0, 0, 0), (0, 0, 0)], (0.5, 0.5), np.array([1.0, 3.0])
    t, dt = 2.0, 1e-6
    before = np.array(v)
    x1, x2 = acc.two_spheres(p, v, r, m, 1.0, t), acc.two_spheres(p, v, r, m, 1.0, t + dt)
    after = (x2 - x1) / dt
    assert np.allclose(m @ before, m @ after, atol=1e-6)
    assert 0.5 * m @ np.sum(before**2, axis=1) == pytest.approx(0.5 * m @ np.sum(after**2, axis=1), rel=1e-6)
    assert not np.allclose(after, before)  # they did collide


# ----------------------------------------------------------------------------- methods
@pytest.mark.parametrize("name", list(acc.PROBLEMS))
def test_the_exact_method_meets_every_answer(name):
    run = acc.run_one(acc.PROBLEMS[name], "exact", "swept", "time", 1 / 60)
    assert not run.failure and run.error < 1e-12, run


def test_euler_is_first_order_in_flight():
    problem = acc.PROBLEMS["ballistic-drag"]
    errors = [acc.run_one(problem, "euler", "swept", "time", dt).error for dt in (1 / 60, 1 / 120, 1 / 240)]
    ratios = [b / a for a, b in zip(errors, errors[1:])]
    assert all(0.45 < r < 0.55 for r in ratios), errors


def test_discrete_detection_tunnels_the_thin_wall_and_swept_does_not():
    wall = acc.PROBLEMS["thin-wall"]
    discrete = acc.run_one(wall, "exact", "discrete", "time", 1 / 30)
    assert discrete.failure == "tunnelled through the wall" and discrete.error > 10
    swept = acc.run_one(wall, "euler", "swept", "time", 1 / 30)
    assert not swept.failure and swept.error < 1e-12


def test_discrete_detection_leaves_overlaps_and_index_ordering_breaks_the_cradle():
    head_on = acc.run_one(acc.PROBLEMS["head-on"], "exact", "discrete", "time", 1 / 30)
    assert head_on.failure == "left spheres overlapping" and head_on.max_overlap > 1e-3
    index = acc.run_one(acc.PROBLEMS["cradle"], "exact", "swept", "index", 1 / 60)
    # the blow is not passed down the row within the step: spheres overlap, the last leaves late
    assert index.error > 0.01 and index.failure == "left spheres overlapping"


def test_the_pareto_front_skips_failed_runs_and_is_monotone():
    runs = [acc.Run("p", "euler", "swept", "time", 0.1, 1, e, "m", c, f) for e, c, f in
            [(1.0, 1.0, ""), (0.5, 2.0, ""), (0.01, 0.5, "left spheres overlapping"), (0.7, 3.0, ""), (0.1, 4.0, "")]]
    front = acc.pareto(runs)
    assert [(r.error, r.ms_per_second) for r in front] == [(1.0, 1.0), (0.5, 2.0), (0.1, 4.0)]


# ----------------------------------------------------------------------------- the command
@pytest.mark.slow
def test_bench_accuracy_writes_the_table_csv_and_chart_and_never_overwrites(tmp_path):
    runner = CliRunner()
    out = tmp_path / "acc"
    args = ["bench", "accuracy", "--quick", "--problem", "bounce", "--problem", "thin-wall", "-o", str(out),
            "--rrd", str(tmp_path / "acc.rrd")]
    done = runner.invoke(app, args)
    assert done.exit_code == 0, done.output
    assert "thin-wall" in done.output and "runs broke (tunnelled, overlapped or blew up" in done.output
    rows = list(csv.DictReader((out / "accuracy.csv").open()))
    assert len(rows) == 2 * 12 * len(acc.QUICK_DTS)  # 4 integrators x 3 detections, time ordering only
    assert {r["problem"] for r in rows} == {"bounce", "thin-wall"}
    tunnelled = [r for r in rows if r["failure"] == "tunnelled through the wall"]
    assert tunnelled and all(r["detection"] != "swept" for r in tunnelled)
    table = (out / "accuracy.md").read_text()
    assert "### bounce" in table and "physdbg bench accuracy --quick" in table
    bounce = table.split("### bounce")[1].split("###")[0]
    front = [line for line in bounce.splitlines() if line.startswith("| ") and not line.startswith("| method")]
    # which of the exact methods is cheapest depends on the machine's timing; that they are swept does not
    assert front and all("/swept/" in line for line in front)
    assert (out / "accuracy.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "<svg" in (out / "accuracy.svg").read_text()[:2000]
    import rerun.chunk as rerun_chunk

    entities = {chunk.entity_path for chunk in rerun_chunk.RrdReader(tmp_path / "acc.rrd").stream()}
    assert {"/accuracy/bounce/runs", "/accuracy/bounce/pareto", "/accuracy/thin-wall/runs"} <= entities
    again = runner.invoke(app, args[:-2])
    assert again.exit_code == 2 and "already exists; pass --force" in again.output
    assert "Traceback" not in again.output


def test_without_matplotlib_the_csv_and_table_are_written_and_a_note_says_how_to_chart(tmp_path, monkeypatch):
    """README command 1 installs no matplotlib: `bench accuracy --quick` from the README must
    still work there (it exited 2), writing the CSV and the table and saying how to chart."""
    import importlib.util

    real_import, real_find_spec = builtins.__import__, importlib.util.find_spec

    def no_matplotlib(name, *args, **kwargs):
        if name == "matplotlib" or name.startswith("matplotlib."):
            raise ImportError("No module named 'matplotlib'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "matplotlib" else real_find_spec(name, *a))
    runner = CliRunner()
    done = runner.invoke(app, ["bench", "accuracy", "--quick", "--problem", "resting", "-j", "2",
                               "-o", str(tmp_path / "a")])
    assert done.exit_code == 0, done.output
    assert "note        no chart drawn: matplotlib is not installed (pip install 'physdbg[charts]'" in done.output
    assert (tmp_path / "a" / "accuracy.csv").exists() and not (tmp_path / "a" / "accuracy.png").exists()
    done = runner.invoke(app, ["bench", "accuracy", "--quick", "--problem", "resting", "--no-chart", "-j", "2",
                               "-o", str(tmp_path / "b")])
    assert done.exit_code == 0 and "note" not in done.output, done.output
    with pytest.raises(PhysdbgError, match="pip install 'physdbg\\[charts\\]'"):  # a chart asked for outright
        api.bench_accuracy(tmp_path / "c", quick=True, chart=True, problems=["resting"])


def test_an_unknown_problem_is_named_with_the_ones_there_are(tmp_path):
    done = CliRunner().invoke(app, ["bench", "accuracy", "--problem", "bouncy", "-o", str(tmp_path)])
    assert done.exit_code == 2 and "no accuracy problem 'bouncy'" in done.output and "bounce" in done.output
