"""What the CLI calls: run a scene and summarise it.

>>> from physdbg.api import run
>>> summary = run("bounce", ["duration=1.0"])
>>> summary.steps, summary.contacts
(60, 2)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from .errors import PhysdbgError
from .scene import Scene, load_scene


@dataclass
class RunSummary:
    """What a run did. Energies in J, momentum in kg·m/s, times in s (ms_per_step in ms).

    energy_drift: (E_end - E_start) / |E_start| of kinetic + potential (0 when E_start = 0);
    momentum_drift: |p_end - p_start| (kg·m/s); dts: every step's dt, to repeat the run.
    compile_seconds: compiling (first run) or loading (cached) the numba kernels, not
    counted in wall_seconds or ms_per_step.
    """

    scene: str
    source: str
    integrator: str
    detection: str
    ordering: str
    broad_phase: str
    broad_phase_reason: str
    particles: int
    walls: int
    steps: int
    sim_time: float
    contacts: int
    swept_tests: int
    resting_at_end: int
    max_contacts_in_a_step: int
    energy_start: float
    energy_end: float
    energy_drift: float
    momentum_start: list[float]
    momentum_end: list[float]
    momentum_drift: float
    max_overlap: float
    wall_seconds: float
    compile_seconds: float
    ms_per_step: float
    phase_seconds: dict[str, float]
    final_hash: str
    warnings: list[str] = field(default_factory=list)
    dts: list[float] = field(default_factory=list, repr=False)

    def as_dict(self) -> dict:
        return asdict(self)


def run(scene: Scene | str, overrides: Sequence[str] = (), observer=None,
        dts: Sequence[float] | None = None,
        on_step: Callable[[int, int | None], None] | None = None) -> RunSummary:
    """Run a scene (built-in name, path, or Scene) to the end and summarise it.

    dts: replay exactly these step lengths (e.g. from a real-time run) instead of the
    scene's dt. on_step(done, total): called after each step (for progress bars).
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    elif overrides:
        raise PhysdbgError("give overrides when loading the scene, not with a Scene object")
    from .engine import energies, warm_up

    world = scene.build_world(observer)
    compile_seconds = warm_up(world.broad_phase.name)
    st = world.state

    k0, p0, mom0 = energies(st, world.gravity)
    total = len(dts) if dts is not None else scene.steps
    used: list[float] = []
    phase = {"forces": 0.0, "broad_phase": 0.0, "narrow_phase": 0.0, "resolve": 0.0, "finish": 0.0}
    contacts = tests = max_in_step = 0
    max_overlap = 0.0
    warnings: list[str] = []
    stats = None
    started = time.perf_counter()
    last = started
    while True:
        done = len(used)
        if dts is not None:
            if done >= len(dts):
                break
            dt = float(dts[done])
        elif scene.dt is not None:
            if done >= scene.steps:
                break
            dt = scene.dt
        else:  # real elapsed time, as the seed suggests; kept in `dts` to repeat the run
            if scene.steps is not None and done >= scene.steps:
                break
            if scene.steps is None and world.time >= scene.duration:
                break
            now = time.perf_counter()
            dt = min(max(now - last, 1e-6), scene.max_dt)
            last = now
        stats = world.step(dt)
        used.append(dt)
        for name, seconds in stats.timings.items():
            phase[name] += seconds
        contacts += stats.contacts
        tests += stats.swept_tests
        max_in_step = max(max_in_step, stats.contacts)
        max_overlap = max(max_overlap, stats.max_overlap)
        if stats.warnings and len(warnings) < 20:
            warnings.extend(stats.warnings[: 20 - len(warnings)])
        if on_step is not None:
            on_step(len(used), total)
    wall = time.perf_counter() - started
    k1, p1, mom1 = energies(st, world.gravity)
    e0, e1 = k0 + p0, k1 + p1
    drift = (e1 - e0) / abs(e0) if e0 != 0 else (e1 - e0)
    if stats is None:
        from .engine import state_hash

        digest = state_hash(st.positions, st.velocities)
    else:
        digest = stats.state_hash
    n_steps = len(used)
    return RunSummary(
        scene=scene.name, source=scene.source, integrator=scene.settings.integrator,
        detection=scene.settings.detection, ordering=scene.settings.ordering,
        broad_phase=world.broad_phase.name,
        broad_phase_reason=world.broad_phase_reason,
        particles=st.count, walls=len(scene.walls), steps=n_steps, sim_time=world.time,
        contacts=contacts, swept_tests=tests, resting_at_end=len(world.held),
        max_contacts_in_a_step=max_in_step, energy_start=e0, energy_end=e1, energy_drift=drift,
        momentum_start=[float(c) for c in mom0], momentum_end=[float(c) for c in mom1],
        momentum_drift=float(np.linalg.norm(mom1 - mom0)), max_overlap=max_overlap,
        wall_seconds=wall, compile_seconds=compile_seconds, ms_per_step=1000.0 * wall / n_steps if n_steps else math.nan,
        phase_seconds=phase, final_hash=digest, warnings=warnings, dts=used)
