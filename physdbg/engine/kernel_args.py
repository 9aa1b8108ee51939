"""The argument groups of the compiled kernels: the step's arrays and settings.

The forces phase (``resolve.settle_held``), the predictions (``timeline.predict_into``),
the contact loop (``timeline.run_time_order``) and the resolver
(``resolve.resolve_contact``) take the step's arrays and settings in these few groups
instead of fifty loose parameters, and hand them down whole. Each group is declared here
once, as a NamedTuple (its fields named, typed and documented), built by name in
``World._kernel_groups``, and handed to the kernels as a plain tuple (``tuple(group)``):
numba's dispatcher types a plain tuple in C, as fast as loose arguments, but a named
tuple in Python (4.6 µs against 1.6 µs a call, measured with two groups). The colliders'
geometry is a group of groups, one per collider kind, declared by each kind's own module
(colliders.geometry_of). A kernel reads the fields it needs through this module's
unpack helpers (``paths``, ``sweep``, ``test_log``, ...), which name them by their index
in the NamedTuple: a field added to a group changes the group and its helpers, no kernel.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


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


class LoopCandidates(NamedTuple):
    """The broad phase's answer: CSR partners (adj_start (N+1,), adj), the swept boxes
    box_lo, box_hi (N, 3) m (grown to each sphere's reach) with their margin (m), the
    largest partner count, path_lo, path_hi (N, 3) m, the box of each sphere's current
    path over the rest of the step (the loop updates a sphere's when it re-predicts it),
    and scan_boxes: a re-query may be a scan of every swept box, run in the loop
    (timeline.grow_unpartnered; the broad phase's query is that scan, no axis periodic);
    scan_partners: there are no partner lists to grow: a re-predicted sphere scans every
    sphere's path box (colliders/sphere.partners_of; World._choose_partner_search)."""

    adj_start: np.ndarray
    adj: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    box_margin: float
    max_degree: int
    path_lo: np.ndarray
    path_hi: np.ndarray
    scan_boxes: bool
    scan_partners: bool


class LoopBudgets(NamedTuple):
    """cap: contacts (max_contacts_per_step); max_tests: swept tests; work_budget: held-solve updates."""

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
    mesh_queries: np.ndarray


# ----------------------------------------------------------------------------- unpack helpers
# Each field's index in its group, from the NamedTuple itself (constants to numba: a
# tuple of arrays of different shapes is indexed by a compile-time constant).
_P = {name: i for i, name in enumerate(LoopParticles._fields)}
_M = {name: i for i, name in enumerate(LoopMethod._fields)}
_C = {name: i for i, name in enumerate(LoopCandidates._fields)}
_B = {name: i for i, name in enumerate(LoopBuffers._fields)}
P_X, P_V, P_A, P_ACC, P_RADIUS, P_INVERSE_MASS, P_RESTITUTION, P_SIGMA, P_LAST_CONTACT = (
    _P[n] for n in ("x", "v", "a", "acc", "radius", "inverse_mass", "restitution", "sigma", "last_contact"))
M_RUN_TIME, M_STEP_END, M_INTEGRATOR, M_DRAG, M_K, M_DETECTION, M_SAMPLES, M_TOLERANCE = (
    _M[n] for n in ("run_time", "step_end", "integrator", "drag", "k", "detection", "samples", "tolerance"))
M_REST_FRACTION, M_REST_STEP_FACTOR, M_ANCHOR_IS_FLOW, M_PATH_FOLLOWS_ACC, M_VTOL, M_ATOL = (
    _M[n] for n in ("rest_fraction", "rest_step_factor", "anchor_is_flow", "path_follows_acc", "vtol", "atol"))
M_RESTITUTION_RULE, M_RAPID_TIME, M_RAPID_RULE = (_M[n] for n in ("rule", "rapid_time", "rapid_rule"))
C_ADJ_START, C_ADJ, C_BOX_LO, C_BOX_HI, C_BOX_MARGIN, C_MAX_DEGREE, C_PATH_LO, C_PATH_HI, C_SCAN_PARTNERS = (
    _C[n] for n in ("adj_start", "adj", "box_lo", "box_hi", "box_margin", "max_degree", "path_lo", "path_hi",
                    "scan_partners"))
B_HEAP_TOI, B_HEAP_DATA, B_TEST_INT, B_TEST_FLOAT, B_TEST_OUTCOME, B_COUNTERS, B_BATCH_MARK, B_MESH_QUERIES = (
    _B[n] for n in ("heap_toi", "heap_data", "test_int", "test_float", "test_outcome", "counters", "batch_mark",
                    "mesh_queries"))


@njit(cache=True, inline="always")
def paths(particles):
    """(x, v, a, radius, sigma): what a sphere's path over the step is read from."""
    return particles[P_X], particles[P_V], particles[P_A], particles[P_RADIUS], particles[P_SIGMA]


@njit(cache=True, inline="always")
def forces(particles):
    """(acc, inverse_mass): the contact-solved accelerations and who can move."""
    return particles[P_ACC], particles[P_INVERSE_MASS]


@njit(cache=True, inline="always")
def sweep(method):
    """(step_end, integrator, k, detection, samples, tolerance): how a swept test runs."""
    return (method[M_STEP_END], method[M_INTEGRATOR], method[M_K], method[M_DETECTION], method[M_SAMPLES],
            method[M_TOLERANCE])


@njit(cache=True, inline="always")
def motion_of(method):
    """(step_end, integrator, drag, k): how the paths move."""
    return method[M_STEP_END], method[M_INTEGRATOR], method[M_DRAG], method[M_K]


@njit(cache=True, inline="always")
def solve_tolerances(method):
    """(vtol, atol): the held solves' velocity and acceleration tolerances."""
    return method[M_VTOL], method[M_ATOL]


@njit(cache=True, inline="always")
def boxes(candidates):
    """(box_lo, box_hi, box_margin, path_lo, path_hi): the swept boxes and the current paths' boxes."""
    return (candidates[C_BOX_LO], candidates[C_BOX_HI], candidates[C_BOX_MARGIN], candidates[C_PATH_LO],
            candidates[C_PATH_HI])


@njit(cache=True, inline="always")
def partner_lists(candidates):
    """(adj_start, adj): the broad phase's partners, CSR."""
    return candidates[C_ADJ_START], candidates[C_ADJ]


@njit(cache=True, inline="always")
def test_log(buffers):
    """(test_int, test_float, test_outcome, heap_toi, heap_data, counters): where a swept
    test is logged and a hit queued."""
    return (buffers[B_TEST_INT], buffers[B_TEST_FLOAT], buffers[B_TEST_OUTCOME], buffers[B_HEAP_TOI],
            buffers[B_HEAP_DATA], buffers[B_COUNTERS])
