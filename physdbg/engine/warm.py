"""Compiling the engine before a run: ``warm_up`` runs small worlds so that every kernel a
step uses is compiled (or loaded from numba's cache) before the first real step, which
is then not charged with it; its two halves, which ``physdbg/precompile.py`` (outside the
core: it starts a process) runs side by side on a cold cache; and the small world they
run (``warm_up_world``, also the audit's)."""

from __future__ import annotations

from time import perf_counter

import numpy as np

from .broadphase import make_broad_phase
from .broadphase.boxes import overlapping
from .resting import new_held
from .sleep import release_static
from .state import Settings, State, Walls
from .timeline import merge_sorted_pairs
from .world import World


def warm_up(broad_phase: str | None = None, sleeping: bool = False, meshes: bool = False,
            calendar: bool = False) -> float:
    """Compile (or load from numba's cache) every kernel a step uses; returns seconds taken.

    Runs a two-sphere, one-wall world for one step with contacts, so the first real step
    is not charged with compilation. The kernels take the integrator and detection as
    arguments, so one run compiles every method. broad_phase: also compile this one;
    sleeping: also the sleep rules' (sleep.py; only a run that sleeps loads them);
    meshes: also the meshes' (the trees' walks, their choice, a moving mesh's placing: only
    a scene with meshes loads them; without this, its first step compiled them, some 10 s
    cold, and the run summary charged them to the narrow phase); calendar: also the event
    calendar's (calendar.py: only a run with event_loop = "calendar" loads them).
    (physdbg.precompile runs this on two cores when the cache is cold.)
    """
    started = perf_counter()
    _warm_up_broad_phase(broad_phase)
    state, walls = warm_up_world()
    for detection in ("swept", "sampled"):
        world = World(state.copy(), walls, Settings(detection=detection))
        world.step(0.5)
    # a mid-step re-query's (World._refresh_box, _add_partners), rare in this small world:
    # otherwise the first one in a run pays ~5 ms loading particle_box's Python entry
    world._refresh_box(world.last_step, 0)
    no_pairs = np.empty((0, 2), dtype=np.int64)
    merge_sorted_pairs(no_pairs, no_pairs)
    overlapping(state.positions, state.positions, state.positions[0], state.positions[0])
    if sleeping:
        World(state.copy(), walls, Settings(sleep_speed=0.1, sleep_time=0.1)).step(0.5)
        release_static(new_held(state.count), np.zeros(state.count))
    if meshes:
        warm_up_meshes()
    if calendar:
        World(state.copy(), walls, Settings(gravity=(0.0, 0.0, 0.0), event_loop="calendar")).step(0.5)
        # under gravity with restitution 0 both spheres are held after the first step: the
        # later ones settle them, anchor them again and expire skips (Calendar.renew,
        # expire_skips), which a run's second step otherwise loads (~0.1 s)
        held_state, held_walls = warm_up_world()
        held_state.restitution[:] = 0.0
        held_walls.restitution[:] = 0.0
        world = World(held_state, held_walls, Settings(event_loop="calendar"))
        for _ in range(3):
            world.step(0.5)
    return perf_counter() - started


def warm_up_meshes() -> None:
    """warm_up's meshes: warm_up_world with a turning triangle under each sphere, a step in
    each mesh search (a walk per sphere, the simultaneous descent)."""
    from .state import Meshes

    state, walls = warm_up_world()
    corners = np.array([[[-1.0, 0.05, -1.0], [1.0, 0.05, 1.0], [1.0, 0.05, -1.0]],
                        [[-1.0, 0.05, -1.0], [-1.0, 0.05, 1.0], [1.0, 0.05, 1.0]]])
    walls.meshes = Meshes(["warm"], np.ones(1), corners, np.zeros(2, dtype=np.int64), ["warm"], [],
                          np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]]), np.zeros((1, 3)))
    for search in ("walk", "together"):
        World(state.copy(), walls, Settings(mesh_search=search)).step(0.5)


def warm_up_held_solve() -> None:
    """The first of warm_up's call trees: the forces phase of its world (settle_held and
    the resting solve beneath it, about 40 % of a cold compile)."""
    state, walls = warm_up_world()
    world = World(state, walls, Settings())
    world._forces(world._begin(0.5))


def warm_up_without_forces(broad_phase: str | None = None) -> None:
    """The second: the rest of the step, with no forces phase (its outputs set as it
    leaves them when nothing is held: the free accelerations, every anchor at the step's
    start). First all that needs no resting solve (the grid and the broad phase named;
    the broad, narrow and finish phases of a sleeping world, the sleep rules included),
    the time-ordered loop last: its held solve calls the resting solve, which a process
    compiling warm_up_held_solve beside this one has by then cached, nearly or wholly
    (physdbg.precompile). The worlds are thrown away: only the compiling counts."""
    _warm_up_broad_phase("grid")
    _warm_up_broad_phase(broad_phase)
    _phases_without_forces("finish", sleep_speed=0.1, sleep_time=0.1)
    _phases_without_forces("resolve")


def _phases_without_forces(last: str, **settings) -> None:
    state, walls = warm_up_world()
    world = World(state, walls, Settings(**settings))
    ctx = world._begin(0.5)
    ctx.path_accel = world._free_accel.copy()
    ctx.sigma = np.zeros(state.count)
    world._broad_phase(ctx)
    world._narrow_phase(ctx)
    (world._finish if last == "finish" else world._resolve)(ctx)


def _warm_up_broad_phase(broad_phase: str | None) -> None:
    if broad_phase is not None and broad_phase != "brute-force":
        boxes = np.random.default_rng(0).uniform(0.0, 1.0, (8, 3))
        make_broad_phase(broad_phase).pairs(boxes, boxes + 0.3)


def warm_up_world() -> tuple[State, Walls]:
    """Two spheres that meet each other and a floor within 0.5 s (warm_up's, and the
    audit's: analysis.audit.warm_up)."""
    state = State(np.array([[0.0, 0.3, 0.0], [0.5, 0.3, 0.0]]), np.array([[1.0, -1.0, 0.0], [-1.0, 0.0, 0.0]]),
                  np.ones(2), np.full(2, 0.1), np.ones(2), np.ones(2))
    walls = Walls(["floor"], np.array([[0.0, 1.0, 0.0]]), np.zeros(1), np.ones(1), np.zeros(1, dtype=np.bool_),
                  np.zeros(1))
    return state, walls
