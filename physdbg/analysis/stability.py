"""Where each method breaks: pass or fail over a grid of conditions, the failure named.

Two maps, each for every integrator × detection (time ordering):

* **impact** — a sphere (r = 0.05 m) flies at a two-sided wall 0.02 m thick (e = 1, no
  gravity) at speed v with step dt. A discrete test finds the overlap only at the end of a
  step and pushes the sphere out on the side its centre is on, so it tunnels once a step
  can carry the centre past the wall's mid-plane: beyond REACH = thickness/2 + r = 0.06 m
  from where it first touches (and misses the wall outright beyond 2·REACH). Sampled
  detection with k samples does the same per sample, so at k times the speed; swept
  detection never. Each cell is run at PHASES starting points (how far into a step the
  sphere touches the wall) and fails if any of them fails; a step then tunnels when
  v·dt·(1 − phase) > REACH, so the map's boundary is v·dt = REACH / (1 − 1/8) for discrete
  detection and, as every sample here starts half a sample before the wall, 2k·REACH for
  sampled.
* **stack** — n spheres (r = 0.1 m) stacked on a floor under gravity, restitution e, held
  for 1 s at dt = 1/60: the resting contact of towers of every height.

Outcomes, in the order they are checked: ``blew up`` (NaN or infinite state),
``tunnelled`` (ended beyond the wall), ``budget hit`` (a work budget stopped a step),
``overlap left`` (deeper than contact_tolerance after a step), ``energy changed``
(kinetic + potential, relative, beyond ENERGY_TOLERANCE: an e = 1 impact must keep it, a
resting stack must not gain it), ``sank`` (the top of the stack moved more than 1 µm),
else ``pass``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..engine.motion import INTEGRATOR_NAMES
from ..engine.toi import DETECTION_NAMES
from .report import markdown_table

OUTCOMES = ("pass", "blew up", "tunnelled", "budget hit", "overlap left", "energy changed", "sank")
ENERGY_TOLERANCE = 1e-6
SANK_TOLERANCE = 1e-6  # m

# impact map
IMPACT_RADIUS = 0.05
WALL_THICKNESS = 0.02
REACH = WALL_THICKNESS / 2 + IMPACT_RADIUS  # how far past first touch a centre may go and still come back (m)
PHASES = (0.125, 0.375, 0.625, 0.875)
IMPACT_DTS = tuple(float(x) for x in np.geomspace(1e-3, 1e-1, 9))
IMPACT_SPEEDS = tuple(float(x) for x in np.geomspace(0.1, 300.0, 12))
QUICK_IMPACT_DTS = IMPACT_DTS[::2]
QUICK_IMPACT_SPEEDS = IMPACT_SPEEDS[::2]

# stack map
STACK_RADIUS = 0.1
STACK_DT = 1 / 60
STACK_SECONDS = 1.0
STACK_RESTITUTIONS = (0.0, 0.3, 0.6, 0.9, 1.0)
STACK_HEIGHTS = (1, 2, 4, 8, 16, 32)
QUICK_STACK_HEIGHTS = (1, 4, 16)


@dataclass
class Cell:
    """One method at one grid point. x, y: the map's two coordinates (impact: dt s and
    speed m/s; stack: restitution and height); outcome: one of OUTCOMES; detail: in words."""

    map: str
    integrator: str
    detection: str
    x: float
    y: float
    outcome: str
    detail: str

    @property
    def method(self) -> str:
        return f"{self.integrator}/{self.detection}"


def _run(table: dict, steps: int, dt: float, check: Callable) -> tuple[str, str]:
    """Run a scene table for ``steps`` steps of ``dt``; (outcome, detail)."""
    from ..engine import energies
    from ..events import EngineWarning
    from ..observe import ListObserver
    from ..advisor import decide
    from ..scene import scene_from_dict

    table = dict(table, dt=dt, steps=steps)
    scene = decide(scene_from_dict(table, "stability map"))
    warnings = ListObserver()
    world = scene.build_world(warnings)
    gravity = np.asarray(scene.settings.gravity)
    kinetic, potential, _ = energies(world.state, gravity)
    start_energy = kinetic + potential
    start = world.state.positions.copy()
    overlap = 0.0
    for k in range(1, steps + 1):
        try:
            stats = world.step(dt)
        except Exception as err:  # a non-finite state
            return "blew up", f"at step {k} ({type(err).__name__})"
        if not np.all(np.isfinite(world.state.positions)):
            return "blew up", f"at step {k}"
        overlap = max(overlap, stats.max_overlap)
    budget = [w for w in warnings.of_type(EngineWarning) if w.code.startswith("max_")]
    verdict = check(start, world.state.positions)
    if verdict:
        return verdict
    if budget:
        return "budget hit", budget[0].message
    if overlap > scene.settings.contact_tolerance:
        return "overlap left", f"{overlap:.3g} m"
    kinetic, potential, _ = energies(world.state, gravity)
    scale = max(abs(start_energy), 1e-12)
    change = (kinetic + potential - start_energy) / scale
    if abs(change) > ENERGY_TOLERANCE:
        return "energy changed", f"{change:+.3g} (relative)"
    return "pass", ""


def impact_cell(integrator: str, detection: str, dt: float, speed: float) -> Cell:
    """The impact map at (dt, speed): the worst of the PHASES starting points."""
    face = -(WALL_THICKNESS / 2 + IMPACT_RADIUS)  # where the centre meets the wall's near face
    worst = ("pass", "")
    for phase in PHASES:
        before = 3 + phase  # steps of flight before the contact
        table = {
            "name": "impact", "integrator": integrator, "detection": detection, "ordering": "time",
            "gravity": [0.0, 0.0, 0.0],
            "particles": [{"position": [face - speed * dt * before, 0.0, 0.0], "velocity": [speed, 0.0, 0.0],
                           "radius": IMPACT_RADIUS, "restitution": 1.0}],
            "planes": [{"name": "wall", "normal": [1.0, 0.0, 0.0], "offset": 0.0, "two_sided": True,
                        "thickness": WALL_THICKNESS}],
        }

        def beyond(start, end):
            return ("tunnelled", f"at v·dt = {speed * dt:.3g} m ({speed * dt / REACH:.3g} × REACH)") if end[0, 0] > 0 else None

        outcome = _run(table, 7, dt, beyond)
        if outcome[0] != "pass" and (worst[0] == "pass" or OUTCOMES.index(outcome[0]) < OUTCOMES.index(worst[0])):
            worst = outcome  # any failure beats a pass; the earlier in OUTCOMES, the graver
    return Cell("impact", integrator, detection, dt, speed, *worst)


def stack_cell(integrator: str, detection: str, restitution: float, height: int) -> Cell:
    """The stack map at (restitution, height)."""
    r = STACK_RADIUS
    table = {
        "name": "stack", "integrator": integrator, "detection": detection, "ordering": "time",
        "gravity": [0.0, -9.81, 0.0],
        "particles": [{"position": [0.0, r + 2 * r * i, 0.0], "radius": r, "restitution": restitution}
                      for i in range(height)],
        "planes": [{"name": "floor", "normal": [0.0, 1.0, 0.0], "offset": 0.0}],
    }

    def moved(start, end):
        drift = float(np.max(np.abs(end - start)))
        return ("sank", f"moved {drift:.3g} m") if drift > SANK_TOLERANCE and not _overlapping(end) else None

    return Cell("stack", integrator, detection, restitution, height,
                *_run(table, round(STACK_SECONDS / STACK_DT), STACK_DT, moved))


def _overlapping(positions: np.ndarray) -> bool:
    """A stack whose spheres overlap (reported as overlap left, which says more than sank)."""
    y = np.sort(positions[:, 1])
    return bool(y[0] < STACK_RADIUS - 1e-9 or np.any(np.diff(y) < 2 * STACK_RADIUS - 1e-9))


def cell(which: str, integrator: str, detection: str, x: float, y: float) -> Cell:
    """One cell of a map by its name (what a sweep's worker process is sent)."""
    return impact_cell(integrator, detection, x, y) if which == "impact" else stack_cell(integrator, detection, x, y)


def maps(quick: bool = False, on_cell: Callable[[Cell, int, int], None] | None = None, workers: int | None = None,
         dask: str | None = None, warm: Callable[[], None] | None = None) -> list[Cell]:
    """Both maps for every integrator × detection, on local cores by default or on Dask
    (analysis.sweep)."""
    from .sweep import run_jobs

    dts, speeds = (QUICK_IMPACT_DTS, QUICK_IMPACT_SPEEDS) if quick else (IMPACT_DTS, IMPACT_SPEEDS)
    heights = QUICK_STACK_HEIGHTS if quick else STACK_HEIGHTS
    jobs: list[tuple] = []
    for integrator in INTEGRATOR_NAMES:
        for detection in DETECTION_NAMES:
            jobs += [("impact", integrator, detection, dt, v) for dt in dts for v in speeds]
            jobs += [("stack", integrator, detection, e, n) for e in STACK_RESTITUTIONS for n in heights]
    return run_jobs(cell, jobs, workers=workers, dask=dask, on_done=on_cell, **({"warm": warm} if warm else {}))


def to_csv(cells: list[Cell]) -> str:
    import csv
    import io

    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["map", "integrator", "detection", "x", "y", "outcome", "detail"])
    for c in cells:
        writer.writerow([c.map, c.integrator, c.detection, repr(c.x), repr(c.y), c.outcome, c.detail])
    return out.getvalue()


