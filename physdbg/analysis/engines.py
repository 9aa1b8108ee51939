"""physdbg against other engines on the same scenes: cost (ms/step) against error.

``physdbg bench engines`` runs each scene in some of physdbg's methods and in each peer
(pybullet, MuJoCo: set up for the same physics by physdbg/peers.py), times the steps, and
measures each run against physdbg's exact run of the scene:

* **largest overlap** (m): how deep two spheres, or a sphere and a wall, are inside each
  other after a step (the deepest over the frames measured);
* **energy error**: the largest |E − E_exact| over the frames measured, relative to the
  exact run's starting energy (kinetic + potential);
* **contact time** (s): |when the first contact happened − when the exact run had it|; a
  physdbg method's own contact record says when; a peer's is read off its trajectory (the
  instant in the step that splits its displacement between the velocities before and
  after, as check-run reads a kick), measured on the small scenes only;
* **tunnelled**: bodies that went through a wall (a two-sided wall's middle crossed, or
  more than a radius behind a one-sided one) at any frame measured.

Steps are timed in a pass of their own with nothing watching, the world built and the
kernels loaded beforehand; a second pass measures the errors (every frame, or every k-th
in the large scenes so the states kept stay under SAMPLE_BUDGET floats).
"""

from __future__ import annotations

import csv
import io
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from types import SimpleNamespace

import numpy as np

from ..peers import PeerSetup
from .report import markdown_table

SAMPLE_BUDGET = 30_000_000  # floats of positions and velocities a measured run keeps
KICK_FRACTION = 0.02  # as check-run: a velocity change beyond this share of speed + |a|·dt is a kick


def box_rain_scene(count: int, steps: int, overrides: tuple[str, ...] = ()):
    """box-rain: ``count`` spheres (r = 0.05 m, e = 0.8) rain into a box whose volume they
    fill to 10 %, dt = 1/240 s (the built-in rain scene, grown); the pile rules are the
    scene's (auto: the TC rule and sleeping, as it makes a pile). overrides: KEY=VALUE."""
    from ..advisor import decide
    from ..scene import read_scene

    side = (count * 4.0 / 3.0 * math.pi * 0.05**3 / 0.1) ** (1.0 / 3.0)
    return decide(read_scene("rain", [f"generate.count={count}", "generate.radius=0.05",
                                      f"box.max=[{side},{side},{side}]", "dt=1/240", f"steps={steps}",
                                      "generate.restitution=0.8", "box.restitution=0.8", *overrides]))


@dataclass(frozen=True)
class Method:
    """One engine and setting: engine "physdbg" (with overrides) or a peer (with setup)."""

    label: str
    engine: str
    overrides: tuple[str, ...] = ()
    setup: PeerSetup | None = None


METHODS = (
    Method("physdbg exact", "physdbg"),
    Method("physdbg discrete", "physdbg", ("detection=discrete",)),
    Method("physdbg euler + discrete", "physdbg", ("integrator=euler", "detection=discrete")),
    Method("pybullet", "pybullet", setup=PeerSetup("pybullet")),
    Method("mujoco PGS-10 +sleep", "mujoco", setup=PeerSetup("mujoco", "PGS", 10, sleep=True)),
    Method("mujoco Newton-100", "mujoco", setup=PeerSetup("mujoco")),
)

# scene name: (how to build it, in the quick set)
SCENES: dict[str, tuple[Callable, bool]] = {
    "bounce": (lambda: _builtin("bounce"), True),
    "cradle": (lambda: _builtin("cradle"), True),
    "bullet-wall": (lambda: _builtin("bullet-wall"), True),
    "gas": (lambda: _builtin("gas", ["generate.count=200", "duration=1"]), True),
    "box-rain 1k": (lambda: box_rain_scene(1000, 240), True),
    "box-rain 10k": (lambda: box_rain_scene(10000, 240), False),
}
SMALL_SCENES = ("bounce", "cradle", "bullet-wall")  # where the contact time is measured


def _builtin(name: str, overrides=()):
    from ..advisor import decide
    from ..scene import read_scene

    return decide(read_scene(name, list(overrides)))


@dataclass
class EngineRun:
    """One method on one scene: ms_per_step; the errors against physdbg's exact run (None:
    not measured); failure: why it could not run (then no numbers)."""

    scene: str
    method: str
    engine: str
    ms_per_step: float | None = None
    largest_overlap: float | None = None
    energy_error: float | None = None
    contact_time_error: float | None = None
    tunnelled: int | None = None
    steps: int = 0
    bodies: int = 0
    failure: str = ""
    notes: list[str] = field(default_factory=list)


