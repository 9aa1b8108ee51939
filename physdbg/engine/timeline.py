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
and held contacts, resting/), called in its two stages (judge_contact in the loop,
finish_with_held outside it: run_time_order says why). The spheres it changed are
re-predicted one by one from a pending list, so the loop can pause between any two of
them. It *pauses* and returns
to Python for:

* REQUERY: a new path left the swept box its broad-phase pairs were found for, and may
  meet a sphere it was never paired with (the loop answers a re-query that finds
  nothing new itself, where the broad phase's query is a scan: grow_unpartnered);
* GROW: a buffer, or the held-contact store, is nearly full.

It stops for good with CAPPED (the contact budget, max_contacts_per_step), TEST_BUDGET
(max_swept_tests_per_step) or RESTING_BUDGET (max_resting_work_per_step): the step's
remaining predictions are marked capped; and with STOPPED at once, leaving the step
half done, when the world's stop switch is set (World.request_stop: Ctrl-C).

Python handles it and calls ``run_time_order`` again, which carries on where it stopped.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..events import CONTACT_ROW, OUTCOME_CAPPED, OUTCOME_HIT, OUTCOME_MISS, OUTCOME_SUPERSEDED
from .broadphase.boxes import box_meets
from .colliders import KINDS, most_partners, partner_sphere, partners_bound, partners_of, searches_meshes, time_of_impact
from .jit import borrowing, kernel, records
from .kernel_args import B_BATCH_MARK, B_COUNTERS, B_MESH_QUERIES, B_TEST_INT, C_SCAN_PARTNERS, M_DETECTION, M_STEP_END, LoopBuffers, boxes, partner_lists, paths, sweep, test_log
from .motion import particle_box
from .resolve import (AT_ONE_INSTANT, AT_ONE_INSTANT_CANDIDATES, NEEDS_HELD, OUT_OF_WORK, SAME_INSTANT, SKIPPED,
                      finish_with_held, judge_contact, resolve_at_one_instant)
from .resting import held_find, held_room
from .resting.store import STOP
from .toi import SWEPT

# statuses
DONE = 0
REQUERY = 2
GROW = 3
CAPPED = 4
TEST_BUDGET = 5
GROW_HELD = 6
RESTING_BUDGET = 7
STOPPED = 8

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
MESH_QUERIES = 10  # rows of the mesh-query log written this step ...
LOG_QUERIES = 11  # ... 1: log the boxes asked of the meshes' trees (the step's search is observed)
COUNTERS = 12


class Buffers:
    """Growable arrays the compiled loop writes into; one set per World."""

    def __init__(self, n: int, heap: int = 1024, tests: int = 4096, contacts: int = 256):
        self.heap_toi = np.empty(heap)
        # the queue: each prediction's time, and its test-log row (kind, a, other are the
        # row's) and the batch it was made in (stale once a later batch changed a or other)
        self.heap_data = np.empty((heap, 2), dtype=np.int64)  # rid, batch
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
        # the boxes the loop asked the meshes' trees with (an observed step of a scene with
        # meshes): sphere, the contact it came after (its row), the box lo, hi (m)
        self.mesh_queries = np.empty((64, MESH_QUERY_COLUMNS))

    def loop(self) -> tuple:
        """The arrays as run_time_order takes them (kernel_args.LoopBuffers, as a plain
        tuple; again after any growth)."""
        return tuple(LoopBuffers(self.heap_toi, self.heap_data, self.test_int, self.test_float, self.test_outcome,
                                 records(self.contacts), self.counters, self.pending, self.changed, self.batch_mark,
                                 self.requery, self.requery_count, self.mesh_queries))

    def renumber(self, old_of_new: np.ndarray) -> None:
        """The spheres renumbered between steps (space_order.py): sphere i is now the one
        that was old_of_new[i]. Only batch_mark outlives a step (the other per-sphere
        arrays are a step's scratch)."""
        n = old_of_new.shape[0]
        self.batch_mark[:n] = self.batch_mark[old_of_new]

    def reset(self, keep_misses: bool = True, log_queries: bool = False) -> None:
        """Start a step. keep_misses: log every swept test; False logs only the tests that
        hit within the step (what the loop acts on): an unobserved step of a dense scene
        runs tens of millions of tests, 95 % of them misses, at 41 bytes a row.
        log_queries: log the box of each re-predicted path asked of the meshes' trees
        (mesh_queries), for the step's recorded search."""
        batch = self.counters[BATCH]  # batch ids stay unique across steps (batch_mark keeps old ones)
        self.counters[:] = 0
        self.counters[BATCH] = batch
        self.counters[KEEP_MISSES] = 1 if keep_misses else 0
        self.counters[LOG_QUERIES] = 1 if log_queries else 0
        self.requery_count[0] = 0

    def ensure(self, heap_room: int, test_room: int, contact_room: int) -> None:
        """Make sure at least this much more fits in each buffer (doubling as needed)."""
        c = self.counters
        rows = _rows_after(self.heap_toi.shape[0], int(c[HEAP_SIZE]), heap_room)
        self.heap_toi = _grown(self.heap_toi, rows)
        self.heap_data = _grown(self.heap_data, rows)
        rows = _rows_after(self.test_outcome.shape[0], int(c[ROWS]), test_room)
        self.test_int = _grown(self.test_int, rows)
        self.test_float = _grown(self.test_float, rows)
        self.test_outcome = _grown(self.test_outcome, rows)
        self.contacts = _grown(self.contacts, _rows_after(self.contacts.shape[0], int(c[CONTACTS]), contact_room))
        if c[LOG_QUERIES]:  # one row a re-prediction: as much room as the test log keeps
            self.mesh_queries = _grown(self.mesh_queries,
                                       _rows_after(self.mesh_queries.shape[0], int(c[MESH_QUERIES]), test_room))

    def bytes_after(self, heap_room: int, test_room: int, contact_room: int) -> tuple[int, int, int]:
        """(all the buffers, the test log alone, the contact rows alone) in bytes once
        ``ensure`` with these rooms has run: what growing would cost, before anything is
        allocated (the world holds it to Settings.max_memory)."""
        c = self.counters
        heap = _rows_after(self.heap_toi.shape[0], int(c[HEAP_SIZE]), heap_room) * HEAP_ROW_BYTES
        log = _rows_after(self.test_outcome.shape[0], int(c[ROWS]), test_room) * TEST_ROW_BYTES
        rows = _rows_after(self.contacts.shape[0], int(c[CONTACTS]), contact_room) * self.contacts.dtype.itemsize
        fixed = sum(a.nbytes for a in (self.counters, self.pending, self.changed, self.batch_mark, self.requery,
                                        self.mesh_queries))
        return heap + log + rows + fixed, log, rows


HEAP_ROW_BYTES = 8 + 2 * 8  # heap_toi, heap_data
MESH_QUERY_COLUMNS = 8  # sphere, after contact, lo (3), hi (3)
TEST_ROW_BYTES = 3 * 8 + 2 * 8 + 1  # test_int, test_float, test_outcome


def _rows_after(rows: int, used: int, room: int) -> int:
    """A buffer's rows once it holds ``room`` more than the ``used`` of its ``rows``: doubled
    as often as needed (Buffers.ensure grows to it, Buffers.bytes_after prices it)."""
    while rows - used < room:
        rows *= 2
    return rows


def _grown(array: np.ndarray, rows: int) -> np.ndarray:
    """array itself if it has ``rows`` rows, else a copy with that many (the new ones empty)."""
    if rows == array.shape[0]:
        return array
    bigger = np.empty((rows,) + array.shape[1:], dtype=array.dtype)
    bigger[: array.shape[0]] = array
    return bigger


# ------------------------------------------------------------------------------ heap
@njit(cache=True, inline="always")
def _precedes(t, rid, other_t, other_rid):
    """Does the prediction at time t (s) from test-log row rid come before the one at
    other_t from other_rid? The queue's one order: by time, ties by row (the tests' order)."""
    return t < other_t or (t == other_t and rid < other_rid)


@njit(cache=True, inline="always")
def heap_push(toi, data, counters, t, rid, batch):
    """Queue the prediction of test-log row ``rid`` at time t (s), made in ``batch``: the
    new entry rises through a hole (each parent on its way moves down once) to where it
    belongs by time, then row."""
    n = counters[HEAP_SIZE]
    counters[HEAP_SIZE] = n + 1
    while n > 0:
        up = (n - 1) // 2
        if _precedes(t, rid, toi[up], data[up, 0]):
            toi[n] = toi[up]
            data[n, 0] = data[up, 0]
            data[n, 1] = data[up, 1]
            n = up
        else:
            break
    toi[n] = t
    data[n, 0] = rid
    data[n, 1] = batch


@borrowing
def heap_pop(toi, data, counters):
    """Move the smallest entry to the slot just past the heap and return that slot. The
    last entry sinks from the root through a hole (each smaller child moves up once),
    which leaves the same heap as swapping it down, with half the moves."""
    n = counters[HEAP_SIZE] - 1
    counters[HEAP_SIZE] = n
    last_t = toi[n]
    last_rid = data[n, 0]
    last_batch = data[n, 1]
    toi[n] = toi[0]
    data[n, 0] = data[0, 0]
    data[n, 1] = data[0, 1]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= n:
            break
        if child + 1 < n and _precedes(toi[child + 1], data[child + 1, 0], toi[child], data[child, 0]):
            child += 1
        if _precedes(toi[child], data[child, 0], last_t, last_rid):
            toi[i] = toi[child]
            data[i, 0] = data[child, 0]
            data[i, 1] = data[child, 1]
            i = child
        else:
            break
    if n > 0:
        toi[i] = last_t
        data[i, 0] = last_rid
        data[i, 1] = last_batch
    return n


# ------------------------------------------------------------------------------ predict
@njit(cache=True, inline="always")
def _record(kind, i, j, start, t, work, step_end, buffers, push):
    """Count a swept test (``work`` against the budget: colliders.time_of_impact), log it
    (every test, or only a hit: counters[KEEP_MISSES]) and push a hit onto the heap if
    ``push``. Rows keep the order of the tests, so the heap's tie-break by row is the same
    either way."""
    test_int, test_float, test_outcome, heap_toi, heap_data, counters = test_log(buffers)
    counters[TESTS] += work
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
        heap_push(heap_toi, heap_data, counters, start + t, rid, counters[BATCH])


@njit(cache=True, inline="always")
def _predict(kind, ia, other, particles, method, geometry, held, buffers, push):
    """Swept test of (kind, ia, other) (pairs: ia < other) from the anchors; record it,
    push a hit. A held contact is not tested."""
    b = partner_sphere(kind, other)
    if held.deg[ia] > 0 and (b < 0 or held.deg[b] > 0) and held_find(held, kind, ia, other) >= 0:
        return
    x, v, a, radius, sigma = paths(particles)
    step_end, integrator, k, detection, samples, tolerance = sweep(method)
    start, t, work = time_of_impact(kind, ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection,
                                    samples, tolerance, geometry)
    _record(kind, ia, other, start, t, work, step_end, buffers, push)


@borrowing
def predict_into(kind, ia, ib, particles, method, geometry, held, buffers, push):
    """Swept-test candidates (kind, ia[m], ib[m]); record each test; push hits if ``push``.

    particles, method, buffers: kernel_args' groups (as plain tuples); geometry:
    colliders.geometry_of; held: the held contacts (resting.HeldContacts), which are not
    tested.
    """
    for m in range(ia.shape[0]):
        _predict(kind, ia[m], ib[m], particles, method, geometry, held, buffers, push)


# ------------------------------------------------------------------------------ resolve
@borrowing
def _repredict(p, particles, method, geometry, held, candidates, buffers, scratch, found):
    """Push new predictions of particle p against the partners of every kind it can reach
    (colliders.partners_of: what p's new path can meet, judged by boxes); returns whether
    p's new path stays inside its swept box (if not, the caller queries the broad phase
    again for it). scratch: (2, 3), left holding the new path's box, which also becomes
    p's row of path_lo, path_hi (N, 3); found: (K, 2) room for the candidates of one kind.

    A partner is judged by the box of its *current* path (path_lo, path_hi), not by its
    swept box grown to its reach: if its path changes later it is re-predicted then,
    against p's path as it is. (The grown boxes are for finding partners at all; judged by
    them, box-rain 10k tested ~1.6 times as many pairs that could not meet.)
    """
    x, v, a, radius, sigma = paths(particles)
    step_end, integrator, k, _detection, _samples, _tolerance = sweep(method)
    box_lo, box_hi, box_margin, path_lo, path_hi = boxes(candidates)
    adj_start, adj = partner_lists(candidates)
    batch_mark = buffers[B_BATCH_MARK]
    batch = buffers[B_COUNTERS][BATCH]
    inside = _inside_box(x, v, a, radius, sigma, p, step_end, integrator, k, box_margin, box_lo, box_hi, scratch)
    for c in range(3):
        path_lo[p, c] = scratch[0, c]
        path_hi[p, c] = scratch[1, c]
    counters = buffers[B_COUNTERS]
    if counters[LOG_QUERIES] and searches_meshes(geometry):  # an observed step: the query, for the search's record
        queries = buffers[B_MESH_QUERIES]
        row = counters[MESH_QUERIES]
        queries[row, 0] = p
        queries[row, 1] = counters[CONTACTS] - 1
        for c in range(3):
            queries[row, 2 + c] = scratch[0, c]
            queries[row, 5 + c] = scratch[1, c]
        counters[MESH_QUERIES] += 1
    scan = candidates[C_SCAN_PARTNERS]
    for kind in range(KINDS):
        m = partners_of(kind, p, scratch, adj_start, adj, path_lo, path_hi, batch_mark, batch, geometry, found, scan)
        for s in range(m):
            _predict(kind, found[s, 0], found[s, 1], particles, method, geometry, held, buffers, True)
    return inside or scan  # a scan found every sphere the new path meets: nothing to re-query


@njit(cache=True, inline="always")
def prediction_room(geometry, max_degree):
    """Room (heap slots, log rows) the loop keeps free before re-predicting a sphere: two
    predictions for each candidate a sphere can have (colliders.partners_bound), and 4."""
    return 2 * partners_bound(geometry, max_degree) + 4


@njit(cache=True, inline="always")
def _least(a, b):
    """np.minimum of two floats: NaN if either is, b where they are equal."""
    return a if (a < b or a != a) else b


@njit(cache=True, inline="always")
def _greatest(a, b):
    """np.maximum of two floats: NaN if either is, b where they are equal."""
    return a if (a > b or a != a) else b


@borrowing
def grow_unpartnered(p, path_box, box_lo, box_hi, adj_start, adj):
    """The world's re-query (World._refresh_box) of sphere p, whose new path's box
    path_box (2, 3) left its swept box, when it would find nothing: if no sphere outside
    p's partners (adj_start, adj: CSR, rows sorted) has a swept box (box_lo, box_hi
    (N, 3)) meeting p's grown to hold the path (touching counts, a NaN bound meets
    nothing), grow p's box so, bit for bit as the world would, and return True; else
    change nothing and return False (the world re-queries). A scan of every box with
    their query's test (boxes.box_meets, as boxes.overlapping)."""
    lo0 = _least(box_lo[p, 0], path_box[0, 0])
    lo1 = _least(box_lo[p, 1], path_box[0, 1])
    lo2 = _least(box_lo[p, 2], path_box[0, 2])
    hi0 = _greatest(box_hi[p, 0], path_box[1, 0])
    hi1 = _greatest(box_hi[p, 1], path_box[1, 1])
    hi2 = _greatest(box_hi[p, 2], path_box[1, 2])
    known = adj_start[p]
    last = adj_start[p + 1]
    for j in range(box_lo.shape[0]):
        if box_meets(lo0, lo1, lo2, hi0, hi1, hi2, box_lo, box_hi, j) and j != p:
            while known < last and adj[known] < j:  # j rises, and so does p's sorted row
                known += 1
            if known == last or adj[known] != j:
                return False
    box_lo[p, 0] = lo0
    box_lo[p, 1] = lo1
    box_lo[p, 2] = lo2
    box_hi[p, 0] = hi0
    box_hi[p, 1] = hi1
    box_hi[p, 2] = hi2
    return True


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


_HELD_SOLVE = -1  # _run_events: the contact in ``judged`` is to be solved with held contacts
_AT_ONE_INSTANT = -2  # ... the contacts in ``judged`` (from judged[5]) are at one instant
# (the loop keeps room in the contact rows for a whole instant's rows)
CONTACT_ROOM = AT_ONE_INSTANT + 1


@kernel
def run_time_order(particles, method, geometry, held, candidates, budgets, buffers):
    """Resolve contacts in time order until done or a pause (see module doc); the groups
    are kernel_args' (as plain tuples), geometry colliders.geometry_of, held the store
    (resting.HeldContacts).

    The event loop itself is :func:`_run_events`, compiled without reference counting
    (jit.py): a compiled function that counts references increfs every array it hands to
    a call and decrefs it after, and this loop calls the re-prediction for every changed
    sphere with ~45 arrays (13 % of box-rain 10k's time went to those atomic updates).
    It stops for what must allocate: a contact to be solved with held contacts
    (resolve.finish_with_held), solved here before it carries on.
    """
    max_degree = candidates[5]
    work_budget = budgets[2]
    (_heap_toi, heap_data, _test_int, _test_float, test_outcome, contacts, counters, pending, changed, batch_mark,
     _requery, requery_count, _mesh_queries) = buffers
    scratch = np.empty((2, 3))  # the lo, hi rows of _inside_box
    found = np.empty((most_partners(geometry, max_degree) + 1, 2), dtype=np.int64)  # one kind's (_repredict)
    # a contact _run_events left for the held solve: rid, kind, a, other, how; or the
    # contacts it found at one instant: how many, then their rows (from judged[5])
    judged = np.empty(5 + AT_ONE_INSTANT_CANDIDATES, dtype=np.int64)
    judged_f = np.empty(4)  # ... its time, closing speed, restitution used, rapid (1.0) or not
    stack = np.empty(2 * 64 + 2, dtype=np.int64)  # the heap's walk (_at_one_instant): two a level
    test_int = buffers[B_TEST_INT]
    while True:
        status = _run_events(particles, method, geometry, held, candidates, budgets, buffers, scratch, found, judged,
                             judged_f, stack)
        if status == _AT_ONE_INSTANT:
            n = judged[4]
            rows = judged[5:5 + n].copy()
            resolved = np.zeros(n, dtype=np.int64)
            solved = resolve_at_one_instant(test_int[rows, 0], test_int[rows, 2], n, judged[2], judged_f[0], particles,
                                            method, geometry, held, contacts, counters, CONTACTS, RAPID, changed,
                                            work_budget, resolved)
            _after_contact(solved, rows[0], batch_mark, pending, changed, test_outcome, counters, requery_count)
            if not resolved[0]:  # it did not approach: the others were resolved without it
                test_outcome[rows[0]] = OUTCOME_SUPERSEDED
            for s in range(1, n):  # the others resolved with it; one left is superseded once popped
                if resolved[s]:
                    test_outcome[rows[s]] = OUTCOME_HIT
        elif status == _HELD_SOLVE:
            rid, kind, ia, other, how = judged[0], judged[1], judged[2], judged[3], judged[4]
            solved = finish_with_held(kind, ia, other, judged_f[0], particles, method, geometry, held, contacts,
                                      counters, CONTACTS, RAPID, changed, work_budget, judged_f[1], judged_f[2], how,
                                      judged_f[3] != 0.0)
            _after_contact(solved, rid, batch_mark, pending, changed, test_outcome, counters, requery_count)
        else:
            return status
        if solved == OUT_OF_WORK:
            mark_capped(heap_data, test_outcome, counters)
            return RESTING_BUDGET


@borrowing
def _after_contact(status, rid, batch_mark, pending, changed, test_outcome, counters, requery_count):
    """A resolved (or skipped) contact's bookkeeping: its test's outcome, and the spheres
    whose paths changed (``changed``) queued for re-prediction in a new batch."""
    test_outcome[rid] = OUTCOME_SUPERSEDED if status == SKIPPED else OUTCOME_HIT
    counters[BATCH] += 1
    for s in range(changed[0]):
        p = changed[1 + s]
        batch_mark[p] = counters[BATCH]
        pending[s] = p
    counters[PENDING_COUNT] = changed[0]
    counters[PENDING_AT] = 0
    requery_count[0] = 0


@borrowing
def _run_events(particles, method, geometry, held, candidates, budgets, buffers, scratch, found, judged, judged_f,
                stack):
    """run_time_order's loop: re-predict, pop, resolve (resolve.judge_contact), until
    done, a pause, a contact that must be solved with held contacts (_HELD_SOLVE, the
    contact in judged, judged_f: see run_time_order), or contacts of one sphere with
    immovable partners at one instant (_AT_ONE_INSTANT, resolved together by
    resolve.resolve_at_one_instant). stack: scratch for the heap's walk."""
    # positional, in kernel_args' field order (the groups come as plain tuples, see there);
    # distinct names for what the loop does not read itself: numba types each name once
    adj_start, adj, box_lo, box_hi, _box_margin, max_degree, _path_lo, _path_hi, scan_boxes, _scan = candidates
    cap, max_tests, _work_budget = budgets
    (heap_toi, heap_data, test_int, _test_float, test_outcome, contacts, counters, pending, changed, batch_mark,
     requery, requery_count, mesh_queries) = buffers
    room = prediction_room(geometry, max_degree)
    while True:
        # re-predict the spheres the last contact changed, pausing if a buffer fills up
        if counters[PENDING_COUNT] > 0:
            while counters[PENDING_AT] < counters[PENDING_COUNT]:
                if (heap_toi.shape[0] - counters[HEAP_SIZE] < room or test_outcome.shape[0] - counters[ROWS] < room
                        or mesh_queries.shape[0] - counters[MESH_QUERIES] < 1):
                    return GROW
                p = pending[counters[PENDING_AT]]
                counters[PENDING_AT] += 1
                if not _repredict(p, particles, method, geometry, held, candidates, buffers, scratch, found):
                    # a path that left its swept box may meet particles it was never paired
                    # with: the world re-queries for it, unless the loop's own scan shows
                    # it meets none (nearly always: box-rain 10k paused 2.5 times a step
                    # for 0.07 new pairs, ~0.25 ms a pause)
                    if not (scan_boxes and grow_unpartnered(p, scratch, box_lo, box_hi, adj_start, adj)):
                        requery[requery_count[0]] = p
                        requery_count[0] += 1
            counters[PENDING_COUNT] = 0
            counters[PENDING_AT] = 0
            if requery_count[0]:
                return REQUERY
        if counters[HEAP_SIZE] == 0:
            return DONE
        if (heap_toi.shape[0] - counters[HEAP_SIZE] < room or test_outcome.shape[0] - counters[ROWS] < room
                or contacts.shape[0] - counters[CONTACTS] < CONTACT_ROOM):
            return GROW
        top = heap_data[0, 0]
        if not held_room(held, test_int[top, 1], partner_sphere(test_int[top, 0], test_int[top, 2])):
            return GROW_HELD
        if counters[TESTS] >= max_tests:
            mark_capped(heap_data, test_outcome, counters)
            return TEST_BUDGET
        if held.count[STOP] != 0:
            return STOPPED
        slot = heap_pop(heap_toi, heap_data, counters)
        counters[EVENTS] += 1
        toi = heap_toi[slot]
        rid = heap_data[slot, 0]
        batch = heap_data[slot, 1]
        kind = test_int[rid, 0]
        ia = test_int[rid, 1]
        other = test_int[rid, 2]
        ib = partner_sphere(kind, other)
        # stale: a batch after the one that made the prediction changed a sphere of it
        if batch_mark[ia] > batch or (ib >= 0 and batch_mark[ib] > batch):
            if test_outcome[rid] != OUTCOME_HIT:  # (not one resolved with others at one instant)
                test_outcome[rid] = OUTCOME_SUPERSEDED
            continue
        if counters[CONTACTS] >= cap:
            test_outcome[rid] = OUTCOME_CAPPED
            mark_capped(heap_data, test_outcome, counters)
            return CAPPED
        # contacts with immovable partners at one instant are resolved together (run_time_order);
        # only a swept test's times are instants (sampled and discrete ones are the samples')
        if ib < 0 and method[M_DETECTION] == SWEPT:
            n = _at_one_instant(heap_toi, heap_data, test_int, batch_mark, counters, ia, toi,
                                toi + SAME_INSTANT * method[M_STEP_END], rid, judged, stack)
            if n > 1:
                judged[2] = ia
                judged[4] = n
                judged_f[0] = toi
                return _AT_ONE_INSTANT
        # resolve.resolve_contact's first stage; the second, which allocates, is run_time_order's
        status, closing, used, how, is_rapid = judge_contact(kind, ia, other, toi, particles, method, geometry, held,
                                                             contacts, counters, CONTACTS, RAPID, changed)
        if status == NEEDS_HELD:
            judged[0] = rid
            judged[1] = kind
            judged[2] = ia
            judged[3] = other
            judged[4] = how
            judged_f[0] = toi
            judged_f[1] = closing
            judged_f[2] = used
            judged_f[3] = 1.0 if is_rapid else 0.0
            return _HELD_SOLVE
        # re-predict only the particles whose paths changed (next time round the loop)
        _after_contact(status, rid, batch_mark, pending, changed, test_outcome, counters, requery_count)


@borrowing
def _at_one_instant(heap_toi, heap_data, test_int, batch_mark, counters, ia, toi, until, rid, judged, stack):
    """The popped contact (test-log row rid, of sphere ia with an immovable partner, at
    toi) and the queued ones of ia with immovable partners up to ``until`` (s), still
    current and each (kind, partner) once: their rows into judged[5:], the popped one
    first, at most AT_ONE_INSTANT_CANDIDATES; returns how many. A walk of the heap that
    enters only entries at or before ``until`` (a heap's children are never earlier than
    their parent), so it costs the entries at that instant: one comparison at the root's
    children nearly always."""
    judged[5] = rid
    n = 1
    top = 0
    if counters[HEAP_SIZE] > 0:
        stack[0] = 0
        top = 1
    while top > 0:
        top -= 1
        e = stack[top]
        if heap_toi[e] > until:
            continue
        r = heap_data[e, 0]
        kind = test_int[r, 0]
        other = test_int[r, 2]
        if (test_int[r, 1] == ia and partner_sphere(kind, other) < 0 and batch_mark[ia] <= heap_data[e, 1]
                and n < AT_ONE_INSTANT_CANDIDATES):
            known = False
            for s in range(n):
                if test_int[judged[5 + s], 0] == kind and test_int[judged[5 + s], 2] == other:
                    known = True
            if not known:
                judged[5 + n] = r
                n += 1
        for child in (2 * e + 1, 2 * e + 2):
            if child < counters[HEAP_SIZE] and top < stack.shape[0]:
                stack[top] = child
                top += 1
    return n


# ------------------------------------------------------------------------------ step helpers
@kernel
def merge_sorted_pairs(pairs, extra):
    """The pairs (M, 2) and extra (E, 2), each sorted (lexicographically) and no pair in
    both, as one sorted (M + E, 2) array: a merge, O(M + E) (a mid-step re-query adds a
    few pairs to the step's whole list; sorting it again cost ~6 ms at 10 000 spheres)."""
    m = pairs.shape[0]
    e = extra.shape[0]
    out = np.empty((m + e, 2), dtype=np.int64)
    s = 0
    t = 0
    for row in range(m + e):
        take_extra = t < e and (s == m or extra[t, 0] < pairs[s, 0]
                                or (extra[t, 0] == pairs[s, 0] and extra[t, 1] < pairs[s, 1]))
        if take_extra:
            out[row, 0] = extra[t, 0]
            out[row, 1] = extra[t, 1]
            t += 1
        else:
            out[row, 0] = pairs[s, 0]
            out[row, 1] = pairs[s, 1]
            s += 1
    return out


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
