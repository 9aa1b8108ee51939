"""The time-ordered contact loop, compiled: the hot path of ``World.step``.

The world hands this module its per-step arrays and a set of *buffers*; the loop pops
the earliest predicted contact, drops it if stale, resolves it (advance the particles to
the contact, impulse or reflection, finish over the remaining time), re-predicts only the
particles involved and pushes their new predictions — until nothing is left before the
end of the step. Everything it does is written to buffers (Box2D-style event arrays):
every swept test (kind, particles, start, toi, outcome) and every contact (time, point,
normal, impulse, velocities before and after ...). The world turns them into typed
events afterwards, only if someone observes.

Resolving is resolve.resolve_contact, the one resolver (it also solves resting, rapid
and held contacts, resting.py). The spheres it changed are re-predicted one by one from
a pending list, so the loop can pause between any two of them. It *pauses* and returns
to Python for:

* REQUERY: a new path left the swept box its broad-phase pairs were found for;
* GROW: a buffer, or the held-contact store, is nearly full.

It stops for good with CAPPED (the contact budget, max_events_per_step), TEST_BUDGET
(max_swept_tests_per_step) or RESTING_BUDGET (max_resting_work_per_step): the step's
remaining predictions are marked capped.

Python handles it and calls ``run_time_order`` again, which carries on where it stopped.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..events import CONTACT_ROW, KIND_PAIR, KIND_WALL, OUTCOME_CAPPED, OUTCOME_HIT, OUTCOME_MISS, OUTCOME_SUPERSEDED
from .broadphase.boxes import box_misses
from .jit import borrowing, kernel
from .kernel_args import LoopBuffers
from .motion import particle_box, path_acceleration_weight, path_coefficients
from .periodic import image
from .resolve import OUT_OF_WORK, SKIPPED, pair_separation, resolve_contact
from .resting import held_find, held_room
from .toi import (
    DISCRETE,
    SWEPT,
    pair_toi_sampled_scalar,
    pair_toi_swept_scalar,
    wall_gap_terms,
    wall_toi_sampled,
    wall_toi_swept,
)

# statuses
DONE = 0
REQUERY = 2
GROW = 3
CAPPED = 4
TEST_BUDGET = 5
GROW_HELD = 6
RESTING_BUDGET = 7

# counters
HEAP_SIZE = 0
TESTS = 1
CONTACTS = 2
EVENTS = 3
RAPID = 4  # contacts the rapid-contact (TC) rule held
PENDING_COUNT = 5  # spheres waiting to be re-predicted ...
PENDING_AT = 6  # ... and how many of them are done
BATCH = 7  # id of the current batch of re-predictions
ROWS = 8  # rows of the test log written this step (TESTS counts every test)
KEEP_MISSES = 9  # 1: log every test (the step is observed); 0: only those that hit
COUNTERS = 10


class Buffers:
    """Growable arrays the compiled loop writes into; one set per World."""

    def __init__(self, n: int, heap: int = 1024, tests: int = 4096, contacts: int = 256):
        self.heap_toi = np.empty(heap)
        self.heap_data = np.empty((heap, 6), dtype=np.int64)  # rid, kind, a, other, version a, version b
        self.test_int = np.empty((tests, 3), dtype=np.int64)  # kind, a, other
        self.test_float = np.empty((tests, 2))  # start, toi
        self.test_outcome = np.empty(tests, dtype=np.int8)
        self.contacts = np.empty(contacts, dtype=CONTACT_ROW)  # the rows of the Contacts event
        self.counters = np.zeros(COUNTERS, dtype=np.int64)
        self.pending = np.empty(max(n, 2), dtype=np.int64)  # spheres to re-predict
        self.changed = np.empty(max(n, 2) + 1, dtype=np.int64)  # count, then spheres (resolve_contact)
        self.batch_mark = np.full(max(n, 2), -1, dtype=np.int64)  # batch id of each sphere's last change
        self.requery = np.empty(max(n, 2), dtype=np.int64)
        self.requery_count = np.zeros(1, dtype=np.int64)

    def loop(self) -> tuple:
        """The arrays as run_time_order takes them (kernel_args.LoopBuffers, as a plain
        tuple; again after any growth)."""
        return tuple(LoopBuffers(self.heap_toi, self.heap_data, self.test_int, self.test_float, self.test_outcome,
                                 self.contacts, self.counters, self.pending, self.changed, self.batch_mark,
                                 self.requery, self.requery_count))

    def reset(self, keep_misses: bool = True) -> None:
        """Start a step. keep_misses: log every swept test; False logs only the tests that
        hit within the step (what the loop acts on): an unobserved step of a dense scene
        runs tens of millions of tests, 95 % of them misses, at 41 bytes a row."""
        batch = self.counters[BATCH]  # batch ids stay unique across steps (batch_mark keeps old ones)
        self.counters[:] = 0
        self.counters[BATCH] = batch
        self.counters[KEEP_MISSES] = 1 if keep_misses else 0
        self.requery_count[0] = 0

    def ensure(self, heap_room: int, test_room: int, contact_room: int) -> None:
        """Make sure at least this much more fits in each buffer (doubling as needed)."""
        c = self.counters
        while self.heap_toi.shape[0] - c[HEAP_SIZE] < heap_room:
            self.heap_toi = _grown(self.heap_toi)
            self.heap_data = _grown(self.heap_data)
        while self.test_outcome.shape[0] - c[ROWS] < test_room:
            self.test_int = _grown(self.test_int)
            self.test_float = _grown(self.test_float)
            self.test_outcome = _grown(self.test_outcome)
        while self.contacts.shape[0] - c[CONTACTS] < contact_room:
            self.contacts = _grown(self.contacts)


def _grown(array: np.ndarray) -> np.ndarray:
    bigger = np.empty((2 * array.shape[0],) + array.shape[1:], dtype=array.dtype)
    bigger[: array.shape[0]] = array
    return bigger


# ------------------------------------------------------------------------------ heap
@njit(cache=True, inline="always")
def _less(toi, data, i, j):
    return toi[i] < toi[j] or (toi[i] == toi[j] and data[i, 0] < data[j, 0])


@njit(cache=True, inline="always")
def _swap(toi, data, i, j):
    t = toi[i]
    toi[i] = toi[j]
    toi[j] = t
    for c in range(6):
        d = data[i, c]
        data[i, c] = data[j, c]
        data[j, c] = d


@njit(cache=True, inline="always")
def heap_push(toi, data, counters, t, rid, kind, a, other, va, vb):
    n = counters[HEAP_SIZE]
    toi[n] = t
    data[n, 0] = rid
    data[n, 1] = kind
    data[n, 2] = a
    data[n, 3] = other
    data[n, 4] = va
    data[n, 5] = vb
    counters[HEAP_SIZE] = n + 1
    while n > 0:
        up = (n - 1) // 2
        if _less(toi, data, n, up):
            _swap(toi, data, n, up)
            n = up
        else:
            break


@borrowing
def heap_pop(toi, data, counters):
    """Move the smallest entry to the slot just past the heap and return that slot."""
    n = counters[HEAP_SIZE] - 1
    _swap(toi, data, 0, n)
    counters[HEAP_SIZE] = n
    i = 0
    while True:
        left = 2 * i + 1
        if left >= n:
            break
        child = left
        if left + 1 < n and _less(toi, data, left + 1, left):
            child = left + 1
        if _less(toi, data, child, i):
            _swap(toi, data, child, i)
            i = child
        else:
            break
    return n


# ------------------------------------------------------------------------------ predict
@njit(cache=True, inline="always")
def _record(kind, i, j, start, t, step_end, version, test_int, test_float, test_outcome, heap_toi, heap_data,
            counters, push):
    """Count a swept test, log it (every test, or only a hit: counters[KEEP_MISSES]) and
    push a hit onto the heap if ``push``. Rows keep the order of the tests, so the heap's
    tie-break by row is the same either way."""
    counters[TESTS] += 1
    hit = start + t <= step_end
    if not hit and counters[KEEP_MISSES] == 0:
        return
    rid = counters[ROWS]
    test_int[rid, 0] = kind
    test_int[rid, 1] = i
    test_int[rid, 2] = j
    test_float[rid, 0] = start
    test_float[rid, 1] = start + t
    test_outcome[rid] = OUTCOME_MISS
    counters[ROWS] = rid + 1
    if push and hit:
        heap_push(heap_toi, heap_data, counters, start + t, rid, kind, i, j, version[i],
                  version[j] if kind == KIND_PAIR else 0)


@njit(cache=True, inline="always")
def _predict_pair(i, j, x, v, a, radius, sigma, version, step_end, integrator, k, detection, samples, tolerance,
                  period, held, test_int, test_float, test_outcome, heap_toi, heap_data, counters, push):
    """Swept test of pair (i, j) (i < j) from the later of their anchors; record it, push a
    hit. A held pair is not tested."""
    if held.deg[i] > 0 and held.deg[j] > 0 and held_find(held, KIND_PAIR, i, j) >= 0:
        return
    start = max(sigma[i], sigma[j])
    pi1, pi2, dpi = path_coefficients(integrator, k, start - sigma[i])
    pj1, pj2, dpj = path_coefficients(integrator, k, start - sigma[j])
    wi = path_acceleration_weight(integrator, pi1)
    wj = path_acceleration_weight(integrator, pj1)
    # relative position (the minimum image on periodic axes) and path velocity at the
    # common start (see motion.path_state)
    dx0 = image((x[i, 0] + v[i, 0] * pi1 + a[i, 0] * pi2) - (x[j, 0] + v[j, 0] * pj1 + a[j, 0] * pj2), period[0])
    dx1 = image((x[i, 1] + v[i, 1] * pi1 + a[i, 1] * pi2) - (x[j, 1] + v[j, 1] * pj1 + a[j, 1] * pj2), period[1])
    dx2 = image((x[i, 2] + v[i, 2] * pi1 + a[i, 2] * pi2) - (x[j, 2] + v[j, 2] * pj1 + a[j, 2] * pj2), period[2])
    dv0 = (v[i, 0] * dpi + a[i, 0] * wi) - (v[j, 0] * dpj + a[j, 0] * wj)
    dv1 = (v[i, 1] * dpi + a[i, 1] * wi) - (v[j, 1] * dpj + a[j, 1] * wj)
    dv2 = (v[i, 2] * dpi + a[i, 2] * wi) - (v[j, 2] * dpj + a[j, 2] * wj)
    horizon = step_end - start
    if detection == SWEPT:
        t = pair_toi_swept_scalar(dx0, dx1, dx2, dv0, dv1, dv2, a[i, 0] - a[j, 0], a[i, 1] - a[j, 1],
                                  a[i, 2] - a[j, 2], radius[i] + radius[j], integrator, k, horizon, tolerance)
    else:
        t = pair_toi_sampled_scalar(dx0, dx1, dx2, dv0, dv1, dv2, a[i, 0] - a[j, 0], a[i, 1] - a[j, 1],
                                    a[i, 2] - a[j, 2], radius[i] + radius[j], integrator, k, horizon,
                                    1 if detection == DISCRETE else samples)
    _record(KIND_PAIR, i, j, start, t, step_end, version, test_int, test_float, test_outcome, heap_toi,
            heap_data, counters, push)


@njit(cache=True, inline="always")
def _predict_wall(i, w, x, v, a, radius, sigma, version, step_end, integrator, k, detection, samples, normals,
                  offsets, half_thickness, two_sided, held, test_int, test_float, test_outcome, heap_toi,
                  heap_data, counters, push):
    """Swept test of particle i against wall w from i's anchor; record it, push a hit.
    A held contact is not tested."""
    if held.deg[i] > 0 and held_find(held, KIND_WALL, i, w) >= 0:
        return
    g0, p, q, _ = wall_gap_terms(x, v, a, radius, i, normals[w], offsets[w], half_thickness[w], two_sided[w])
    start = sigma[i]
    horizon = step_end - start
    if detection == SWEPT:
        t = wall_toi_swept(g0, p, q, integrator, k, horizon)
    else:
        depth = 2.0 * (radius[i] + half_thickness[w]) if two_sided[w] else math.inf
        t = wall_toi_sampled(g0, p, q, integrator, k, horizon, 1 if detection == DISCRETE else samples, depth)
    _record(KIND_WALL, i, w, start, t, step_end, version, test_int, test_float, test_outcome, heap_toi, heap_data,
            counters, push)


@borrowing
def predict_into(kind, ia, ib, x, v, a, radius, sigma, version, step_end, integrator, k, detection, samples,
                 tolerance, normals, offsets, half_thickness, two_sided, period, held,
                 test_int, test_float, test_outcome, heap_toi, heap_data, counters, push):
    """Swept-test candidates (kind, ia[m], ib[m]); record each test; push hits if ``push``.

    held: the held contacts (resting.HeldContacts), which are not tested; period: (3,)
    m, the periodic axes (0 = not periodic).
    """
    for m in range(ia.shape[0]):
        if kind == KIND_PAIR:
            _predict_pair(ia[m], ib[m], x, v, a, radius, sigma, version, step_end, integrator, k, detection,
                          samples, tolerance, period, held, test_int, test_float, test_outcome, heap_toi,
                          heap_data, counters, push)
        else:
            _predict_wall(ia[m], ib[m], x, v, a, radius, sigma, version, step_end, integrator, k, detection,
                          samples, normals, offsets, half_thickness, two_sided, held, test_int, test_float,
                          test_outcome, heap_toi, heap_data, counters, push)


# ------------------------------------------------------------------------------ resolve
@borrowing
def _repredict(p, x, v, a, radius, sigma, version, step_end, integrator, k, detection, samples, tolerance,
               normals, offsets, half_thickness, two_sided, period, held, adj_start, adj, batch_mark, batch, test_int,
               test_float, test_outcome, heap_toi, heap_data, counters, box_lo, box_hi, box_margin, scratch):
    """Push new predictions of particle p against the partners and walls it can reach;
    returns whether p's new path stays inside its swept box (if not, the caller queries the
    broad phase again for it). scratch: (2, 3), left holding the new path's box.

    A pair whose both spheres changed in this batch is predicted once, from the larger index.
    A partner q that did not change in this batch is predicted only where the new path's box
    meets q's swept box, which holds q's path (the step's boxes hold every path, and a path
    that leaves its box has the box grown, World._refresh_box). A wall is predicted where
    p's swept box reaches it (the step-start rule, reachable_walls), or, where p's new path
    has left that box, every wall. A path whose box misses another box cannot touch what
    that box holds, so what is skipped is a miss. (Everything used to be
    tested: in box-rain 10k's last steps 3–4.6 million tests a step, 95 % of them misses;
    this leaves 55 % of them, with the same contacts.)
    """
    inside = _inside_box(x, v, a, radius, sigma, p, step_end, integrator, k, box_margin, box_lo, box_hi, scratch)
    for s in range(adj_start[p], adj_start[p + 1]):
        q = adj[s]
        if batch_mark[q] == batch:
            if q < p:
                continue
        elif box_misses(scratch, box_lo, box_hi, q, period):
            continue
        _predict_pair(min(p, q), max(p, q), x, v, a, radius, sigma, version, step_end, integrator, k, detection,
                      samples, tolerance, period, held, test_int, test_float, test_outcome, heap_toi,
                      heap_data, counters, True)
    for w in range(normals.shape[0]):
        if inside and not box_reaches_wall(box_lo, box_hi, p, normals, offsets, half_thickness, two_sided, w):
            continue
        _predict_wall(p, w, x, v, a, radius, sigma, version, step_end, integrator, k, detection, samples, normals,
                      offsets, half_thickness, two_sided, held, test_int, test_float, test_outcome, heap_toi,
                      heap_data, counters, True)
    return inside


@borrowing
def mark_capped(heap_data, test_outcome, counters):
    """Every prediction still queued is left unresolved by a budget: mark it, empty the heap."""
    for s in range(counters[HEAP_SIZE]):
        test_outcome[heap_data[s, 0]] = OUTCOME_CAPPED
    counters[HEAP_SIZE] = 0
    counters[PENDING_COUNT] = 0
    counters[PENDING_AT] = 0


@borrowing
def _inside_box(x, v, a, radius, sigma, p, step_end, integrator, k, margin, box_lo, box_hi, scratch):
    particle_box(x, v, a, radius, sigma, p, step_end, integrator, k, margin, scratch[0], scratch[1])
    for c in range(3):
        if scratch[0, c] < box_lo[p, c] or scratch[1, c] > box_hi[p, c]:
            return False
    return True


@kernel
def run_time_order(particles, method, walls, held, candidates, budgets, buffers):
    """Resolve contacts in time order until done or a pause (see module doc); the groups
    are kernel_args' (as plain tuples), held the store (resting.HeldContacts)."""
    # positional, in kernel_args' field order (the groups come as plain tuples, see there);
    # distinct names for what the loop does not read itself: numba types each name once
    x, v, a, _acc, radius, _inverse_mass, _restitution, sigma, version, _last_contact = particles
    (_run_time, step_end, integrator, _drag, k, detection, samples, tolerance, _rest_fraction, _rest_step_factor,
     _rule, _rapid_time, _anchor_is_flow, _path_follows_acc, _vtol, _atol) = method
    normals, offsets, half_thickness, two_sided, _wall_restitution, period = walls
    adj_start, adj, box_lo, box_hi, box_margin, max_degree = candidates
    cap, max_tests, work_budget = budgets
    (heap_toi, heap_data, test_int, test_float, test_outcome, contacts, counters, pending, changed, batch_mark,
     requery, requery_count) = buffers
    nw = normals.shape[0]
    room = 2 * max_degree + 2 * nw + 4
    scratch = np.empty((2, 3))  # the lo, hi rows of _inside_box
    while True:
        # re-predict the spheres the last contact changed, pausing if a buffer fills up
        if counters[PENDING_COUNT] > 0:
            while counters[PENDING_AT] < counters[PENDING_COUNT]:
                if heap_toi.shape[0] - counters[HEAP_SIZE] < room or test_outcome.shape[0] - counters[ROWS] < room:
                    return GROW
                p = pending[counters[PENDING_AT]]
                counters[PENDING_AT] += 1
                if not _repredict(p, x, v, a, radius, sigma, version, step_end, integrator, k, detection, samples,
                                  tolerance, normals, offsets, half_thickness, two_sided, period, held, adj_start,
                                  adj, batch_mark, counters[BATCH], test_int, test_float, test_outcome, heap_toi,
                                  heap_data, counters, box_lo, box_hi, box_margin, scratch):
                    # a path that left its swept box may meet particles it was never paired with
                    requery[requery_count[0]] = p
                    requery_count[0] += 1
            counters[PENDING_COUNT] = 0
            counters[PENDING_AT] = 0
            if requery_count[0]:
                return REQUERY
        if counters[HEAP_SIZE] == 0:
            return DONE
        if (heap_toi.shape[0] - counters[HEAP_SIZE] < room or test_outcome.shape[0] - counters[ROWS] < room
                or contacts.shape[0] - counters[CONTACTS] < 2):
            return GROW
        if not held_room(held, heap_data[0, 2], heap_data[0, 3] if heap_data[0, 1] == KIND_PAIR else -1):
            return GROW_HELD
        if counters[TESTS] >= max_tests:
            mark_capped(heap_data, test_outcome, counters)
            return TEST_BUDGET
        slot = heap_pop(heap_toi, heap_data, counters)
        counters[EVENTS] += 1
        toi = heap_toi[slot]
        rid = heap_data[slot, 0]
        kind = heap_data[slot, 1]
        ia = heap_data[slot, 2]
        other = heap_data[slot, 3]
        if version[ia] != heap_data[slot, 4] or (kind == KIND_PAIR and version[other] != heap_data[slot, 5]):
            test_outcome[rid] = OUTCOME_SUPERSEDED
            continue
        if counters[CONTACTS] >= cap:
            test_outcome[rid] = OUTCOME_CAPPED
            mark_capped(heap_data, test_outcome, counters)
            return CAPPED
        status = resolve_contact(kind, ia, other, toi, particles, method, walls, held, contacts, counters, CONTACTS,
                                 RAPID, changed, work_budget)
        test_outcome[rid] = OUTCOME_SUPERSEDED if status == SKIPPED else OUTCOME_HIT
        # re-predict only the particles whose paths changed (next time round the loop)
        counters[BATCH] += 1
        for s in range(changed[0]):
            p = changed[1 + s]
            version[p] += 1
            batch_mark[p] = counters[BATCH]
            pending[s] = p
        counters[PENDING_COUNT] = changed[0]
        counters[PENDING_AT] = 0
        requery_count[0] = 0
        if status == OUT_OF_WORK:
            mark_capped(heap_data, test_outcome, counters)
            return RESTING_BUDGET