def run_all(scenes=None, quick: bool = False, methods=METHODS,
            on_run: Callable[[EngineRun, int, int], None] | None = None) -> list[EngineRun]:
    """Every method on every scene (quick: the quick set); on_run(run, done, total)."""
    from ..peers import available

    names = [n for n in SCENES if (scenes is None or n in scenes) and (not quick or SCENES[n][1] or scenes)]
    total, done = len(names) * len(methods), 0
    out = []
    for name in names:
        scene_of = SCENES[name][0]
        reference = _measure_physdbg(scene_of(), (), name in SMALL_SCENES)
        for method in methods:
            run = EngineRun(name, method.label, method.engine)
            try:
                if method.engine != "physdbg" and not available(method.engine):
                    run.failure = f"{method.engine} is not installed (pip install 'physdbg[peers]')"
                else:
                    _run_one(run, method, scene_of, reference, name in SMALL_SCENES)
            except Exception as err:  # a method that cannot run the scene is a row that says so
                run.failure = f"{type(err).__name__}: {err}"
            out.append(run)
            done += 1
            if on_run is not None:
                on_run(run, done, total)
    return out


def _run_one(run: EngineRun, method: Method, scene_of, reference: dict, small: bool) -> None:
    scene = scene_of() if not method.overrides else _rebuilt(scene_of(), method.overrides)
    run.steps, run.bodies = scene.steps, scene.state.count
    if method.engine == "physdbg":
        measured = reference if not method.overrides else _measure_physdbg(scene, method.overrides, small)
        run.ms_per_step = _time_physdbg(scene)
    else:
        from ..peers import build

        measured = _measure_peer(scene, method.setup, small)
        run.ms_per_step = _time_peer(scene, method.setup, build)
        run.notes = measured["notes"]
    _errors(run, scene, measured, reference)


def _rebuilt(scene, overrides):
    """The scene again with more overrides (its own first)."""
    from ..advisor import decide
    from ..scene import read_scene

    return decide(read_scene(scene.source if scene.source.endswith(".toml") else scene.name,
                             [*getattr(scene, "overrides", ()), *overrides]))


def _sample_every(scene) -> int:
    return max(1, math.ceil(6 * scene.state.count * (scene.steps + 1) / SAMPLE_BUDGET))


def _time_physdbg(scene) -> float:
    from ..engine.warm import warm_up

    world = scene.build_world()
    warm_up(world.broad_phase.name, sleeping=world.sleepers is not None)
    world.step(scene.dt)  # the first step builds what the later ones reuse: timed apart from them
    started = time.perf_counter()
    for _ in range(scene.steps - 1):
        world.step(scene.dt)
    return 1000.0 * (time.perf_counter() - started) / max(scene.steps - 1, 1)


def _time_peer(scene, setup, build) -> float:
    world = build(scene, setup)
    try:
        world.step()
        started = time.perf_counter()
        for _ in range(scene.steps - 1):
            world.step()
        return 1000.0 * (time.perf_counter() - started) / max(scene.steps - 1, 1)
    finally:
        world.close()


def _measure_physdbg(scene, overrides, small: bool) -> dict:
    """States at the sampled frames and the first contact's time, from a run of scene."""
    from ..events import Contacts, StepBegin

    first = []

    class FirstContact:
        """The time of the run's first contact (the step's start plus the contact's time in it)."""

        wants_swept_tests = False
        wants_mesh_search = False
        time = 0.0

        def on_event(self, event):
            if isinstance(event, StepBegin):
                self.time = event.time
            elif isinstance(event, Contacts) and len(event) and not first:
                first.append(self.time + float(event.time_in_step[0]))

    watcher = FirstContact()
    world = scene.build_world(watcher)
    every = _sample_every(scene)
    frames = [(0.0, scene.state.positions.copy(), scene.state.velocities.copy())]
    for k in range(1, scene.steps + 1):
        world.step(scene.dt)
        if k % every == 0 or k == scene.steps:
            frames.append((world.time, world.state.positions.copy(), world.state.velocities.copy()))
    return {"frames": frames, "every": every, "first_contact": first[0] if first else None, "notes": []}


def _measure_peer(scene, setup, small: bool) -> dict:
    from ..peers import build

    world = build(scene, setup)
    try:
        every = 1 if small else _sample_every(scene)
        frames = [(0.0, world.positions(), world.velocities())]
        t = 0.0
        for k in range(1, scene.steps + 1):
            world.step()
            t += scene.dt
            if k % every == 0 or k == scene.steps:
                frames.append((t, world.positions(), world.velocities()))
        notes = world.notes
    finally:
        world.close()
    first = _first_kick(scene, frames) if small else None
    return {"frames": frames, "every": every, "first_contact": first, "notes": notes}


def _first_kick(scene, frames) -> float | None:
    """When in the run the first kick came: the first frame pair where a body's velocity
    changed by more than the forces explain, and the instant in that step that splits its
    displacement between the velocities before and after."""
    st = scene.state
    g = np.asarray(scene.settings.gravity, dtype=float)
    acc = np.where((st.inverse_mass > 0)[:, None], st.gravity_scale[:, None] * g[None, :], 0.0)
    for (t0, x0, v0), (t1, x1, v1) in zip(frames, frames[1:], strict=False):
        dt = t1 - t0
        change = np.linalg.norm(v1 - v0 - acc * dt, axis=1)
        kicked = np.flatnonzero(change > KICK_FRACTION * (np.linalg.norm(v0, axis=1) + np.linalg.norm(acc, axis=1) * dt)
                                + 1e-12)
        if not len(kicked):
            continue
        i = int(kicked[0])
        along = v0[i] - v1[i]
        size = float(along @ along)
        tau = dt if not size > 0 else float(np.clip(((x1[i] - x0[i] - v1[i] * dt) @ along) / size, 0.0, dt))
        return t0 + tau
    return None