def to_markdown(cells: list[Cell], command: str) -> str:
    """Per map and method: how many cells pass, and each failure with where it begins."""
    lines = [f"Made by `{command}`.", ""]
    for name, x_name, y_name in (("impact", "dt (s)", "speed (m/s)"), ("stack", "restitution", "height")):
        lines += [f"### {name}", ""]
        rows = []
        methods = sorted({c.method for c in cells if c.map == name}, key=lambda m: (
            INTEGRATOR_NAMES.index(m.split("/")[0]), DETECTION_NAMES.index(m.split("/")[1])))
        for method in methods:
            mine = [c for c in cells if c.map == name and c.method == method]
            passed = sum(c.outcome == "pass" for c in mine)
            failures = []
            for outcome in OUTCOMES[1:]:
                bad = [c for c in mine if c.outcome == outcome]
                if bad:
                    first = min(bad, key=lambda c: (c.x * c.y if name == "impact" else c.y, c.x))
                    failures.append(f"{outcome} ×{len(bad)} (e.g. {x_name} {first.x:.3g}, {y_name} {first.y:.3g})")
            rows.append([method, f"{passed}/{len(mine)}", "; ".join(failures) or "-"])
        lines += markdown_table(["method", "pass", "failures (first at)"], rows)
        lines.append("")
    return "\n".join(lines)


