"""Every fact check-run states about a run is true of that run's frames.

A matrix: the project's student engines (tests/student_engine.py in Python, tests/js/
student_engine.js under Node) on every built-in sphere scene, right and with each planted
mistake, checked by check-run; for each finding, the fact it states is recomputed here from
the run's own frames, apart from check-run's code: a step's number names the frames k−1 and
k; "no change of velocity" means the velocity changed by no more than the forces and drag
give; "momentum is not kept" means the spheres it names changed their momentum by more
than the forces and drag give, "momentum kept and no energy gained" the opposite; and a
class table of the same runs gives each the cause its single check-run gives.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from physdbg import api
from physdbg.analysis.departure import DEPARTURE_KINDS
from physdbg.api import load_scene
from physdbg.record.foreign import read_run
from physdbg.scene import scene_table
from tests.student_engine import MISTAKES, simulate, simulate_swept, write_jsonl

ROOT = Path(__file__).resolve().parents[1]
NODE = shutil.which("node")
KICK_FRACTION = 0.02  # departure.py's: a velocity change beyond this share of the speed is a kick

# every built-in sphere scene (no meshes), small enough for the student engines' O(N²) loops
SCENES = {  # (the steps that hold the scene's contacts: billiards breaks at step 22)
    "bounce": ["steps=300"],
    "billiards": ["steps=60"],
    "bullet-wall": [],
    "cradle": [],
    "rest": ["steps=60"],
    "rain": ["generate.count=10", "steps=90"],
    "gas": ["generate.count=12", "steps=40"],
}
JS_MISTAKES = ("one-missing", "impulse-doubled", "restitution-sign", "tangent-reversed", "drag-per-step")
# the JavaScript engine's doubled impulse with no guard blows billiards up within a few steps,
# and check-run of that run takes ~30 s (every departing step's ties tried in every order);
# the Python engine's (guarded) doubled impulse on billiards stays in the matrix
JS_LEFT_OUT = {("billiards", "impulse-doubled")}


def test_the_matrix_covers_every_built_in_sphere_scene():
    from physdbg.scene import read_scene
    from physdbg.scenes import builtin_names

    spheres_only = {name for name in builtin_names() if not len(read_scene(name).walls.meshes.corners)}
    assert spheres_only == set(SCENES)


def _decays(scene, dt: float) -> list[float]:
    """The drag factors a run may apply over a step: the scene's d^dt, d itself (per step),
    none."""
    d = float(scene.settings.drag)
    return [d ** dt, d, 1.0] if 0 < d < 1 else [1.0]


def _acc(scene) -> np.ndarray:
    st = scene.state
    g = np.asarray(scene.settings.gravity, dtype=float)
    return np.where((st.inverse_mass > 0)[:, None], st.gravity_scale[:, None] * g[None, :], 0.0)


def check_claims(scene, run_path: Path, report) -> None:
    """Every departure's stated fact against the run's frames (module doc)."""
    run = read_run(run_path, scene.state.count)
    t, v = run.times, run.velocities
    inv, acc = scene.state.inverse_mass, _acc(scene)
    frames = len(t)
    for d in report.departures:
        assert 1 <= d.step < frames, (d.kind, d.step)
        if "time" in d.evidence and d.kind not in ("extra-contact",):
            k = d.step
            slack = 1e-9 + 0.05 * (t[k] - t[k - 1])
            assert t[k - 1] - slack <= d.evidence["time"] <= t[k] + slack or d.kind == "bounce-time", (d.kind, d.step,
                                                                                                      d.evidence)
        k = d.step
        dt = float(t[k] - t[k - 1])
        if d.kind == "missed-contact":  # "no change of velocity in that step beyond the forces'"
            for b in (d.body, d.other):
                if b is None or inv[b] == 0:
                    continue
                speed = float(np.linalg.norm(v[k - 1, b])) + float(np.linalg.norm(acc[b])) * dt
                change = min(float(np.linalg.norm(v[k, b] - v[k - 1, b] * f - acc[b] * dt)) for f in _decays(scene, dt))
                assert change <= KICK_FRACTION * speed + 1e-9, (run_path.name, d.step, b, change, d.text)
        if d.kind in ("contact-energy", "collision-order") and "momentum_off" in d.evidence:
            bodies = np.array(d.evidence["momentum_bodies"])
            mass = 1.0 / inv[bodies]
            start = [v[k - 1, bodies] * f + acc[bodies] * dt for f in _decays(scene, dt)]
            offs = [float(np.linalg.norm((mass[:, None] * (v[k, bodies] - s)).sum(axis=0))) for s in start]
            slack = d.evidence["forces_slack"] + 1e-3 * float(np.sum(mass * np.linalg.norm(v[k, bodies], axis=1)))
            if "momentum is not kept" in d.text:
                assert min(offs) > slack * 0.999, (run_path.name, d.step, offs, d.text)
            if "momentum kept" in d.text:
                assert not d.evidence["walls"] and min(offs) <= slack * 1.001, (run_path.name, d.step, offs, d.text)
            if "energy gained" in d.text and "no energy gained" not in d.text:
                energies = [0.5 * float(mass @ (s * s).sum(axis=1)) for s in start]
                after = 0.5 * float(mass @ (v[k, bodies] ** 2).sum(axis=1))
                assert after > max(energies), (run_path.name, d.step, after, energies)
    if report.first is not None:  # the headline tells the first departure's cause, in its words
        words = DEPARTURE_KINDS[report.first.cause][0]
        assert words in report.headline or report.first.cause == "drift" and "integrator" in report.headline, (
            run_path.name, report.first.cause, report.headline)


def _python_runs(name: str, overrides: list[str], folder: Path):
    """(label, path, overrides) of the Python student engine's runs of a scene: the swept
    engine right and with each mistake (the scene's integrator set to the student's Euler),
    the right one against the scene's own integrator, and the course's discrete engine."""
    euler = [*overrides, "integrator=euler"]
    scene = load_scene(name, euler)
    steps = scene.steps
    for mistake in (None, *MISTAKES):
        with np.errstate(all="ignore"):
            times, xs, vs = simulate_swept(scene, steps, scene.dt, mistake)
        path = folder / f"{name}-py-{mistake or 'right'}.jsonl"
        write_jsonl(path, times, xs, vs)
        yield mistake or "right", path, euler
    times, xs, vs = simulate_swept(scene, steps, scene.dt)
    path = folder / f"{name}-py-exact.jsonl"
    write_jsonl(path, times, xs, vs)
    yield "right, against exact", path, overrides
    times, xs, vs = simulate(scene, steps, scene.dt)
    path = folder / f"{name}-py-discrete.jsonl"
    write_jsonl(path, times, xs, vs)
    yield "discrete", path, overrides


def _js_runs(name: str, overrides: list[str], folder: Path, tracer: Path):
    """The JavaScript student engine's runs, each carrying its scene (integrator euler)."""
    scene = load_scene(name, [*overrides, "integrator=euler"])
    scene_file = folder / f"{name}.scene.json"
    scene_file.write_text(json.dumps(scene_table(scene)))
    for mistake in (None, *JS_MISTAKES):
        if (name, mistake) in JS_LEFT_OUT:
            continue
        out = folder / f"{name}-js-{mistake or 'right'}.jsonl"
        flags = ["--mistake", mistake] if mistake else []
        done = subprocess.run([NODE, str(ROOT / "tests" / "js" / "student_engine.js"), str(scene_file), str(out),
                               *flags], capture_output=True, text=True, env={"PHYSDBG_TRACE": str(tracer)},
                              timeout=300)
        assert done.returncode == 0, done.stderr
        yield mistake or "right", out, None