def _errors(run: EngineRun, scene, measured: dict, reference: dict) -> None:
    from .audit import deepest_overlap

    st, walls = scene.state, scene.walls
    g = np.asarray(scene.settings.gravity, dtype=float)
    by_time = {round(t, 9): (x, v) for t, x, v in reference["frames"]}
    e0 = None
    worst_energy, worst_overlap = 0.0, 0.0
    through = np.zeros(st.count, dtype=bool)
    start_side = np.sign(st.positions @ walls.normals.T - walls.offsets[None, :]) if len(walls) else None
    for t, x, v in measured["frames"]:
        worst_overlap = max(worst_overlap, deepest_overlap(x, st.radius, walls, t)[0])
        if len(walls):
            h = x @ walls.normals.T - walls.offsets[None, :]
            crossed = np.where(walls.two_sided[None, :], np.sign(h) != start_side,
                               h < -st.radius[:, None])
            through |= crossed.any(axis=1) | ~np.isfinite(x).all(axis=1)
        ref = by_time.get(round(t, 9))
        if ref is not None:
            energy, ref_energy = _energy(st, x, v, g), _energy(st, ref[0], ref[1], g)
            e0 = abs(ref_energy) if e0 is None else e0
            worst_energy = max(worst_energy, abs(energy - ref_energy))
    run.largest_overlap = worst_overlap
    run.energy_error = worst_energy / e0 if e0 else None
    run.tunnelled = int(np.count_nonzero(through))
    if measured["first_contact"] is not None and reference["first_contact"] is not None:
        run.contact_time_error = abs(measured["first_contact"] - reference["first_contact"])


def _energy(st, x, v, g) -> float:
    from ..engine.state import energies

    kinetic, potential, _ = energies(SimpleNamespace(positions=np.ascontiguousarray(x),
                                                     velocities=np.ascontiguousarray(v),
                                                     inverse_mass=st.inverse_mass, gravity_scale=st.gravity_scale), g)
    return kinetic + potential


# ----------------------------------------------------------------------------- output
def summary_lines(runs: list[EngineRun]) -> list[str]:
    """`bench engines`'s summary: a line per scene (physdbg exact against the fastest method,
    with that method's largest overlap and tunnelling), then each run that could not run."""
    lines = []
    for name in dict.fromkeys(r.scene for r in runs):
        mine = [r for r in runs if r.scene == name and not r.failure]
        exact = next((r for r in mine if r.method == "physdbg exact"), None)
        fastest = min(mine, key=lambda r: r.ms_per_step, default=None)
        if exact is not None and fastest is not None:
            lines.append(f"{name:13} physdbg exact {exact.ms_per_step:.3g} ms/step; fastest {fastest.method} "
                         f"{fastest.ms_per_step:.3g} ms/step (largest overlap {fastest.largest_overlap:.2g} m, "
                         f"{fastest.tunnelled} tunnelled)")
    lines += [f"{run.scene:13} {run.method}: could not run ({run.failure})" for run in runs if run.failure]
    return lines


COLUMNS = ("scene", "method", "engine", "ms_per_step", "largest_overlap", "energy_error", "contact_time_error",
           "tunnelled", "steps", "bodies", "failure")


def to_csv(runs: list[EngineRun]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=COLUMNS, extrasaction="ignore")
    writer.writeheader()
    for run in runs:
        writer.writerow({k: ("" if v is None else v) for k, v in asdict(run).items()})
    return out.getvalue()


def _fmt(value, unit: str = "") -> str:
    if value is None:
        return "—"
    if isinstance(value, int):
        return str(value)
    return "0" if value == 0 else f"{value:.2g}{unit}"


def to_markdown(runs: list[EngineRun], command: str) -> str:
    lines = [f"Made by `{command}`: each scene in each engine and setting, the steps timed with nothing watching; "
             f"the errors against physdbg's exact run of the scene (docs/benchmarks.md, \"Engines\").", ""]
    lines += markdown_table(
        ["scene", "engine and setting", "ms/step", "largest overlap (m)", "energy error", "contact time error (s)",
         "tunnelled"],
        [[run.scene, run.method, f"could not run: {run.failure}", None, None, None, None] if run.failure else
         [run.scene, run.method, f"{run.ms_per_step:.3g}", _fmt(run.largest_overlap), _fmt(run.energy_error),
          _fmt(run.contact_time_error), _fmt(run.tunnelled)] for run in runs])
    notes = {}
    for run in runs:  # each setting's notes once, from the first scene it ran
        if run.notes and run.method not in notes:
            notes[run.method] = run.notes
    if notes:
        lines += ["", "How each peer was set up (the step length is each scene's):", ""]
        lines += [f"- **{method}**: {' '.join(n)}" for method, n in notes.items()]
    return "\n".join(lines) + "\n"


__all__ = ["COLUMNS", "METHODS", "SCENES", "EngineRun", "Method", "box_rain_scene", "run_all", "to_csv", "to_markdown"]
