"""What lives for one step: made when ``World.step`` begins, dropped when the next begins.

The world keeps what lasts a run (the state, the walls, the settings, the held contacts,
each sphere's last contact time, the loop's buffers); everything a step computes for
itself and the phases hand on to each other is here, so the step's pipeline reads as
phases over one context (Box2D's b2StepContext) and nothing step-scoped sits on the world.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..events import EngineWarning


@dataclass
class StepContext:
    """One step's working set.

    step: the step's number, counted from 1 (the recording's frame of its end state); dt:
    its length (s); run_time: the run's time at its start (s); vtol: the velocity tolerance of this step's held-contact solves (m/s);
    observer: where events go (None: nobody listens).
    Set by the phases, in order:
    forces: path_accel (N, 3) m/s², the acceleration each path follows (contact-solved);
    sigma (N,) s, each sphere's anchor time in the step (motion.py).
    broad_phase: path_lo, path_hi (N, 3) m, the box of each path over the step; lo, hi
    (N, 3) m, those boxes grown to what the sphere could reach after a contact (and again
    mid-step when a contact sends a sphere out of its box); pairs (P, 2) int64, sorted candidate pairs; adj_start (N+1,),
    adj (2P,) their CSR adjacency and max_degree; grown, the spheres whose boxes grew;
    too_wide_mid_step, why a grown box broke the periodic minimum image (or None).
    resolve: kernel_groups, the step's arrays as the compiled kernels take them (built
    once, World._kernel_groups).
    finish: max_overlap (m); with sleeping on (sleep.py), sleeping_pairs (the broad
    phase's pairs of two sleeping spheres, left out of ``pairs``), how many spheres
    slept and woke, and which (sleep_changed, int64: their paths changed at the step's end); kinetic, potential (J), momentum (3,), state_hash, non_finite.
    warnings and timings (s per phase) collect through the step.
    """

    step: int
    dt: float
    run_time: float
    vtol: float
    observer: object | None = None
    path_accel: np.ndarray | None = None
    sigma: np.ndarray | None = None
    path_lo: np.ndarray | None = None
    path_hi: np.ndarray | None = None
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    pairs: np.ndarray | None = None
    adj_start: np.ndarray | None = None
    adj: np.ndarray | None = None
    max_degree: int = 0
    grown: set[int] = field(default_factory=set)
    scan_partners: bool = False  # re-predictions scan every path box: no partner lists (World._choose_partner_search)
    too_wide_mid_step: str | None = None
    kernel_groups: tuple | None = None
    out_of_memory: int = 0  # bytes the buffers would have needed, when max_memory stopped growing them
    # the step's walks of the meshes' trees, for an observer that reads them (World._mesh_search):
    # the path boxes asked at step start (lo, hi (N, 3) m), then the MeshSearch event
    search_start: tuple | None = None
    mesh_search_method: str = ""  # "walk" or "together": how the step's candidates were found (World._mesh_candidates)
    mesh_search: object | None = None
    max_overlap: float = 0.0
    overlap_with: tuple[int, int, int] | None = None  # (kind, sphere, partner) of max_overlap
    sleeping_pairs: np.ndarray = field(default_factory=lambda: np.empty((0, 2), np.int64))
    slept: int = 0
    woken: int = 0
    sleep_changed: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    kinetic: float = 0.0
    potential: float = 0.0
    momentum: np.ndarray | None = None
    state_hash: str = ""
    non_finite: tuple | None = None
    warnings: list[EngineWarning] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)

    def warn(self, code: str, message: str, bodies: tuple[int, ...] = ()) -> None:
        """Note a warning for this step (bodies: the spheres it is about) and report it at once."""
        self.warnings.append(EngineWarning(self.step, code, message, tuple(int(b) for b in bodies)))
        if self.observer is not None:
            self.observer.on_event(self.warnings[-1])

    def warned(self, code: str) -> bool:
        return any(w.code == code for w in self.warnings)

    def partners(self, i: int) -> np.ndarray:
        """Sphere i's broad-phase partners (int64 indices)."""
        return self.adj[self.adj_start[i]:self.adj_start[i + 1]]


def wants_mesh_search(observer) -> bool:
    """Whether the step keeps the boxes it asks the meshes' trees with and sends the
    ``MeshSearch`` event (a scene with meshes): for an observer that reads it, which says
    so with a ``wants_mesh_search`` attribute (one without it gets every event). The
    audit and the run summary read none of it."""
    return observer is not None and bool(getattr(observer, "wants_mesh_search", True))


def wants_swept_tests(observer) -> bool:
    """Whether the step logs every swept test, misses included, and sends the
    ``SweptTests`` event: only for an observer that reads it. An observer says so with a
    ``wants_swept_tests`` attribute (physdbg.observe.FanOut asks each of its observers);
    one without it gets every event. A dense step runs tens of millions of tests, about
    95 % misses, at 41 bytes a row: the audit, the Rerun view and a recording below
    detail "full" read none of them. Logging or not changes no result (the hits keep
    their order: Buffers.reset)."""
    return observer is not None and bool(getattr(observer, "wants_swept_tests", True))