@pytest.fixture(scope="module")
def tracer(tmp_path_factory) -> Path:
    return api.write_trace_js(tmp_path_factory.mktemp("tracer"))


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SCENES))
def test_every_fact_check_run_states_is_true_of_the_run(name, tmp_path, tracer):
    overrides = SCENES[name]
    runs = list(_python_runs(name, overrides, tmp_path))
    if NODE is not None:
        runs += list(_js_runs(name, overrides, tmp_path, tracer))
    causes = {}
    for label, path, given in runs:
        scene = load_scene(name, given if given is not None else [*overrides, "integrator=euler"])
        report = api.check_run(path, name if given is not None else None, given or []).report
        check_claims(scene, path, report)
        causes[path.name] = report.first.cause if report.first is not None else None
        # (the student engines' walls are one-sided: bullet-wall's two-sided thin wall is theirs to miss;
        # and they bounce a resting stack where physdbg holds it: rest departs, named resting)
        if label == "right" and name not in ("bullet-wall", "rest") and (given is None or "integrator=euler" in given):
            assert report.exit_code == 0, (path.name, report.headline)
    # the class table (each run checked again in a worker) gives each run its single check-run's cause
    for group, given in (("py", [*overrides, "integrator=euler"]), ("js", None)):
        paths = [p for _, p, g in runs if f"-{group}-" in p.name and (g == given)]
        if not paths:
            continue
        table = api.check_class(paths, name if given is not None else None, given or [], workers=1)
        for row in table.rows:
            assert row.verdict != "ERROR", row.said
            assert row.cause == causes[Path(row.run).name] or (row.verdict == "SAME" and causes[Path(row.run).name]
                                                               is None), (row.run, row.cause)


def test_the_missing_one_on_billiards_is_named_one_missing_in_a_single_check_and_the_class_table(tmp_path):
    """A break of 16 balls: the chain's speeds are not in the frames, so the mistake that
    reproduces the step (each impulse with e − 1, each contact once) is named, not its
    symptoms (collision-order, drift)."""
    scene = load_scene("billiards", ["integrator=euler", "steps=60"])
    times, xs, vs = simulate_swept(scene, scene.steps, scene.dt, "one-missing")
    path = tmp_path / "one-missing.jsonl"
    write_jsonl(path, times, xs, vs)
    report = api.check_run(path, "billiards", ["integrator=euler", "steps=60"]).report
    assert report.first.cause == "one-missing" and report.first.step == 22
    named = next(d for d in report.departures if d.kind == "one-missing")
    assert named.step == 22 and "effective restitution (-0.05 for 0–2" in named.text and named.evidence["reproduced"]
    assert "one-missing" in report.headline.split(":")[1] or "(1 + e)" in report.headline
    assert "unexplained" not in report.headline and "every step" not in report.headline
    table = api.check_class([path], "billiards", ["integrator=euler", "steps=60"], workers=1)
    assert table.rows[0].cause == "one-missing"


def test_a_late_bounce_at_a_step_boundary_is_not_called_a_missed_contact(tmp_path):
    """The right Euler engine against the exact integrator on bounce: a bounce the run made
    at the start of step 234 is judged once (with step 233's contact), never 'no change of
    velocity' in the step where its velocity went from -1.575 to +1.112 m/s."""
    scene = load_scene("bounce")
    times, xs, vs = simulate_swept(scene, scene.steps, scene.dt)
    path = tmp_path / "euler.jsonl"
    write_jsonl(path, times, xs, vs)
    report = api.check_run(path, "bounce").report
    assert report.first.cause == "drift" and "explicit Euler" in report.headline
    assert not any(d.kind == "missed-contact" for d in report.departures), [d.text for d in report.departures]
    check_claims(scene, path, report)
