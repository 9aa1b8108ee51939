"""The event calendar: contacts predicted once and kept across steps (``event_loop = "calendar"``).

The time-ordered loop (timeline.py) works a step at a time: at each step's start it boxes
every path, pairs the boxes and predicts every pair again, though a sphere in free flight
keeps its path from one step to the next. This loop is the design of the fastest
event-driven hard-sphere codes (Smallenburg's EDMD, Eur. Phys. J. E 45, 22 (2022)), for a
world whose paths change only at contacts:

* each sphere's **anchor** (x, v at time sigma, s since the calendar's epoch) changes only
  at its own contacts; a step's end is an output point, read from the anchors
  (``Calendar.positions_at``), and predicts nothing again;
* each sphere has a **neighbour list**: the spheres whose *shell centres* (where it was
  when its list was made) are within r_i + r_j + 2·delta of its own, delta =
  (SHELL - 1)·(the largest radius). Two spheres not on each other's lists cannot touch
  before one of them has moved delta from its centre, and that is an event of its own
  (leaving the shell), at which its list is made again from a grid of the centres;
* each sphere has **one event** in a heap of the N minima: the earliest of leaving its
  shell, a contact with a neighbour (the engine's swept pair test) and a contact with a
  wall (the planes' swept test). A sphere's contact counter (``stamp``) changes with its
  path; a pair event whose partner's counter moved since is stale and is predicted again.

Contacts are resolved by the engine's own resolver (resolve.judge_contact, and
resolve.resolve_at_one_instant for a sphere meeting walls at one instant, as the
time-ordered loop does), so every rule (impulse, restitution, the rapid-contact rule) is
the one the time-ordered loop applies; the contact rows are the same schema, with each
row's time made relative to its step by ``Calendar.run``'s caller.

Where it applies (World._calendar_unfit says why not, and the world steps with the
time-ordered loop instead): straight paths between contacts (no gravity on any movable
sphere, no drag, the exact or a straight-path integrator), swept detection, time
ordering, no meshes, no sleeping, no held contact, and no observer that reads each
step's swept tests (the calendar does not test pairs each step, so it has no such log).

Units: s, m, m/s. Arrays are in the world's numbering (space_order.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..events import KIND_PAIR, KIND_WALL
from .colliders import plane, sphere
from .jit import borrowing, kernel, records
from .motion import EXACT, advance_particle, advance_particles
from .periodic import image
from .resolve import AT_ONE_INSTANT_CANDIDATES, NEEDS_HELD, RESOLVED, SAME_INSTANT, SKIPPED, judge_contact, \
    resolve_at_one_instant
from .resting.store import HELD, STOP
from .timeline import CONTACTS, EVENTS, RAPID, TESTS
from .toi import SWEPT

# Each sphere's neighbours are those within its shell: delta = (SHELL - 1)·r_max from its
# centre. 1.5 (EDMD's, in units of the diameter there) measured best of 1.1-1.8 on the exact
# gas (benchmarks/experiments/calendar_gas.py: thinner shells are left too often, thicker
# ones list too many neighbours).
SHELL = 1.5
# the lists' reach is widened by this fraction of delta, so that a sphere a rounded
# shell-exit time lets go a little past delta is still on its neighbours' lists
SHELL_SLACK = 1e-9
LEAVE_SHELL = -1  # an event's kind besides events.KIND_PAIR and KIND_WALL
NONE = -1
FIRST_ROOM = 32  # neighbours a list has room for at first (grown on demand: Calendar.run)
MOST_CELLS_PER_SPHERE = 8  # a closed box's grid has at most this many cells a sphere
STOP_CHECK_EVERY = 1024  # events between reads of the world's stop switch
# a step may pop at most this many events per contact its budget allows (and per sphere):
# shell crossings and stale events come about one a contact (calendar_gas.py: 0.94 and
# 0.24), so only a loop that goes round without resolving anything reaches it
MOST_EVENTS_PER_CONTACT = 16
CONTACT_ROOM = AT_ONE_INSTANT_CANDIDATES + 1  # contact rows the loop wants free before each event

# Calendar.run's statuses
DONE = 0
GROW_CONTACTS = 1  # the contact rows are nearly full: grow them and call again
GROW_LISTS = 2  # a neighbour list is full: grow the lists and call again
CAPPED = 3  # the step's contact budget is spent (max_contacts_per_step)
STOPPED = 4  # World.request_stop
HELD_CONTACT = 5  # a contact was held: this loop has no held contacts (a world that holds one cannot use it)

# the rows of ``Calendar.ints``' skip table: a contact judged not to approach is not
# predicted again until one of its spheres changes (as the time-ordered loop, which re-predicts
# neither sphere after a skipped contact on a flow path)
SKIP_KIND, SKIP_OTHER, SKIP_STAMP_A, SKIP_STAMP_B = range(4)


SKIPS = 4  # skipped contacts remembered per sphere (SKIP_* fields each)


class Calendar:
    """The calendar of one world: anchors, shells, lists and events, kept across steps.

    x, v (N, 3): the spheres' positions and velocities at run time ``epoch`` (s), in the
    world's numbering (copied); radius (N,) m; period, origin (3,) m (period 0: an axis not
    periodic). ``build`` predicts every sphere's first event; ``run`` takes the events up
    to a time; ``positions_at`` reads the anchors at a step's end.
    """

    def __init__(self, x: np.ndarray, v: np.ndarray, radius: np.ndarray, period: np.ndarray, origin: np.ndarray,
                 epoch: float):
        n = x.shape[0]
        self.epoch = float(epoch)
        self.now = 0.0  # s since the epoch: the end of the last step run
        self.x = np.array(x, dtype=np.float64)
        self.v = np.array(v, dtype=np.float64)
        self.a = np.zeros((n, 3))  # straight paths: no path acceleration (the resolver reads it)
        self.acc = np.zeros((n, 3))
        self.sigma = np.zeros(n)
        r_max = float(radius.max()) if n else 0.0
        self.delta = (SHELL - 1.0) * r_max
        self.centre = self.x.copy()
        self.lo, self.width, self.cells, self.period = _grid(self.centre, period, origin, list_reach(radius))
        self.head = np.full(int(np.prod(self.cells)), NONE, dtype=np.int64)
        self.next = np.full(n, NONE, dtype=np.int64)
        self.previous = np.full(n, NONE, dtype=np.int64)
        self.cell = np.full(n, NONE, dtype=np.int64)
        self.neighbours = np.empty((n, max(1, min(FIRST_ROOM, n - 1))), dtype=np.int64)
        self.count = np.zeros(n, dtype=np.int64)
        self.when = np.full(n, math.inf)
        self.what = np.full(n, LEAVE_SHELL, dtype=np.int64)
        self.partner = np.full(n, NONE, dtype=np.int64)
        self.partner_stamp = np.zeros(n, dtype=np.int64)
        self.stamp = np.zeros(n, dtype=np.int64)
        self.skip = np.full((n, SKIPS, 4), NONE, dtype=np.int64)
        self.heap = np.arange(n, dtype=np.int64)
        self.where = np.arange(n, dtype=np.int64)
        self.kinds = np.zeros(AT_ONE_INSTANT_CANDIDATES, dtype=np.int64)
        self.others = np.zeros(AT_ONE_INSTANT_CANDIDATES, dtype=np.int64)
        self.resolved = np.zeros(AT_ONE_INSTANT_CANDIDATES, dtype=np.int64)
        self.last_x: np.ndarray | None = None  # the state the last step handed out (World: written since?)
        self.last_v: np.ndarray | None = None

    # the kernels' groups, as plain tuples (again after any growth)
    def _lists(self) -> tuple:
        return (self.centre, self.lo, self.width, self.cells, self.period, self.head, self.next, self.previous,
                self.cell, self.neighbours, self.count)

    def _events(self) -> tuple:
        return (self.when, self.what, self.partner, self.partner_stamp, self.stamp, self.skip, self.heap, self.where,
                self.kinds, self.others, self.resolved, np.empty(self.neighbours.shape[1], dtype=np.int64))

    def paths(self, radius, inverse_mass, restitution, last_contact) -> tuple:
        """kernel_args.LoopParticles of the anchors, as the resolver takes them."""
        return (self.x, self.v, self.a, self.acc, radius, inverse_mass, restitution, self.sigma, last_contact)

    def grow_lists(self) -> None:
        """Twice the room in every neighbour list (a list was full: GROW_LISTS); a list
        with room for every other sphere is never full."""
        n, room = self.neighbours.shape
        if room >= n - 1:
            raise RuntimeError("a neighbour list with room for every sphere overflowed: a bug (calendar.py)")
        grown = np.empty((n, min(2 * room, max(n - 1, 1))), dtype=np.int64)
        grown[:, :room] = self.neighbours
        self.neighbours = grown

    def build(self, particles: tuple, method: tuple, geometry: tuple, counters: np.ndarray) -> None:
        """The grid, every list and every sphere's first event (the swept tests count in counters)."""
        while not _build(self._lists(), self._events(), particles, method, geometry, counters, self.delta):
            self.grow_lists()

    def run(self, until: float, particles: tuple, method: tuple, geometry: tuple, held, contacts: np.ndarray,
            counters: np.ndarray, changed: np.ndarray, cap: int, most_events: int, work_budget: int) -> int:
        """Take the events up to ``until`` (s since the epoch), resolving contacts into
        ``contacts`` (events.CONTACT_ROW) and counting in ``counters`` (timeline's slots);
        returns a status (DONE, GROW_CONTACTS, CAPPED, STOPPED, HELD_CONTACT; a full list
        is grown here). Call again after GROW_CONTACTS: it carries on where it stopped."""
        while True:
            status = _run(self._lists(), self._events(), particles, method, geometry, held, records(contacts),
                          counters, changed, until, cap, most_events, work_budget, self.delta)
            if status != GROW_LISTS:
                return status
            self.grow_lists()

    def positions_at(self, time: float, integrator: int, drag: float, k: float, x_out: np.ndarray,
                     v_out: np.ndarray) -> None:
        """Every sphere's position and velocity at ``time`` (s since the epoch) into x_out,
        v_out (N, 3), along its path from its anchor (motion.advance_particles, the rule
        the time-ordered loop ends its steps with); the anchors stay."""
        n = self.x.shape[0]
        np.copyto(x_out, self.x)
        np.copyto(v_out, self.v)
        advance_particles(x_out, v_out, self.a, self.sigma.copy(), np.arange(n, dtype=np.int64), time, integrator,
                          drag, k)

    def pairs(self) -> np.ndarray:
        """(P, 2) int64, by i: the listed pairs i < j (every pair that can touch before one
        of them leaves its shell)."""
        return _listed_pairs(self.neighbours, self.count)


