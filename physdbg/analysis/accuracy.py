"""Accuracy against cost: every method on reference problems with known answers.

Each problem is a small scene with a closed-form answer (the seed's physics solved by
hand). A *method* is an integrator × detection × ordering; each runs at several dt, and
each run gives its **error** against the answer (the problem's unit) and its **cost**
(wall milliseconds per simulated second, measured around the step loop, kernels already
compiled). ``physdbg bench accuracy`` writes the table, a CSV and the chart
(:mod:`.charts`).

Ordering only changes what happens when contacts share a step, so it is varied only on
the problems with more than two spheres (model no more than the question needs).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass

import numpy as np

from ..engine.motion import INTEGRATOR_NAMES
from ..engine.state import ORDERING_NAMES
from ..engine.toi import DETECTION_NAMES
from .report import markdown_table

G = 9.81
DTS = (1 / 30, 1 / 60, 1 / 120, 1 / 240)
QUICK_DTS = (1 / 30, 1 / 120)
BLEW_UP = math.inf  # the error of a run whose state became NaN or infinite


@dataclass(frozen=True)
class Problem:
    """A scene with a known answer. table(): the scene's TOML table without the method;
    exact(t): (N, 3) positions at time t s; error(times, positions, kinetic) -> the
    measured error in ``unit`` over the sampled frames (times (F,), positions (F, N, 3),
    kinetic (F,))."""

    name: str
    description: str
    unit: str
    duration: float
    table: Callable[[], dict]
    error: Callable[[np.ndarray, np.ndarray, np.ndarray], float]


@dataclass
class Run:
    """One method on one problem at one dt. error: in the problem's unit (inf: blew up);
    ms_per_second: wall ms per simulated second; failure: "" or what went wrong in words;
    max_overlap: the deepest overlap left after any step (m); failure_kind: what went wrong
    without where or why (the words the report groups the failed runs by)."""

    problem: str
    integrator: str
    detection: str
    ordering: str
    dt: float
    steps: int
    error: float
    unit: str
    ms_per_second: float
    failure: str
    max_overlap: float = 0.0
    failure_kind: str = ""

    @property
    def method(self) -> str:
        return f"{self.integrator}/{self.detection}/{self.ordering}"


# ----------------------------------------------------------------------------- closed forms
def free_flight(x0, v0, t, drag: float = 1.0, gravity=(0.0, -G, 0.0)):
    """Position (3,) at t of dv/dt = g - k v, k = -ln(drag) (the seed's v·d^t): exact."""
    x0, v0, g = np.asarray(x0, float), np.asarray(v0, float), np.asarray(gravity, float)
    k = -math.log(drag)
    if k == 0.0:
        return x0 + v0 * t + 0.5 * g * t * t
    phi1 = -math.expm1(-k * t) / k
    phi2 = (t - phi1) / k
    return x0 + v0 * phi1 + g * phi2


def bounce_height(t: float, y0: float, radius: float, e: float) -> float:
    """Height of the centre of a ball dropped from rest at centre height y0 onto a floor at
    y = 0 with restitution e (no drag): the exact piecewise parabola."""
    h = y0 - radius
    t_hit = math.sqrt(2 * h / G)
    if t <= t_hit:
        return y0 - 0.5 * G * t * t
    speed = e * G * t_hit
    start = t_hit
    while True:
        flight = 2 * speed / G
        if t <= start + flight or flight < 1e-12:
            tau = t - start
            return radius + speed * tau - 0.5 * G * tau * tau
        start += flight
        speed *= e


def two_spheres(p, v, radius, mass, e, t):
    """(2, 3) positions at t of two spheres in free flight (no gravity) that collide once
    with restitution e: the seed's impulse along the line of centres at contact."""
    p, v = np.asarray(p, float), np.asarray(v, float)
    d, w = p[0] - p[1], v[0] - v[1]
    reach = radius[0] + radius[1]
    a, b, c = w @ w, 2 * d @ w, d @ d - reach * reach
    disc = b * b - 4 * a * c
    hit = (-b - math.sqrt(disc)) / (2 * a) if a > 0 and disc >= 0 else math.inf
    if not 0 <= hit <= t or b >= 0:
        return p + v * t
    at = p + v * hit
    n = (at[0] - at[1]) / reach
    closing = (v[0] - v[1]) @ n
    j = -(1 + e) * closing / (1 / mass[0] + 1 / mass[1])
    after = v + np.array([n * j / mass[0], -n * j / mass[1]])
    return at + after * (t - hit)


# ----------------------------------------------------------------------------- problems
def _particle(position, radius, velocity=(0.0, 0.0, 0.0), mass=1.0, restitution=1.0) -> dict:
    return {"position": list(position), "velocity": list(velocity), "radius": radius, "mass": mass,
            "restitution": restitution}


def _scene(name, duration, gravity, particles, planes=(), drag=1.0) -> dict:
    return {"name": name, "description": f"accuracy problem {name}", "duration": duration, "gravity": list(gravity),
            "drag": drag, "particles": list(particles), "planes": list(planes)}


def _position_error(exact: Callable[[float], np.ndarray]):
    """Largest distance (m) between a sampled centre and the exact one, over every frame."""
    def error(times, positions, kinetic):
        want = np.array([exact(t) for t in times])
        return float(np.max(np.linalg.norm(positions - want, axis=2)))
    return error


def _problems() -> dict[str, Problem]:
    drag_x0, drag_v0, drag = (0.0, 0.0, 0.0), (3.0, 4.0, 0.0), 0.5
    head_p, head_v, head_r, head_m = [(-1.0, 0, 0), (1.0, 0, 0)], [(1.0, 0, 0), (-1.0, 0, 0)], (0.5, 0.5), (1.0, 2.0)
    obl_p, obl_v, obl_r, obl_m = [(-1.0, 0.3, 0), (1.0, 0, 0)], [(1.0, 0, 0), (0.0, 0, 0)], (0.5, 0.5), (1.0, 1.0)
    cradle_start = [(-0.73, 0, 0), (1.0, 0, 0), (2.0, 0, 0), (3.0, 0, 0), (4.0, 0, 0)]

    def cradle_exact(t):
        x = np.array(cradle_start)
        if t <= 0.73:
            x[0, 0] += t
        else:  # the blow passes down the touching row at once; the last ball leaves at 1 m/s
            x[0, 0] = 0.0
            x[4, 0] += t - 0.73
        return x

    def wall_exact(t):  # r = 0.1 at 100 m/s meets the wall's face at x = 1 - r at t = 0.009 s
        return np.array([[0.9 - 100.0 * (t - 0.009) if t > 0.009 else 100.0 * t, 0.0, 0.0]])

    def energy_error(times, positions, kinetic):
        return float(np.max(np.abs(kinetic - kinetic[0])) / kinetic[0])

    floor = {"name": "floor", "normal": [0.0, 1.0, 0.0], "offset": 0.0}
    problems = [
        Problem("ballistic-drag", "a ball thrown at (3, 4) m/s under gravity with drag d = 0.5, 1 s", "m", 1.0,
                lambda: _scene("ballistic-drag", 1.0, (0, -G, 0), [_particle(drag_x0, 0.1, drag_v0)], drag=drag),
                _position_error(lambda t: free_flight(drag_x0, drag_v0, t, drag)[None])),
        Problem("bounce", "a ball (e = 0.8) dropped 1 m onto a floor: four bounces in 2 s", "m", 2.0,
                lambda: _scene("bounce", 2.0, (0, -G, 0), [_particle((0, 1.1, 0), 0.1, restitution=0.8)], [floor]),
                _position_error(lambda t: np.array([[0.0, bounce_height(t, 1.1, 0.1, 0.8), 0.0]]))),
        Problem("head-on", "two spheres (1 and 2 kg, e = 1) meet head on at 2 m/s, 2 s", "m", 2.0,
                lambda: _scene("head-on", 2.0, (0, 0, 0), [_particle(p, r, v, m) for p, v, r, m
                                                          in zip(head_p, head_v, head_r, head_m)]),
                _position_error(lambda t: two_spheres(head_p, head_v, head_r, head_m, 1.0, t))),
        Problem("oblique", "a sphere strikes a resting one 0.3 m off centre (e = 0.9), 2 s", "m", 2.0,
                lambda: _scene("oblique", 2.0, (0, 0, 0), [
                    _particle(p, r, v, m, 0.9) for p, v, r, m in zip(obl_p, obl_v, obl_r, obl_m)]),
                _position_error(lambda t: two_spheres(obl_p, obl_v, obl_r, obl_m, 0.9, t))),
        Problem("cradle", "Newton's cradle of 5 touching balls: the last one leaves at 1 m/s, 3 s", "m", 3.0,
                lambda: _scene("cradle", 3.0, (0, 0, 0), [
                    _particle(p, 0.5, (1.0, 0, 0) if i == 0 else (0, 0, 0)) for i, p in enumerate(cradle_start)]),
                _position_error(cradle_exact)),
        Problem("thin-wall", "a 0.1 m sphere at 100 m/s against a wall of no thickness: it must bounce, 0.2 s", "m",
                0.2, lambda: _scene("thin-wall", 0.2, (0, 0, 0), [_particle((0, 0, 0), 0.1, (100.0, 0, 0), 0.01)], [
                    {"name": "thin wall", "normal": [1.0, 0.0, 0.0], "offset": 1.0, "two_sided": True}]),
                _position_error(wall_exact)),
        Problem("gas-energy", "64 spheres, e = 1, no gravity, in a box: kinetic energy must stay, 1 s",
                "relative", 1.0, _gas_table, energy_error),
        Problem("resting", "a sphere resting on a floor under gravity must stay put, 2 s", "m", 2.0,
                lambda: _scene("resting", 2.0, (0, -G, 0), [_particle((0, 0.5, 0), 0.5, restitution=0.5)], [floor]),
                _position_error(lambda t: np.array([[0.0, 0.5, 0.0]]))),
    ]
    return {p.name: p for p in problems}


def _gas_table() -> dict:
    from ..scenes import builtin_text
    import tomllib

    table = tomllib.loads(builtin_text("gas"))
    table.update(name="gas-energy", duration=1.0)
    for key in ("dt", "integrator", "detection", "ordering"):
        table.pop(key, None)
    return table


PROBLEMS = _problems()


def methods(problem: Problem) -> Iterator[tuple[str, str, str]]:
    """(integrator, detection, ordering) of every method tried on a problem."""
    many = len(problem.table().get("particles", [])) > 2 or "generate" in problem.table()
    for integrator in INTEGRATOR_NAMES:
        for detection in DETECTION_NAMES:
            for ordering in (ORDERING_NAMES if many else ("time",)):
                yield integrator, detection, ordering


# ----------------------------------------------------------------------------- running
def run_one(problem: Problem, integrator: str, detection: str, ordering: str, dt: float) -> Run:
    """Run one method on a problem at dt: its error and cost."""
    from ..engine import energies
    from ..advisor import decide
    from ..scene import scene_from_dict

    table = problem.table()
    table.update(integrator=integrator, detection=detection, ordering=ordering, dt=dt)
    table.pop("duration", None)
    steps = max(1, round(problem.duration / dt))
    table["steps"] = steps
    scene = decide(scene_from_dict(table, f"accuracy problem {problem.name}"))
    world = scene.build_world()
    n = scene.state.count
    times, positions, kinetic = np.empty(steps + 1), np.empty((steps + 1, n, 3)), np.empty(steps + 1)
    times[0], positions[0] = 0.0, scene.state.positions
    kinetic[0] = energies(scene.state, np.asarray(scene.settings.gravity))[0]
    failure = kind = ""
    elapsed, overlap = 0.0, 0.0
    for k in range(1, steps + 1):
        started = time.perf_counter()
        try:
            stats = world.step(dt)
        except Exception as err:  # a non-finite state: this method blew up here
            elapsed += time.perf_counter() - started
            kind = "blew up"
            failure = f"{kind} at step {k} ({type(err).__name__})"
            break
        elapsed += time.perf_counter() - started
        overlap = max(overlap, stats.max_overlap)
        times[k], positions[k], kinetic[k] = world.time, world.state.positions, stats.kinetic
        if not np.all(np.isfinite(positions[k])):
            kind = "blew up"
            failure = f"{kind} at step {k}"
            break
    done = k if not failure else k - 1
    error = BLEW_UP if failure else problem.error(times[:done + 1], positions[:done + 1], kinetic[:done + 1])
    if not failure and problem.name == "thin-wall" and positions[done, 0, 0] > 1.0:
        failure = kind = "tunnelled through the wall"
    elif not failure and overlap > scene.settings.contact_tolerance:
        failure = kind = "left spheres overlapping"
    return Run(problem.name, integrator, detection, ordering, dt, steps, error, problem.unit,
               1e3 * elapsed / (steps * dt), failure, overlap, kind)


def run_named(problem: str, integrator: str, detection: str, ordering: str, dt: float) -> Run:
    """run_one by the problem's name (what a sweep's worker process is sent)."""
    return run_one(PROBLEMS[problem], integrator, detection, ordering, dt)


def run_all(problems: list[str] | None = None, quick: bool = False,
            on_run: Callable[[Run, int, int], None] | None = None, workers: int | None = None,
            dask: str | None = None, warm: Callable[[], None] | None = None) -> list[Run]:
    """Every method on every problem (or the named ones) at every dt (QUICK_DTS if quick),
    in this process (workers=1), on local cores or on Dask (analysis.sweep; the kernels are
    loaded first, so cost is the stepping, not the compiler). on_run(run, done, total)."""
    from .sweep import run_jobs

    dts = QUICK_DTS if quick else DTS
    jobs = [(name, *m, dt) for name in (problems or PROBLEMS) for m in methods(PROBLEMS[name]) for dt in dts]
    return run_jobs(run_named, jobs, workers=workers, dask=dask, on_done=on_run, **({"warm": warm} if warm else {}))


def pareto(runs: list[Run]) -> list[Run]:
    """The runs that did not fail and that no other such run beats on both cost and error
    (lower is better), by cost: the choices worth making."""
    front, best = [], math.inf
    for run in sorted((r for r in runs if not r.failure), key=lambda r: (r.ms_per_second, r.error)):
        if run.error < best:
            front.append(run)
            best = run.error
    return front


# ----------------------------------------------------------------------------- output
def summary_lines(runs: list[Run]) -> list[str]:
    """`bench accuracy`'s summary, a line per problem: its Pareto front, its most accurate
    method, and how many runs broke."""
    lines = []
    for name in PROBLEMS:
        mine = [r for r in runs if r.problem == name]
        if not mine:
            continue
        best = pareto(mine)
        failed = sum(1 for r in mine if r.failure)
        lines.append(f"{name:15} {len(best)} on the Pareto front; most accurate {best[-1].method} at "
                     f"dt 1/{round(1 / best[-1].dt)} ({best[-1].error:.1e} {best[-1].unit})"
                     + (f"; {failed} of {len(mine)} runs broke (tunnelled, overlapped or blew up: the methods "
                        f"kept to show where they fail; each named in the table)" if failed else ""))
    return lines


CSV_FIELDS = ("problem", "integrator", "detection", "ordering", "dt", "steps", "error", "unit", "ms_per_second",
              "failure", "max_overlap")


def to_csv(runs: list[Run]) -> str:
    import csv
    import io

    out = io.StringIO()
    # failure_kind is not a column: the failure says it, with where and why
    writer = csv.DictWriter(out, fieldnames=CSV_FIELDS, lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    for run in runs:
        row = asdict(run)
        row["dt"] = repr(run.dt)
        row["error"] = repr(run.error)
        row["ms_per_second"] = f"{run.ms_per_second:.4g}"
        row["max_overlap"] = repr(run.max_overlap)
        writer.writerow(row)
    return out.getvalue()


def to_markdown(runs: list[Run], command: str) -> str:
    """Per problem: its Pareto front (the methods worth choosing) and what failed."""
    lines = [f"Made by `{command}`. Error against the closed-form answer; cost in wall ms per",
             "simulated second (this machine; compare within the table). Pareto front: the runs that",
             "did not fail and that no other such run beats on both cost and accuracy.", ""]
    for name, problem in PROBLEMS.items():
        mine = [r for r in runs if r.problem == name]
        if not mine:
            continue
        lines += [f"### {name}", "", problem.description + f" (error in {problem.unit}).", ""]
        lines += markdown_table(["method (integrator/detection/ordering)", "dt", "error", "ms per simulated s"],
                                [[run.method, f"1/{round(1 / run.dt)}", _fmt(run.error), f"{run.ms_per_second:.3g}"]
                                 for run in pareto(mine)])
        failed: dict[str, list[str]] = {}  # what went wrong: the method of each run it went wrong in
        for run in mine:
            if run.failure:
                failed.setdefault(run.failure_kind, []).append(run.method)
        for what, methods in failed.items():
            lines.append("")
            lines.append(f"{what}: {len(methods)} runs ({', '.join(sorted(set(methods)))}).")
        lines.append("")
    return "\n".join(lines)


def _fmt(error: float) -> str:
    return "blew up" if math.isinf(error) else f"{error:.2e}"