def first_step(cells: list[Cell], method: str, outcome: str = "tunnelled") -> float:
    """The smallest v·dt (m) at which a method had this outcome on the impact map (inf: never)."""
    hits = [c.x * c.y for c in cells if c.map == "impact" and c.method == method and c.outcome == outcome]
    return min(hits) if hits else math.inf


def summary_lines(cells: list[Cell]) -> list[str]:
    """`bench stability`'s summary, a line per method: impact cells passed and where it
    starts to tunnel (in v·dt and in REACH), and stack cells passed."""
    lines = []
    for method in dict.fromkeys(c.method for c in cells):
        step = first_step(cells, method)
        impact = [c for c in cells if c.map == "impact" and c.method == method]
        stack = [c for c in cells if c.map == "stack" and c.method == method]
        lines.append(f"{method:22} impact {sum(c.outcome == 'pass' for c in impact)}/{len(impact)} pass, "
                     + ("never tunnels" if math.isinf(step) else
                        f"tunnels from v·dt = {step:.3g} m ({step / REACH:.2g} × REACH)")
                     + f"; stacks {sum(c.outcome == 'pass' for c in stack)}/{len(stack)} pass")
    return lines


def last_step_without(cells: list[Cell], method: str, outcome: str = "tunnelled") -> float:
    """The largest v·dt (m) at which a method did not have this outcome (0: none)."""
    clear = [c.x * c.y for c in cells if c.map == "impact" and c.method == method and c.outcome != outcome]
    return max(clear) if clear else 0.0