# ------------------------------------------------------------------------------ step helpers
@kernel
def adjacency_from_pairs(pairs, n):
    """CSR partner lists (start (N+1,), partners (2M,)) from sorted pairs i < j.

    Rows come out sorted because the pairs are: row i first receives the (x, i) with
    x < i in order of x, then the (i, y) in order of y.
    """
    start = np.zeros(n + 1, dtype=np.int64)
    for m in range(pairs.shape[0]):
        start[pairs[m, 0] + 1] += 1
        start[pairs[m, 1] + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    partners = np.empty(2 * pairs.shape[0], dtype=np.int64)
    for m in range(pairs.shape[0]):
        i = pairs[m, 0]
        j = pairs[m, 1]
        partners[fill[i]] = j
        fill[i] += 1
        partners[fill[j]] = i
        fill[j] += 1
    return start, partners


@kernel
def reachable_walls(lo, hi, normals, offsets, half_thickness, two_sided):
    """Particle–wall candidates (particles (K,), walls (K,)) whose swept box reaches the wall.

    lo, hi already include the radius, so a box entirely beyond the plane (or slab) cannot
    touch it on its current path.
    """
    n = lo.shape[0]
    nw = normals.shape[0]
    ip = np.empty(n * nw, dtype=np.int64)
    iw = np.empty(n * nw, dtype=np.int64)
    m = 0
    for i in range(n):
        for w in range(nw):
            if box_reaches_wall(lo, hi, i, normals, offsets, half_thickness, two_sided, w):
                ip[m] = i
                iw[m] = w
                m += 1
    return ip[:m], iw[:m]


@borrowing
def box_reaches_wall(lo, hi, i, normals, offsets, half_thickness, two_sided, w) -> bool:
    """Whether particle i's box lo[i], hi[i] (m, radius included) reaches wall w: it is not
    entirely beyond the plane (or, for a two-sided wall, the slab)."""
    low = 0.0
    high = 0.0
    for c in range(3):
        a = normals[w, c] * lo[i, c]
        b = normals[w, c] * hi[i, c]
        low += min(a, b)
        high += max(a, b)
    low -= offsets[w]
    high -= offsets[w]
    h = half_thickness[w]
    return (two_sided[w] and low <= h and high >= -h) or (not two_sided[w] and low <= h)


@borrowing
def max_overlap(x, radius, pairs, normals, offsets, half_thickness, two_sided, period, ignore_tunnelled):
    """Deepest penetration (m, >= 0) among the candidate pairs and every particle–wall pair
    (pairs through the minimum image on the periodic axes of period (3,), 0 = not periodic).

    ignore_tunnelled: a sphere past the middle of a thin wall went through it (discrete or
    sampled detection) and is not counted as overlapping it.
    """
    worst = 0.0
    for m in range(pairs.shape[0]):
        i = pairs[m, 0]
        j = pairs[m, 1]
        d = pair_separation(x, i, j, period)[3]
        worst = max(worst, radius[i] + radius[j] - d)
    for i in range(x.shape[0]):
        for w in range(normals.shape[0]):
            h = normals[w, 0] * x[i, 0] + normals[w, 1] * x[i, 1] + normals[w, 2] * x[i, 2] - offsets[w]
            if two_sided[w]:
                h = abs(h)
            pen = half_thickness[w] + radius[i] - h
            if ignore_tunnelled and two_sided[w] and pen > radius[i]:
                pen = 0.0
            worst = max(worst, pen)
    return worst
