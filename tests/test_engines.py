"""physdbg bench engines: physdbg's methods and the peers on the same scenes, each run
measured against physdbg's exact run (analysis/engines.py)."""

from __future__ import annotations

import csv

import pytest
from typer.testing import CliRunner

from physdbg.analysis import engines
from physdbg.cli import app


@pytest.mark.slow
def test_the_exact_run_is_the_zero_every_error_is_measured_from_and_the_thin_wall_is_tunnelled(tmp_path):
    result = CliRunner().invoke(app, ["bench", "engines", "--scene", "bounce", "--scene", "bullet-wall",
                                      "-o", str(tmp_path), "--no-progress"])
    assert result.exit_code == 0, result.output
    assert "12 runs in" in result.output and "wrote" in result.output
    rows = {(r["scene"], r["method"]): r for r in csv.DictReader((tmp_path / "engines.csv").open())}
    assert len(rows) == 12 and not any(r["failure"] for r in rows.values())
    for scene in ("bounce", "bullet-wall"):
        exact = rows[(scene, "physdbg exact")]
        assert float(exact["largest_overlap"]) == 0 and float(exact["energy_error"]) == 0
        assert float(exact["contact_time_error"]) == 0 and exact["tunnelled"] == "0"
        for row in rows.values():
            assert float(row["ms_per_step"]) > 0
    # at 100 m/s and dt = 0.1 s every method that tests where steps end goes through the wall
    for method in ("physdbg discrete", "pybullet", "mujoco PGS-10 +sleep", "mujoco Newton-100"):
        assert rows[("bullet-wall", method)]["tunnelled"] == "1", method
    # a discrete bounce is late and from inside the floor: an overlap, a contact-time error
    late = rows[("bounce", "physdbg discrete")]
    assert float(late["largest_overlap"]) > 0.01 and float(late["contact_time_error"]) > 0.005
    table = (tmp_path / "engines.md").read_text()
    assert "| bullet-wall | physdbg exact |" in table and "How each peer was set up" in table
    assert (tmp_path / "engines.png").stat().st_size > 10_000


def test_an_unknown_scene_is_one_line_and_exit_2(tmp_path):
    result = CliRunner().invoke(app, ["bench", "engines", "--scene", "pile", "-o", str(tmp_path)])
    assert result.exit_code == 2 and "no engines scene 'pile'; the scenes are: bounce" in result.output


def test_a_kick_is_read_at_the_instant_that_splits_the_step(tmp_path):
    """A ball at 1 m/s reversed at 0.25 of a 0.1 s step (no forces): the kick's instant."""
    import numpy as np

    from physdbg.api import load_scene

    scene = load_scene("bullet-wall")
    frames = [(0.0, np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]])),
              (0.1, np.array([[0.025 - 0.075, 0, 0]]), np.array([[-1.0, 0, 0]]))]
    assert abs(engines._first_kick(scene, frames) - 0.025) < 1e-12
