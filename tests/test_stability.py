"""physdbg bench stability: the boundaries the geometry predicts, and the command."""

from __future__ import annotations

import csv

import pytest
from typer.testing import CliRunner

from physdbg.analysis import stability as st
from physdbg.cli import app


@pytest.mark.parametrize("integrator, dt", [("exact", 0.01), ("euler", 0.05)])
def test_discrete_detection_tunnels_exactly_where_a_step_carries_the_centre_past_the_mid_plane(integrator, dt):
    boundary = st.REACH / (1 - st.PHASES[0])  # the earliest-touching phase decides
    below = st.impact_cell(integrator, "discrete", dt, 0.99 * boundary / dt)
    above = st.impact_cell(integrator, "discrete", dt, 1.01 * boundary / dt)
    assert below.outcome == "overlap left"  # found, but only after the overlap
    assert above.outcome == "tunnelled" and "× REACH" in above.detail


def test_sampled_detection_tunnels_at_k_times_the_speed():
    boundary = 2 * 4 * st.REACH  # k = 4 samples, each starting half a sample before the wall
    assert st.impact_cell("exact", "sampled", 0.01, 0.98 * boundary / 0.01).outcome != "tunnelled"
    assert st.impact_cell("exact", "sampled", 0.01, 1.02 * boundary / 0.01).outcome == "tunnelled"


@pytest.mark.parametrize("dt, speed", [(0.1, 300.0), (0.001, 0.1), (0.1, 0.1), (0.001, 300.0)])
def test_swept_detection_never_fails_at_the_corners_of_the_map(dt, speed):
    for integrator in ("euler", "exact"):
        assert st.impact_cell(integrator, "swept", dt, speed).outcome == "pass"


@pytest.mark.parametrize("restitution, height", [(0.0, 1), (1.0, 1), (0.0, 8), (1.0, 8)])
def test_swept_stacks_hold_and_discrete_ones_overlap(restitution, height):
    assert st.stack_cell("exact", "swept", restitution, height).outcome == "pass"
    discrete = st.stack_cell("exact", "discrete", restitution, height)
    assert discrete.outcome == "overlap left" and discrete.detail.endswith(" m")


@pytest.mark.slow
def test_bench_stability_writes_the_maps_and_says_where_each_method_tunnels(tmp_path):
    out = tmp_path / "stab"
    done = CliRunner().invoke(app, ["bench", "stability", "--quick", "-o", str(out)])
    assert done.exit_code == 0, done.output
    assert "exact/swept            impact 30/30 pass, never tunnels" in done.output
    assert "exact/discrete" in done.output and "tunnels from v·dt" in done.output
    rows = list(csv.DictReader((out / "stability.csv").open()))
    assert {r["map"] for r in rows} == {"impact", "stack"}
    assert all(r["outcome"] in st.OUTCOMES for r in rows)
    assert not any(r["outcome"] == "tunnelled" for r in rows if r["detection"] == "swept")
    for name in ("stability-impact.png", "stability-stack.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG"
    again = CliRunner().invoke(app, ["bench", "stability", "--quick", "-o", str(out)])
    assert again.exit_code == 2 and "already exists; pass --force" in again.output
