"""The argument groups of the compiled contact loop and its resolver.

``timeline.run_time_order`` and ``resolve.resolve_contact`` take the step's arrays and
settings in these few groups instead of fifty loose parameters. Each group is declared
here once, as a NamedTuple (its fields named, typed and documented), built by name in
``World._kernel_groups``, and handed to the kernels as a plain tuple (``tuple(group)``):
numba's dispatcher types a plain tuple in C, as fast as loose arguments, but a named
tuple in Python (4.6 µs against 1.6 µs a call, measured with two groups). A kernel
unpacks a group once at its top, positionally in the order below. A leaf module (numpy
only), so the loop, the resolver and the world all import it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class LoopParticles(NamedTuple):
    """Per-sphere arrays (N rows): positions, velocities (N, 3), path and contact-solved
    accelerations a, acc (N, 3) m/s², radius, inverse_mass, restitution, anchor time sigma
    (s), last contact time (s since the run began)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    acc: np.ndarray
    radius: np.ndarray
    inverse_mass: np.ndarray
    restitution: np.ndarray
    sigma: np.ndarray
    last_contact: np.ndarray


class LoopMethod(NamedTuple):
    """The step and its methods: run_time (s, at step start), step_end (dt, s), the
    integrator and detection codes, drag and k = -ln(drag), samples, the swept tests'
    tolerance (m), the resting and rapid rules (rest_fraction, rest_step_factor, rule (an
    index into RESTITUTION_RULES), rapid_time (s), rapid_rule (an index into
    resting.RAPID_RULES)), the integrator's traits
    (anchor_is_flow, path_follows_acc) and the held solves' tolerances vtol, atol."""

    run_time: float
    step_end: float
    integrator: int
    drag: float
    k: float
    detection: int
    samples: int
    tolerance: float
    rest_fraction: float
    rest_step_factor: float
    rule: int
    rapid_time: float
    rapid_rule: int
    anchor_is_flow: bool
    path_follows_acc: bool
    vtol: float
    atol: float


class LoopWalls(NamedTuple):
    """The planes (W rows): normals (W, 3), offsets, half_thickness (m), two_sided,
    restitution; and period (3,) m (0 = not periodic)."""

    normals: np.ndarray
    offsets: np.ndarray
    half_thickness: np.ndarray
    two_sided: np.ndarray
    restitution: np.ndarray
    period: np.ndarray

    @classmethod
    def of(cls, walls) -> LoopWalls:
        """The group of a scene's walls (state.Walls), as the kernels' contiguous float64
        (two_sided: bool) arrays."""
        def floats(values) -> np.ndarray:
            return np.ascontiguousarray(values, dtype=np.float64)
        return cls(floats(walls.normals).reshape(-1, 3), floats(walls.offsets), floats(walls.thickness * 0.5),
                   np.ascontiguousarray(walls.two_sided, dtype=np.bool_), floats(walls.restitution),
                   floats(walls.period).reshape(3))


class LoopCandidates(NamedTuple):
    """The broad phase's answer: CSR partners (adj_start (N+1,), adj), the swept boxes
    box_lo, box_hi (N, 3) m (grown to each sphere's reach) with their margin (m), the
    largest partner count, path_lo, path_hi (N, 3) m, the box of each sphere's current
    path over the rest of the step (the loop updates a sphere's when it re-predicts it),
    and scan_boxes: a re-query may be a scan of every swept box, run in the loop
    (timeline.grow_unpartnered; the broad phase's query is that scan, no axis periodic)."""

    adj_start: np.ndarray
    adj: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    box_margin: float
    max_degree: int
    path_lo: np.ndarray
    path_hi: np.ndarray
    scan_boxes: bool


class LoopBudgets(NamedTuple):
    """cap: contacts (max_events_per_step); max_tests: swept tests; work_budget: held-solve updates."""

    cap: int
    max_tests: int
    work_budget: int


class LoopBuffers(NamedTuple):
    """timeline.Buffers' arrays, as the loop writes them (``Buffers.loop()``)."""

    heap_toi: np.ndarray
    heap_data: np.ndarray
    test_int: np.ndarray
    test_float: np.ndarray
    test_outcome: np.ndarray
    contacts: np.ndarray
    counters: np.ndarray
    pending: np.ndarray
    changed: np.ndarray
    batch_mark: np.ndarray
    requery: np.ndarray
    requery_count: np.ndarray