def list_reach(radius: np.ndarray) -> float:
    """The widest reach of a neighbour list (m): two of the largest spheres, each delta
    from its centre, and the slack."""
    r_max = float(radius.max()) if radius.size else 0.0
    return 2.0 * r_max + 2.0 * (SHELL - 1.0) * r_max * (1.0 + SHELL_SLACK)


def periodic_axes_too_short(period: np.ndarray, radius: np.ndarray) -> bool:
    """Whether a periodic axis is shorter than 3 cells of the lists' reach (the 27 cells
    round a sphere would not be distinct): the calendar cannot serve such a box."""
    return bool(np.any((period > 0) & (period < 3.0 * list_reach(radius))))


def _grid(centre: np.ndarray, period: np.ndarray, origin: np.ndarray, reach: float) -> tuple:
    """The grid of shell centres: (lo (3,) m, cell width (3,) m, cells (3,) int64, period
    (3,) m). A periodic axis is cut into cells at least ``reach`` wide across its period;
    a closed axis spans where the centres are now (at most MOST_CELLS_PER_SPHERE cells a
    sphere in all), and a centre outside it counts in the nearest end cell, so every pair
    within ``reach`` is in neighbouring cells either way."""
    n = centre.shape[0]
    lo = np.zeros(3)
    width = np.ones(3)
    cells = np.ones(3, dtype=np.int64)
    period = np.ascontiguousarray(period, dtype=np.float64).reshape(3)
    closed = [c for c in range(3) if not period[c] > 0]
    per_axis = max(1, int(round((MOST_CELLS_PER_SPHERE * max(n, 1)) ** (1.0 / max(len(closed), 1)))))
    for c in range(3):
        if period[c] > 0:
            lo[c] = origin[c]
            cells[c] = max(1, int(period[c] // reach)) if reach > 0 else 1
            width[c] = period[c] / cells[c]
        else:
            low = float(centre[:, c].min()) if n else 0.0
            span = float(centre[:, c].max()) - low if n else 0.0
            cells[c] = max(1, min(per_axis, int(span // reach))) if reach > 0 else 1
            lo[c] = low
            width[c] = max(span / cells[c], reach, 1e-300)
    return lo, width, cells, period


# ------------------------------------------------------------------------------ the heap
@njit(cache=True, inline="always")
def _before(when, i, j):
    return when[i] < when[j] or (when[i] == when[j] and i < j)


@njit(cache=True, inline="always")
def _heap_fix(heap, where, when, i, n):
    """Sphere i's event time changed: move it up or down the heap of the first n slots."""
    s = where[i]
    while s > 0:
        up = (s - 1) // 2
        if _before(when, i, heap[up]):
            heap[s] = heap[up]
            where[heap[s]] = s
            s = up
        else:
            break
    while True:
        child = 2 * s + 1
        if child >= n:
            break
        if child + 1 < n and _before(when, heap[child + 1], heap[child]):
            child += 1
        if _before(when, heap[child], i):
            heap[s] = heap[child]
            where[heap[s]] = s
            s = child
        else:
            break
    heap[s] = i
    where[i] = s


# ------------------------------------------------------------------------------ the grid and the lists
@njit(cache=True, inline="always")
def _axis_cell(value, lo, width, cells, period):
    """A centre's cell on one axis: wrapped on a periodic axis, clamped on a closed one."""
    k = math.floor((value - lo) / width)
    if period > 0.0:
        return int(k - cells * math.floor(k / cells))
    return int(min(max(k, 0.0), cells - 1.0))


@borrowing
def _cell_of(lists, i):
    centre, lo, width, cells, period = lists[0], lists[1], lists[2], lists[3], lists[4]
    key = 0
    for d in range(3):
        key = key * cells[d] + _axis_cell(centre[i, d], lo[d], width[d], cells[d], period[d])
    return key


@borrowing
def _link(head, nxt, prv, k, i):
    prv[i] = NONE
    nxt[i] = head[k]
    if head[k] != NONE:
        prv[head[k]] = i
    head[k] = i


@borrowing
def _unlink(head, nxt, prv, k, i):
    if prv[i] != NONE:
        nxt[prv[i]] = nxt[i]
    else:
        head[k] = nxt[i]
    if nxt[i] != NONE:
        prv[nxt[i]] = prv[i]


@njit(cache=True, inline="always")
def _centre_image(d, length):
    """periodic.image of a separation of two shell centres, which are kept in the box (so
    |d| < length): one comparison instead of a floor."""
    if length > 0.0:
        if d > 0.5 * length:
            return d - length
        if d < -0.5 * length:
            return d + length
    return d


@njit(cache=True, inline="always")
def _near(lists, radius, delta, i, j):
    """Whether j's shell centre is within the lists' reach of i's."""
    centre, period = lists[0], lists[4]
    reach = radius[i] + radius[j] + 2.0 * delta * (1.0 + SHELL_SLACK)
    d2 = 0.0
    for d in range(3):
        e = _centre_image(centre[i, d] - centre[j, d], period[d])
        d2 += e * e
    return d2 <= reach * reach


@borrowing
def _scan(lists, radius, delta, i, found):
    """The spheres whose centres are near i's (_near), from the 27 cells round it, into
    ``found``; how many, or -1 if more than ``found`` holds."""
    centre, lo, width, cells, period, head, nxt = lists[0], lists[1], lists[2], lists[3], lists[4], lists[5], lists[6]
    k0 = _axis_cell(centre[i, 0], lo[0], width[0], cells[0], period[0])
    k1 = _axis_cell(centre[i, 1], lo[1], width[1], cells[1], period[1])
    k2 = _axis_cell(centre[i, 2], lo[2], width[2], cells[2], period[2])
    m = 0
    for o0 in range(-1, 2):
        c0 = k0 + o0
        if period[0] > 0.0:
            c0 = (c0 + cells[0]) % cells[0]
        elif c0 < 0 or c0 >= cells[0]:
            continue
        for o1 in range(-1, 2):
            c1 = k1 + o1
            if period[1] > 0.0:
                c1 = (c1 + cells[1]) % cells[1]
            elif c1 < 0 or c1 >= cells[1]:
                continue
            for o2 in range(-1, 2):
                c2 = k2 + o2
                if period[2] > 0.0:
                    c2 = (c2 + cells[2]) % cells[2]
                elif c2 < 0 or c2 >= cells[2]:
                    continue
                j = head[(c0 * cells[1] + c1) * cells[2] + c2]
                while j != NONE:
                    if j != i and _near(lists, radius, delta, i, j):
                        if m >= found.shape[0]:
                            return -1
                        found[m] = j
                        m += 1
                    j = nxt[j]
    return m


@borrowing
def _relist(lists, radius, delta, i, found) -> bool:
    """i's list made again from its new centre, symmetrically (off its old neighbours'
    lists, onto its new ones'); False, changing nothing, if a list would overflow.
    found: scratch of the lists' room."""
    neighbours, count = lists[9], lists[10]
    room = neighbours.shape[1]
    m = _scan(lists, radius, delta, i, found)
    if m < 0:
        return False
    for s in range(m):  # room on each new neighbour's list (one already listing i keeps its count)
        j = found[s]
        if count[j] >= room:
            listed = False
            for q in range(count[i]):
                listed = listed or neighbours[i, q] == j
            if not listed:
                return False
    for s in range(count[i]):
        j = neighbours[i, s]
        for q in range(count[j]):
            if neighbours[j, q] == i:
                count[j] -= 1
                neighbours[j, q] = neighbours[j, count[j]]
                break
    for s in range(m):
        j = found[s]
        neighbours[i, s] = j
        neighbours[j, count[j]] = i
        count[j] += 1
    count[i] = m
    return True


@kernel
def _listed_pairs(neighbours, count):
    total = 0
    for i in range(count.shape[0]):
        for s in range(count[i]):
            if neighbours[i, s] > i:
                total += 1
    pairs = np.empty((total, 2), dtype=np.int64)
    m = 0
    for i in range(count.shape[0]):
        for s in range(count[i]):
            j = neighbours[i, s]
            if j > i:
                pairs[m, 0] = i
                pairs[m, 1] = j
                m += 1
    return pairs


# ------------------------------------------------------------------------------ predictions
@njit(cache=True, inline="always")
def _skipped(skip, stamp, i, kind, other):
    """Whether contact (kind, i, other) was judged not to approach and neither sphere changed since."""
    for s in range(SKIPS):
        if (skip[i, s, SKIP_KIND] == kind and skip[i, s, SKIP_OTHER] == other and skip[i, s, SKIP_STAMP_A] == stamp[i]
                and (kind != KIND_PAIR or skip[i, s, SKIP_STAMP_B] == stamp[other])):
            return True
    return False


@borrowing
def _remember_skip(skip, stamp, i, kind, other):
    """Remember a skipped contact of i, in the first slot no longer current (else the first)."""
    slot = 0
    for s in range(SKIPS):
        current = (skip[i, s, SKIP_KIND] != NONE and skip[i, s, SKIP_STAMP_A] == stamp[i]
                   and (skip[i, s, SKIP_KIND] != KIND_PAIR or skip[i, s, SKIP_STAMP_B] == stamp[skip[i, s, SKIP_OTHER]]))
        if not current:
            slot = s
            break
    skip[i, slot, SKIP_KIND] = kind
    skip[i, slot, SKIP_OTHER] = other
    skip[i, slot, SKIP_STAMP_A] = stamp[i]
    skip[i, slot, SKIP_STAMP_B] = stamp[other] if kind == KIND_PAIR else 0


@njit(cache=True, inline="always")
def _predict(i, now, lists, events, particles, method, geometry, counters, delta, heap_size):
    """Sphere i's one event from ``now`` (s since the epoch): leaving its shell, or its
    earliest contact with a neighbour or a wall (the engine's swept tests, from the
    anchors); filed in the heap of the first ``heap_size`` slots (0: not yet a heap)."""
    centre, period = lists[0], lists[4]
    neighbours, count = lists[9], lists[10]
    when, what, partner, partner_stamp, stamp, skip, heap, where = (events[0], events[1], events[2], events[3],
                                                                    events[4], events[5], events[6], events[7])
    x, v, a, radius, sigma = particles[0], particles[1], particles[2], particles[4], particles[7]
    samples, tolerance = method[6], method[7]
    # The swept tests as constants the compiler can fold (a test with them as run-time values
    # costs three times as much: 66 against 20 ns): the calendar serves only paths without
    # drag (k = -ln(drag) = 0) or path acceleration, on which every integrator's path is
    # x + v·tau bit for bit (the a·P2 term is 0), tested by swept detection.
    integrator, k, detection = EXACT, 0.0, SWEPT
    # i's anchor to now (in the box on a periodic axis): a pair's swept test starts at the
    # later anchor, and takes the image of the separation there, which must be the image
    # of now, when the neighbours are within the lists' reach (an anchor from long ago may
    # see the pair through another image)
    advance_particle(x, v, a, sigma, i, now, integrator, 1.0, k)
    for d in range(3):
        if period[d] > 0.0:
            x[i, d] -= period[d] * math.floor((x[i, d] - lists[1][d]) / period[d])
    # leaving the shell: |x_i + v_i·s - c_i| = delta, s from i's anchor
    e0 = image(x[i, 0] - centre[i, 0], period[0])
    e1 = image(x[i, 1] - centre[i, 1], period[1])
    e2 = image(x[i, 2] - centre[i, 2], period[2])
    vv = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2]
    best = math.inf
    kind = LEAVE_SHELL
    other = NONE
    if vv > 0.0:
        b = e0 * v[i, 0] + e1 * v[i, 1] + e2 * v[i, 2]
        c = e0 * e0 + e1 * e1 + e2 * e2 - delta * delta
        best = sigma[i] + (-b + math.sqrt(max(b * b - vv * c, 0.0))) / vv
    for s in range(count[i]):
        j = neighbours[i, s]
        start, t, work = sphere.time_of_impact(min(i, j), max(i, j), x, v, a, radius, sigma, math.inf, integrator, k,
                                               detection, samples, tolerance, geometry[KIND_PAIR])
        counters[TESTS] += work
        if start + t < best and not _skipped(skip, stamp, i, KIND_PAIR, j):
            best = start + t
            kind = KIND_PAIR
            other = j
    for w in range(geometry[KIND_WALL][1].shape[0]):
        start, t, work = plane.time_of_impact(i, w, x, v, a, radius, sigma, math.inf, integrator, k, detection,
                                              samples, geometry[KIND_WALL])
        counters[TESTS] += work
        if start + t < best and not _skipped(skip, stamp, i, KIND_WALL, w):
            best = start + t
            kind = KIND_WALL
            other = w
    when[i] = max(best, now)  # (a rounded root a hair before now is now: the calendar's time never runs back)
    what[i] = kind
    partner[i] = other
    partner_stamp[i] = stamp[other] if kind == KIND_PAIR else 0
    if heap_size > 0:
        _heap_fix(heap, where, when, i, heap_size)


@kernel
def _build(lists, events, particles, method, geometry, counters, delta) -> bool:
    """Calendar.build: False (with nothing listed) if a list overflows."""
    head, nxt, prv, cell, neighbours, count = lists[5], lists[6], lists[7], lists[8], lists[9], lists[10]
    heap, where, when = events[6], events[7], events[0]
    radius = particles[4]
    n = count.shape[0]
    head[:] = NONE
    count[:] = 0
    for i in range(n):
        cell[i] = _cell_of(lists, i)
        _link(head, nxt, prv, cell[i], i)
    for i in range(n):
        m = _scan(lists, radius, delta, i, lists[9][i])
        if m < 0:
            return False
        lists[10][i] = m
    for i in range(n):
        _predict(i, 0.0, lists, events, particles, method, geometry, counters, delta, 0)
    for i in range(n):  # one at a time: the first i + 1 slots are a heap
        heap[i] = i
        where[i] = i
        _heap_fix(heap, where, when, i, i + 1)
    return True


@kernel
def _run(lists, events, particles, method, geometry, held, contacts, counters, changed, until, cap, most_events,
         work_budget, delta) -> int:
    """Calendar.run's loop (its statuses, and GROW_LISTS before any change)."""
    centre, head, nxt, prv, cell = lists[0], lists[5], lists[6], lists[7], lists[8]
    when, what, partner, partner_stamp, stamp, skip, heap = (events[0], events[1], events[2], events[3], events[4],
                                                             events[5], events[6])
    kinds, others, resolved = events[8], events[9], events[10]
    x, v, radius, sigma = particles[0], particles[1], particles[4], particles[7]
    samples, tolerance, step_end = method[6], method[7], method[1]
    integrator, k, detection = EXACT, 0.0, SWEPT  # as in _predict
    n = heap.shape[0]
    walls = geometry[KIND_WALL][1].shape[0]
    while n > 0:
        i = heap[0]
        now = when[i]
        if now > until:
            return DONE
        if contacts.shape[0] - counters[CONTACTS] < CONTACT_ROOM:
            return GROW_CONTACTS
        if counters[EVENTS] % STOP_CHECK_EVERY == 0 and held.count[STOP] != 0:
            return STOPPED
        if counters[EVENTS] >= most_events:
            return CAPPED
        kind = what[i]
        if kind == LEAVE_SHELL:
            old0, old1, old2 = centre[i, 0], centre[i, 1], centre[i, 2]
            for d in range(3):  # the new centre: where i is now (on a periodic axis, in the box)
                c = x[i, d] + v[i, d] * (now - sigma[i])
                if lists[4][d] > 0.0:
                    c -= lists[4][d] * math.floor((c - lists[1][d]) / lists[4][d])
                centre[i, d] = c
            if not _relist(lists, radius, delta, i, events[11]):
                centre[i, 0], centre[i, 1], centre[i, 2] = old0, old1, old2
                return GROW_LISTS
            counters[EVENTS] += 1
            _unlink(head, nxt, prv, cell[i], i)
            cell[i] = _cell_of(lists, i)
            _link(head, nxt, prv, cell[i], i)
            _predict(i, now, lists, events, particles, method, geometry, counters, delta, n)
            continue
        counters[EVENTS] += 1
        j = partner[i]
        if kind == KIND_PAIR:
            if stamp[j] != partner_stamp[i]:  # j's path changed since: i predicted again
                _predict(i, now, lists, events, particles, method, geometry, counters, delta, n)
                continue
            if counters[CONTACTS] >= cap:
                return CAPPED
            status, _closing, _used, _how, _rapid = judge_contact(KIND_PAIR, min(i, j), max(i, j), now, particles,
                                                                  method, geometry, held, contacts, counters,
                                                                  CONTACTS, RAPID, changed)
            if status == NEEDS_HELD:
                return HELD_CONTACT
            if status == RESOLVED:
                stamp[i] += 1
                stamp[j] += 1
            else:
                _remember_skip(skip, stamp, i, KIND_PAIR, j)
                _remember_skip(skip, stamp, j, KIND_PAIR, i)
            _predict(i, now, lists, events, particles, method, geometry, counters, delta, n)
            _predict(j, now, lists, events, particles, method, geometry, counters, delta, n)
            continue
        # a wall: with every other wall i meets at the same instant (as the time-ordered loop)
        if counters[CONTACTS] >= cap:
            return CAPPED
        kinds[0] = KIND_WALL
        others[0] = j
        met = 1
        for w in range(walls):
            if w == j or met >= AT_ONE_INSTANT_CANDIDATES or _skipped(skip, stamp, i, KIND_WALL, w):
                continue
            start, t, work = plane.time_of_impact(i, w, x, v, particles[2], radius, sigma, math.inf, integrator, k,
                                                  detection, samples, geometry[KIND_WALL])
            counters[TESTS] += work
            if start + t <= now + SAME_INSTANT * step_end:
                kinds[met] = KIND_WALL
                others[met] = w
                met += 1
        if met > 1:
            resolve_at_one_instant(kinds, others, met, i, now, particles, method, geometry, held, contacts, counters,
                                   CONTACTS, RAPID, changed, work_budget, resolved)
            took = False
            for m in range(met):
                took = took or resolved[m] != 0
            if took:
                stamp[i] += 1
            else:
                for m in range(met):
                    _remember_skip(skip, stamp, i, KIND_WALL, others[m])
        else:
            status, _closing, _used, _how, _rapid = judge_contact(KIND_WALL, i, j, now, particles, method, geometry,
                                                                  held, contacts, counters, CONTACTS, RAPID, changed)
            if status == NEEDS_HELD:
                return HELD_CONTACT
            if status == RESOLVED:
                stamp[i] += 1
            else:
                _remember_skip(skip, stamp, i, KIND_WALL, j)
        if held.count[HELD] != 0:
            return HELD_CONTACT
        _predict(i, now, lists, events, particles, method, geometry, counters, delta, n)
    return DONE
