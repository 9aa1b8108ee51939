"""The event calendar: contacts predicted once and kept across steps (``event_loop = "calendar"``).

Why one module of this size: the calendar's kernels read and write one structure (the
``Calendar``'s anchors, shells, neighbour and partner lists and its queue) and call each
other compiled; the world's step from it is calendar_step.py.

The time-ordered loop (timeline.py) works a step at a time: at each step's start it boxes
every path, pairs the boxes and predicts every pair again, though a sphere between
contacts keeps its path from one step to the next. This loop is the design of the fastest
event-driven hard-sphere codes (Smallenburg's EDMD, Eur. Phys. J. E 45, 22 (2022)), for a
world whose paths change only at contacts:

* each sphere's **anchor** (x, v at time sigma, s since the calendar's epoch, and its
  path acceleration a) changes only at its own contacts; a step's end is an output
  point, read from the anchors (``Calendar.positions_at``), and predicts nothing again.
  That holds wherever re-anchoring a path leaves it unchanged (motion.FLOW): exact paths
  under gravity and drag, Verlet's parabola without drag, straight paths without forces;
* each sphere has a **neighbour list**: the spheres whose *shell centres* (where it was
  when its list was made) are within r_i + r_j + 2·delta of its own, delta at least
  (SHELL - 1)·(the largest radius), thicker in a dilute world (``shell_fit``). Two
  spheres not on each other's lists cannot touch before one of them has moved delta
  from its centre, and that is an event of its own (leaving the shell: exact on a
  straight path, a time no later than it on a curved one, ``shell_exit``), at which its
  list is made again from a grid of the centres, and with it the list of its **immovable
  partners**: the walls and the fixed meshes' triangles the box of its shell reaches
  (colliders.immovable_partners_in: each mesh's tree walked once a shell);
* each sphere has **one event** in a heap of the N minima: the earliest of leaving its
  shell, a contact with a neighbour and a contact with a listed immovable partner,
  each the engine's swept test through the collider switch (colliders.time_of_impact).
  Two spheres that fall alike (one gravity, the same gravity scale) move on a straight
  line relative to each other (the acceleration cancels in the pair test); a wall's path
  is the parabola the time-ordered loop tests, as is a pair's that falls differently. A
  sphere's contact counter (``stamp``) changes with its path; a pair event whose
  partner's counter moved since is stale and is predicted again.

Contacts are resolved by the engine's own resolver (resolve.resolve_contact, and
resolve.resolve_at_one_instant for a sphere meeting walls or triangles at one instant,
as the time-ordered loop does), so every rule (impulse, restitution, the rapid-contact rule) is
the one the time-ordered loop applies; the contact rows are the same schema, with each
row's time made relative to its step by ``Calendar.run``'s caller.

Held contacts (resting.py's rules) are the resolver's too: a contact the resolver holds,
or one that reaches a sphere with held contacts, is solved with the held contacts it
reaches (resolve.resolve_contact), and every sphere whose path that changes takes a new
anchor and is predicted again; a held contact is never tested. At each step's start the
forces phase's rule (resolve.settle_held, from the state there, as the time-ordered loop
takes it) releases contacts whose gaps opened and solves the held accelerations, and the
spheres whose paths that changes are anchored again there (``Calendar.renew``); a settled
pile keeps its anchors, and costs no event. So are the spheres that fall asleep or wake
at a step's end (sleep.py): asleep, a sphere is immovable and still, an obstacle whose
path has no event; a world that sleeps has its lists reach the sleep rules' support gap
farther (Calendar's margin), since the rules read them as the step's pairs.

Where it applies (World._calendar_unfit says why not, and the world steps with the
time-ordered loop instead): paths whose anchor is their flow (not Euler's, not a
semi-implicit kick under forces), swept detection, time ordering, partners of the kinds
it takes (colliders.CALENDAR_TAKES: spheres, walls, meshes), fixed meshes only (a
kinematic mesh's triangles move into shells whose lists were made without them), and
no observer that reads each step's swept tests or its search of the meshes' trees (the
calendar tests pairs only when their paths change and walks a tree only when a shell is
made, so it has no such logs).

Units: s, m, m/s. Arrays are in the world's numbering (space_order.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..events import KIND_PAIR
from .colliders import CALENDAR_TAKES, KINDS, PARTNER_IS_SPHERE, immovable_partners_in, time_of_impact
from .jit import borrowing, kernel, records
from .motion import EXACT, advance_particle, advance_particles
from .periodic import image
from .resolve import AT_ONE_INSTANT_CANDIDATES, OUT_OF_WORK, SAME_INSTANT, SKIPPED, resolve_at_one_instant, \
    resolve_contact
from .resting.store import STOP, held_find, held_room
from .timeline import CONTACTS, EVENTS, RAPID, TESTS
from .toi import SWEPT

# Each sphere's neighbours are those within its shell: at least delta = (SHELL - 1)·r_max
# from its centre. 1.5 (EDMD's, in units of the diameter there) measured best of 1.1-1.8 on
# the exact gas (benchmarks/experiments/calendar_gas.py: thinner shells are left too often,
# thicker ones list too many neighbours). A dilute world's shells are thicker (shell_fit).
SHELL = 1.5
# shell_fit's rule: a step that left shells more than SHELL_GROW_AT times as often as it
# met something (or as an eighth of its spheres, where it met little) doubles the
# thickness (again while that would still hold, each doubling about halving the shells
# left), if the lists (neighbours and immovable partners) then stay at most
# SHELL_MOST_LISTED long on average; one that
# left them under 1/SHELL_GROW_AT as often, or whose lists are over twice that long,
# halves it (never below delta). Each change makes the calendar afresh at the next step.
# Thinning is judged over SHELL_JUDGED_OVER steps at a time: a calendar's first step
# leaves few shells (each was made at its start), so one step alone would thin every new
# shell again. Thickening is judged from SHELL_GROWN_AFTER steps (that first step counts
# against it): a dilute world pays for every step on the thinnest shells.
SHELL_GROW_AT = 4
SHELL_MOST_LISTED = 32
SHELL_JUDGED_OVER = 8
SHELL_GROWN_AFTER = 2
# the lists' reach is widened by this fraction of delta, so that a sphere a rounded
# shell-exit time lets go a little past delta is still on its neighbours' lists
SHELL_SLACK = 1e-9
LEAVE_SHELL = -1  # an event's kind besides the collider kinds' codes (events.KIND_*)
NONE = -1
FIRST_ROOM = 32  # neighbours a list has room for at first (grown on demand: Calendar.run)
FIRST_IMMOVABLE_ROOM = 8  # immovable partners (walls, triangles) a shell's list has room for at first
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
GROW_HELD = 5  # the held store has no room for the next contact's: grow it and call again
RESTING_BUDGET = 6  # a held-contact solve spent the step's resting work (max_resting_work_per_step)
GROW_PARTNERS = 7  # a list of immovable partners is full: grow the lists and call again

# the rows of the skip table: a contact judged not to approach is not predicted again
# until one of its spheres changes or the step ends (as the time-ordered loop, which
# re-predicts neither sphere after a skipped contact, and predicts every pair again at its
# next step's start: Calendar.expire_skips)
SKIP_KIND, SKIP_OTHER, SKIP_STAMP_A, SKIP_STAMP_B = range(4)


SKIPS = 4  # skipped contacts remembered per sphere (SKIP_* fields each)

# the kinds of immovable partner the calendar lists for each shell (colliders' table:
# those it takes whose partners are not spheres), in the order of their codes
IMMOVABLE_KINDS = tuple(kind for kind in range(KINDS) if CALENDAR_TAKES[kind] and not PARTNER_IS_SPHERE[kind])


class Calendar:
    """The calendar of one world: anchors, shells, lists and events, kept across steps.

    x, v (N, 3): the spheres' positions and velocities at run time ``epoch`` (s), in the
    world's numbering (copied); path_accel (N, 3) m/s²: each path's acceleration (the
    forces phase's); radius (N,) m; period, origin (3,) m (period 0: an axis not
    periodic); margin (m): how much farther apart than touching a listed pair may be
    (the sleep rules' support gap, which reads the lists as the step's pairs);
    most_partners: the most immovable partners of one kind (colliders.most_partners:
    every wall, every triangle), the room a shell's search of them needs; delta (m): the
    shells' thickness (None: thinnest_shell's; shell_fit chooses another). ``build``
    predicts every sphere's first event; ``run`` takes the events up to a time;
    ``positions_at`` reads the anchors at a step's end.
    """

    def __init__(self, x: np.ndarray, v: np.ndarray, path_accel: np.ndarray, radius: np.ndarray, period: np.ndarray,
                 origin: np.ndarray, epoch: float, margin: float = 0.0, most_partners: int = 0,
                 delta: float | None = None):
        n = x.shape[0]
        self.epoch = float(epoch)
        self.now = 0.0  # s since the epoch: the end of the last step run
        self.x = np.array(x, dtype=np.float64)
        self.v = np.array(v, dtype=np.float64)
        # each sphere's path acceleration (N, 3) m/s², kept with its anchor: one gravity for
        # every movable sphere, 0 for an immovable one (the resolver reads both a and acc)
        self.a = np.array(path_accel, dtype=np.float64).reshape(n, 3)
        self.acc = self.a.copy()
        self.accelerates = bool(np.any(self.a))
        self.sigma = np.zeros(n)
        self.delta = thinnest_shell(radius) if delta is None else float(delta)
        # the lists reach as if each shell were margin/2 thicker: a listed pair is every one
        # within margin of touching while both are inside their shells
        self.list_delta = self.delta + 0.5 * margin
        self.centre = self.x.copy()
        self.lo, self.width, self.cells, self.period = _grid(self.centre, period, origin, list_reach(radius, margin, self.delta))
        self.head = np.full(int(np.prod(self.cells)), NONE, dtype=np.int64)
        self.next = np.full(n, NONE, dtype=np.int64)
        self.previous = np.full(n, NONE, dtype=np.int64)
        self.cell = np.full(n, NONE, dtype=np.int64)
        self.neighbours = np.empty((n, max(1, min(FIRST_ROOM, n - 1))), dtype=np.int64)
        self.count = np.zeros(n, dtype=np.int64)
        # each sphere's immovable partners within its shell's reach, rows (kind, other), and
        # the box that reached them (a row of shell_lo, shell_hi (N, 3) m)
        self.immovables = np.empty((n, FIRST_IMMOVABLE_ROOM, 2), dtype=np.int64)
        self.immovable_count = np.zeros(n, dtype=np.int64)
        self.shell_lo = np.zeros((n, 3))
        self.shell_hi = np.zeros((n, 3))
        self.found_partners = np.empty((max(int(most_partners), 1), 2), dtype=np.int64)
        # what the steps since the last judgement did: shells left, contacts met, and how
        # many steps that was (shell_fit reads and resets it)
        self.tally = np.zeros(3, dtype=np.int64)
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
        self.settle_next = False  # whether a contact was held in the last step (CalendarSteps: settle the next)
        self.last_v: np.ndarray | None = None

    # the kernels' groups, as plain tuples (again after any growth)
    def _lists(self) -> tuple:
        return (self.centre, self.lo, self.width, self.cells, self.period, self.head, self.next, self.previous,
                self.cell, self.neighbours, self.count, self.immovables, self.immovable_count, self.shell_lo,
                self.shell_hi, self.found_partners)

    def _events(self) -> tuple:
        return (self.when, self.what, self.partner, self.partner_stamp, self.stamp, self.skip, self.heap, self.where,
                self.kinds, self.others, self.resolved, np.empty(self.neighbours.shape[1], dtype=np.int64),
                self.tally)

    def paths(self, radius, inverse_mass, restitution, last_contact) -> tuple:
        """kernel_args.LoopParticles of the anchors, as the resolver takes them."""
        return (self.x, self.v, self.a, self.acc, radius, inverse_mass, restitution, self.sigma, last_contact)

    def _shell(self, method: tuple) -> tuple:
        """(delta m, curved, list delta m): the shell's thickness, whether any path bends
        (drag, or a path acceleration: where none does, a pair's test needs no bracket,
        _predict), and the thickness the lists reach as (delta and half the margin)."""
        return self.delta, bool(method[4] != 0.0 or self.accelerates), self.list_delta

    def grow_lists(self) -> None:
        """Twice the room in every neighbour list (a list was full: GROW_LISTS); a list
        with room for every other sphere is never full."""
        n, room = self.neighbours.shape
        if room >= n - 1:
            raise RuntimeError("a neighbour list with room for every sphere overflowed: a bug (calendar.py)")
        grown = np.empty((n, min(2 * room, max(n - 1, 1))), dtype=np.int64)
        grown[:, :room] = self.neighbours
        self.neighbours = grown

    def grow_partners(self) -> None:
        """Twice the room in every list of immovable partners (one was full: GROW_PARTNERS)."""
        n, room, _ = self.immovables.shape
        grown = np.empty((n, 2 * room, 2), dtype=np.int64)
        grown[:, :room] = self.immovables
        self.immovables = grown

    def _grow(self, status: int) -> bool:
        """Grow what a kernel's status says was full; whether it was a call to grow."""
        if status == GROW_LISTS:
            self.grow_lists()
        elif status == GROW_PARTNERS:
            self.grow_partners()
        else:
            return False
        return True

    def build(self, particles: tuple, method: tuple, geometry: tuple, held, counters: np.ndarray) -> None:
        """The grid, every list and every sphere's first event (the swept tests count in
        counters; held: the held store, whose contacts are not tested)."""
        while self._grow(_build(self._lists(), self._events(), particles, method, geometry, held, counters,
                                self._shell(method))):
            pass

    def renew(self, spheres: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray, acc: np.ndarray,
              particles: tuple, method: tuple, geometry: tuple, held, counters: np.ndarray) -> None:
        """New paths for ``spheres`` (int64 indices) at a step's start (``now``): their
        rows of x, v (N, 3), m, m/s, of a (N, 3) m/s², the path accelerations (the held
        contacts' solve's, or a sleeper's 0), and of acc (N, 3) m/s², the accelerations the
        resolver judges pressing by; each predicted again (its old events go stale)."""
        self.accelerates = self.accelerates or bool(np.any(a[spheres]))
        self.acc[spheres] = acc[spheres]
        _renew(self._lists(), self._events(), particles, method, geometry, held, counters, self._shell(method),
               self.now, spheres, x, v, a)

    def expire_skips(self, particles: tuple, method: tuple, geometry: tuple, held, counters: np.ndarray) -> None:
        """At a step's start (``now``): forget every contact judged not to approach, and
        predict its spheres again. The time-ordered loop takes such a skip for the rest of
        its step only; on a curved path (a wall under gravity, two spheres that fall
        differently) the contact can come back without either sphere meeting anything else."""
        _expire_skips(self._lists(), self._events(), particles, method, geometry, held, counters,
                      self._shell(method), self.now)

    def run(self, until: float, particles: tuple, method: tuple, geometry: tuple, held, contacts: np.ndarray,
            counters: np.ndarray, changed: np.ndarray, cap: int, most_events: int, work_budget: int) -> int:
        """Take the events up to ``until`` (s since the epoch), resolving contacts into
        ``contacts`` (events.CONTACT_ROW) and counting in ``counters`` (timeline's slots);
        returns a status (DONE, GROW_CONTACTS, GROW_HELD, CAPPED, STOPPED, RESTING_BUDGET; a
        full list is grown here). Call again after GROW_CONTACTS or GROW_HELD (with the
        grown store): it carries on where it stopped."""
        while True:
            status = _run(self._lists(), self._events(), particles, method, geometry, held, records(contacts),
                          counters, changed, until, cap, most_events, work_budget, self._shell(method))
            if not self._grow(status):
                return status

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


def thinnest_shell(radius: np.ndarray) -> float:
    """The thinnest shell (m): (SHELL - 1)·r_max, the thickness a dense world keeps."""
    return (SHELL - 1.0) * (float(radius.max()) if radius.size else 0.0)


def list_reach(radius: np.ndarray, margin: float = 0.0, delta: float | None = None) -> float:
    """The widest reach of a neighbour list (m): two of the largest spheres, each delta
    (None: thinnest_shell) from its centre, the margin (Calendar) and the slack."""
    r_max = float(radius.max()) if radius.size else 0.0
    delta = thinnest_shell(radius) if delta is None else delta
    return 2.0 * r_max + 2.0 * (delta + 0.5 * margin) * (1.0 + SHELL_SLACK)


def periodic_axes_too_short(period: np.ndarray, radius: np.ndarray, margin: float = 0.0,
                            delta: float | None = None) -> bool:
    """Whether a periodic axis is shorter than 3 cells of the lists' reach (the 27 cells
    round a sphere would not be distinct): the calendar cannot serve such a box (or such
    a thickness, delta m)."""
    return bool(np.any((period > 0) & (period < 3.0 * list_reach(radius, margin, delta))))


def shell_fit(cal: "Calendar", radius: np.ndarray, period: np.ndarray, margin: float) -> float | None:
    """The shell thickness (m) the calendar's next build should have, from what its last
    steps did (cal.tally: shells left, contacts met, steps; the lists' lengths), or None
    to keep its own (SHELL_GROW_AT's rule: thicker from SHELL_GROWN_AFTER steps, thinner
    after SHELL_JUDGED_OVER; the tally starts again after each judgement that is made).
    A dilute gas leaves a thin shell many times between contacts (5,000 spheres at
    250 m/s, 6 m apart: 33 times a step each at 0.125 m), and each leaving lists the
    shell again and predicts the sphere again; a pile meets its neighbours many times in
    a step and leaves few shells, and every one of those contacts tests every listed
    neighbour. Read from counts, never from clocks: a run chooses the
    same thicknesses each time (bit-identical reruns)."""
    n = cal.count.shape[0]
    steps = int(cal.tally[2])
    if n == 0 or steps < SHELL_GROWN_AFTER:
        return None
    left, met = int(cal.tally[0]) // steps, int(cal.tally[1]) // steps  # a step's
    base = max(met, n // 8, 1)
    if left <= SHELL_GROW_AT * base and steps < SHELL_JUDGED_OVER:
        return None  # (too soon to thin)
    cal.tally[:] = 0
    # neighbours and immovable partners a shell lists (a dense terrain mesh among sparse
    # spheres: each thicker shell would reach many more triangles)
    listed = float(cal.count.sum() + cal.immovable_count.sum()) / n
    floor = thinnest_shell(radius)
    r_max = float(radius.max())
    if left > SHELL_GROW_AT * base:
        # doubled while it would still leave them too often (about half as often each
        # time), and the lists, which grow with the volume of their reach, stay short
        grown = cal.delta
        while (left > SHELL_GROW_AT * base
               and listed * ((r_max + 2.0 * grown) / (r_max + cal.delta)) ** 3 <= SHELL_MOST_LISTED
               and not periodic_axes_too_short(period, radius, margin, 2.0 * grown)):
            grown *= 2.0
            left //= 2
        return grown if grown > cal.delta else None
    if cal.delta > floor and (SHELL_GROW_AT * left < base or listed > 2 * SHELL_MOST_LISTED):
        return max(floor, 0.5 * cal.delta)
    return None


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


@borrowing
def _list_immovables(lists, radius, delta, geometry, i) -> bool:
    """i's immovable partners (every kind the calendar takes whose partners are not
    spheres: walls, a fixed mesh's triangles) that the box of its shell reaches (its
    centre, r_i + delta and the slack every way), found through the collider switch
    (colliders.immovable_partners_in: a mesh's tree walked once per shell, not once per
    prediction); False, with i's list unusable until made again, if it would overflow."""
    centre, rows, count, lo, hi, found = lists[0], lists[11], lists[12], lists[13], lists[14], lists[15]
    reach = radius[i] + delta * (1.0 + SHELL_SLACK)
    for d in range(3):
        lo[i, d] = centre[i, d] - reach
        hi[i, d] = centre[i, d] + reach
    m = 0
    count[i] = 0
    for kind in IMMOVABLE_KINDS:
        reached = immovable_partners_in(kind, i, lo, hi, geometry, found)
        if m + reached > rows.shape[1]:
            return False
        for s in range(reached):
            rows[i, m, 0] = kind
            rows[i, m, 1] = found[s, 1]
            m += 1
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
def _toi(kind, i, other, x, v, a, radius, sigma, until, k, samples, tolerance, geometry):
    """The engine's swept test of (kind, i, other) from the anchors up to time ``until``
    (s since the epoch), through the collider switch: (start, t, work). The integrator and
    detection are constants the compiler folds (a test with them as run-time values costs
    three times as much: 66 against 20 ns), and so is k where there is no drag: the
    calendar serves only paths whose anchor is their flow (World._calendar_unfit_by_scene),
    on which every such integrator's path is exact's (x + v·P1 + a·P2), tested by swept
    detection."""
    if k == 0.0:
        return time_of_impact(kind, i, other, x, v, a, radius, sigma, until, EXACT, 0.0, SWEPT, samples, tolerance,
                              geometry)
    return time_of_impact(kind, i, other, x, v, a, radius, sigma, until, EXACT, k, SWEPT, samples, tolerance,
                          geometry)


@njit(cache=True, inline="always")
def _curved(i, a, k):
    """Whether sphere i's path bends (drag or a path acceleration)."""
    return k != 0.0 or a[i, 0] != 0.0 or a[i, 1] != 0.0 or a[i, 2] != 0.0


@njit(cache=True, inline="always")
def _exit_time(i, lists, x, v, a, sigma, delta, curved):
    """When sphere i, from its anchor, leaves its shell (s since the epoch; shell_exit;
    curved: whether its path bends)."""
    centre, period = lists[0], lists[4]
    return sigma[i] + shell_exit(image(x[i, 0] - centre[i, 0], period[0]), image(x[i, 1] - centre[i, 1], period[1]),
                                 image(x[i, 2] - centre[i, 2], period[2]), v[i, 0], v[i, 1], v[i, 2], a[i, 0],
                                 a[i, 1], a[i, 2], delta, curved)


@njit(cache=True, inline="always")
def shell_exit(e0, e1, e2, v0, v1, v2, a0, a1, a2, delta, curved):
    """When (s after the anchor) a sphere at e (m) from its shell centre, with velocity v
    (m/s) and path acceleration a (m/s²), is delta (m) from the centre: the root of
    |e + v·s| = delta on a straight path; on a curved one (gravity or drag: ``curved``)
    the time its distance from the anchor, at most |v|·s + |a|·s²/2 (drag only slows a
    path: |v(s)| <= |v| + |a|·s), can first make up the room left, delta - |e|: never after
    the sphere really leaves, so its neighbours stay listed while it is inside."""
    vv = v0 * v0 + v1 * v1 + v2 * v2
    if not curved:
        if vv <= 0.0:
            return math.inf
        b = e0 * v0 + e1 * v1 + e2 * v2
        c = e0 * e0 + e1 * e1 + e2 * e2 - delta * delta
        t = (-b + math.sqrt(max(b * b - vv * c, 0.0))) / vv
        if t > 0.0:
            return t
        # on the shell and leaving, or vv·c underflowed (a held solve's residue of 1e-161
        # m/s), which left the root 0 and the sphere leaving its shell at once, for ever:
        # no earlier than the room left at full speed
        return (delta - math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)) / math.sqrt(vv)
    room = delta - math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if room <= 0.0:
        return 0.0
    speed = math.sqrt(vv)
    push = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if push > 0.0:  # speed·s + push·s²/2 = room, in the form that does not cancel
        return 2.0 * room / (speed + math.sqrt(speed * speed + 2.0 * push * room))
    if speed > 0.0:
        return room / speed
    return math.inf


@njit(cache=True, inline="always")
def _earliest(i, lists, events, particles, geometry, held, counters, delta, drag, k, curved, samples, tolerance):
    """Sphere i's earliest event from its anchor (advanced to now by the caller): (time s
    since the epoch, kind, partner), among its listed neighbours and immovable partners. ``curved``: whether any path of the world bends (drag,
    or an acceleration); called with drag, k and curved as constants where none does, so
    the compiler folds the straight paths' tests (_toi)."""
    neighbours, count = lists[9], lists[10]
    stamp, skip = events[4], events[5]
    x, v, a, radius, sigma = particles[0], particles[1], particles[2], particles[4], particles[7]
    # Every prediction of i need reach only as far as its shell: it is predicted again when
    # it leaves. A straight pair's or wall's test has a closed form at any reach; a curved
    # one's root search needs a finite bracket, which the sooner of the two shells' exits
    # gives, and no later than the earliest event found so far (a pair that cannot meet
    # before it is not i's next event: in a pile, where held spheres and falling ones meet
    # on curved paths, the shorter bracket ends most searches at once).
    curved_i = curved and _curved(i, a, k)
    exit_i = _exit_time(i, lists, x, v, a, sigma, delta, curved_i)
    holds = held.deg[i] > 0
    best = exit_i
    kind = LEAVE_SHELL
    other = NONE
    for s in range(count[i]):
        j = neighbours[i, s]
        if holds and held.deg[j] > 0 and held_find(held, KIND_PAIR, min(i, j), max(i, j)) >= 0:
            continue  # a held contact is not tested (they touch: the held solves keep it)
        until = math.inf
        if curved:
            curved_j = _curved(j, a, k)
            if curved_i or curved_j:
                until = min(best, _exit_time(j, lists, x, v, a, sigma, delta, curved_j))
        start, t, work = _toi(KIND_PAIR, min(i, j), max(i, j), x, v, a, radius, sigma, until, k, samples, tolerance,
                              geometry)
        counters[TESTS] += work
        if start + t < best and not _skipped(skip, stamp, i, KIND_PAIR, j):
            best = start + t
            kind = KIND_PAIR
            other = j
    # the immovable partners its shell reaches, tested no further than its shell (the
    # bracket a triangle's root search needs; a later touch is never before leaving it)
    # (kind by kind, as the rows are: the compiler unrolls the constant tuple, and folds
    # each kind's branch of the switch)
    rows = lists[11]
    for partner_kind in IMMOVABLE_KINDS:
        for s in range(lists[12][i]):
            w = rows[i, s, 1]
            if rows[i, s, 0] != partner_kind or (holds and held_find(held, partner_kind, i, w) >= 0):
                continue
            start, t, work = _toi(partner_kind, i, w, x, v, a, radius, sigma, exit_i, k, samples, tolerance, geometry)
            counters[TESTS] += work
            if start + t < best and not _skipped(skip, stamp, i, partner_kind, w):
                best = start + t
                kind = partner_kind
                other = w
    return best, kind, other


@njit(cache=True, inline="always")
def _predict(i, now, lists, events, particles, method, geometry, held, counters, shell, heap_size):
    """Sphere i's one event from ``now`` (s since the epoch): leaving its shell, or its
    earliest contact with a neighbour or an immovable partner of a kind the calendar takes
    (the engine's swept tests through the collider switch, from the anchors); filed in
    the heap of the first ``heap_size`` slots (0: not yet a heap)."""
    period = lists[4]
    when, what, partner, partner_stamp, stamp, heap, where = (events[0], events[1], events[2], events[3], events[4],
                                                              events[6], events[7])
    x, v, a, sigma = particles[0], particles[1], particles[2], particles[7]
    drag, k, samples, tolerance = method[3], method[4], method[6], method[7]
    delta, curved = shell[0], shell[1]
    # i's anchor to now (in the box on a periodic axis): a pair's swept test starts at the
    # later anchor, and takes the image of the separation there, which must be the image
    # of now, when the neighbours are within the lists' reach (an anchor from long ago may
    # see the pair through another image)
    if curved:
        advance_particle(x, v, a, sigma, i, now, EXACT, drag, k)
    else:
        advance_particle(x, v, a, sigma, i, now, EXACT, 1.0, 0.0)
    for d in range(3):
        if period[d] > 0.0:
            x[i, d] -= period[d] * math.floor((x[i, d] - lists[1][d]) / period[d])
    if curved:
        best, kind, other = _earliest(i, lists, events, particles, geometry, held, counters, delta, drag, k, True,
                                      samples, tolerance)
    else:
        best, kind, other = _earliest(i, lists, events, particles, geometry, held, counters, delta, 1.0, 0.0, False,
                                      samples, tolerance)
    when[i] = max(best, now)  # (a rounded root a hair before now is now: the calendar's time never runs back)
    what[i] = kind
    partner[i] = other
    partner_stamp[i] = stamp[other] if kind == KIND_PAIR else 0
    if heap_size > 0:
        _heap_fix(heap, where, when, i, heap_size)


@kernel
def _build(lists, events, particles, method, geometry, held, counters, shell) -> int:
    """Calendar.build: DONE, or GROW_LISTS or GROW_PARTNERS (nothing predicted) if a list
    overflows."""
    list_delta = shell[2]
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
        m = _scan(lists, radius, list_delta, i, lists[9][i])
        if m < 0:
            return GROW_LISTS
        lists[10][i] = m
        if not _list_immovables(lists, radius, list_delta, geometry, i):
            return GROW_PARTNERS
    for i in range(n):
        _predict(i, 0.0, lists, events, particles, method, geometry, held, counters, shell, 0)
    for i in range(n):  # one at a time: the first i + 1 slots are a heap
        heap[i] = i
        where[i] = i
        _heap_fix(heap, where, when, i, i + 1)
    return DONE


@kernel
def _expire_skips(lists, events, particles, method, geometry, held, counters, shell, now) -> None:
    """Calendar.expire_skips: every sphere with a skip still current forgets its skips
    and is predicted again from ``now``."""
    stamp, skip = events[4], events[5]
    n = stamp.shape[0]
    for i in range(n):
        current = False
        for s in range(SKIPS):
            if skip[i, s, SKIP_KIND] != NONE and _skipped(skip, stamp, i, skip[i, s, SKIP_KIND], skip[i, s, SKIP_OTHER]):
                current = True
            skip[i, s, SKIP_KIND] = NONE
        if current:
            _predict(i, now, lists, events, particles, method, geometry, held, counters, shell, n)


@kernel
def _renew(lists, events, particles, method, geometry, held, counters, shell, now, spheres, x_new, v_new,
           a_new) -> None:
    """Calendar.renew: each sphere of ``spheres`` anchored at ``now`` with x_new, v_new,
    a_new (N, 3) (its rows), its contact counter moved on, and predicted again."""
    x, v, a, sigma = particles[0], particles[1], particles[2], particles[7]
    stamp = events[4]
    n = stamp.shape[0]
    for s in range(spheres.shape[0]):
        i = spheres[s]
        for d in range(3):
            x[i, d] = x_new[i, d]
            v[i, d] = v_new[i, d]
            a[i, d] = a_new[i, d]
        sigma[i] = now
        stamp[i] += 1
    for s in range(spheres.shape[0]):
        _predict(spheres[s], now, lists, events, particles, method, geometry, held, counters, shell, n)


@kernel
def _run(lists, events, particles, method, geometry, held, contacts, counters, changed, until, cap, most_events,
         work_budget, shell) -> int:
    """Calendar.run's loop (its statuses, and GROW_LISTS before any change)."""
    list_delta = shell[2]
    centre, head, nxt, prv, cell = lists[0], lists[5], lists[6], lists[7], lists[8]
    when, what, partner, partner_stamp, stamp, skip, heap = (events[0], events[1], events[2], events[3], events[4],
                                                             events[5], events[6])
    kinds, others, resolved, tally = events[8], events[9], events[10], events[12]
    x, v, a, radius, sigma = particles[0], particles[1], particles[2], particles[4], particles[7]
    drag, k, samples, tolerance, step_end = method[3], method[4], method[6], method[7], method[1]
    n = heap.shape[0]
    while n > 0:
        status = SKIPPED
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
        again = NONE  # a second sphere whose path the event changed (a pair's partner)
        if kind == LEAVE_SHELL:
            old0, old1, old2 = centre[i, 0], centre[i, 1], centre[i, 2]
            advance_particle(x, v, a, sigma, i, now, EXACT, drag, k)  # (the path stays: its anchor is its flow)
            for d in range(3):  # the new centre: where i is now (on a periodic axis, in the box)
                c = x[i, d]
                if lists[4][d] > 0.0:
                    c -= lists[4][d] * math.floor((c - lists[1][d]) / lists[4][d])
                centre[i, d] = c
            # (its immovable partners first: a list that overflows leaves the others as they were)
            if not _list_immovables(lists, radius, list_delta, geometry, i):
                centre[i, 0], centre[i, 1], centre[i, 2] = old0, old1, old2
                return GROW_PARTNERS
            if not _relist(lists, radius, list_delta, i, events[11]):
                centre[i, 0], centre[i, 1], centre[i, 2] = old0, old1, old2
                return GROW_LISTS
            counters[EVENTS] += 1
            tally[0] += 1
            _unlink(head, nxt, prv, cell[i], i)
            cell[i] = _cell_of(lists, i)
            _link(head, nxt, prv, cell[i], i)
        elif kind == KIND_PAIR:
            j = partner[i]
            if stamp[j] == partner_stamp[i]:  # (else j's path changed since: i is predicted again)
                if counters[CONTACTS] >= cap:
                    return CAPPED
                if not held_room(held, min(i, j), max(i, j)):
                    return GROW_HELD
                counters[EVENTS] += 1
                status = resolve_contact(KIND_PAIR, min(i, j), max(i, j), now, particles, method, geometry, held,
                                         contacts, counters, CONTACTS, RAPID, changed, work_budget)
                if status == SKIPPED:
                    _remember_skip(skip, stamp, i, KIND_PAIR, j)
                    _remember_skip(skip, stamp, j, KIND_PAIR, i)
                again = j
            else:  # (j was predicted again when its counter moved)
                counters[EVENTS] += 1
                changed[0] = 0
        else:  # an immovable partner: with every other i meets at the same instant (as the time-ordered loop)
            j = partner[i]
            if counters[CONTACTS] >= cap:
                return CAPPED
            if not held_room(held, i, -1):
                return GROW_HELD
            counters[EVENTS] += 1
            kinds[0] = kind
            others[0] = j
            met = 1
            rows = lists[11]
            for s in range(lists[12][i]):  # (i's shell lists every immovable partner it can meet)
                partner_kind, w = rows[i, s, 0], rows[i, s, 1]
                if ((partner_kind == kind and w == j) or met >= AT_ONE_INSTANT_CANDIDATES
                        or _skipped(skip, stamp, i, partner_kind, w)
                        or (held.deg[i] > 0 and held_find(held, partner_kind, i, w) >= 0)):
                    continue
                start, t, work = _toi(partner_kind, i, w, x, v, a, radius, sigma,
                                      now + 2.0 * SAME_INSTANT * step_end, k, samples, tolerance, geometry)
                counters[TESTS] += work
                if start + t <= now + SAME_INSTANT * step_end:
                    kinds[met] = partner_kind
                    others[met] = w
                    met += 1
            if met > 1:
                status = resolve_at_one_instant(kinds, others, met, i, now, particles, method, geometry, held, contacts,
                                                counters, CONTACTS, RAPID, changed, work_budget, resolved)
                if status == SKIPPED:  # i unchanged: what was judged not to approach is skipped, the
                    # rest predicted again (the time-ordered loop keeps them queued)
                    for m in range(met):
                        if resolved[m] != 0:
                            _remember_skip(skip, stamp, i, kinds[m], others[m])
            else:
                status = resolve_contact(kind, i, j, now, particles, method, geometry, held, contacts, counters,
                                         CONTACTS, RAPID, changed, work_budget)
                if status == SKIPPED:
                    _remember_skip(skip, stamp, i, kind, j)
        if kind != LEAVE_SHELL:
            # every sphere whose path the contact changed (a held solve's reach) takes a new counter
            for s in range(changed[0]):
                stamp[changed[1 + s]] += 1
        # one place predicts (the prediction is inlined, and every copy of it costs the
        # loop's instruction cache: measured 13 % on the gas with five): i, a pair's
        # partner, then the other spheres a held solve changed
        extra = changed[0] if kind != LEAVE_SHELL else 0
        for q in range(2 + extra):
            p = i if q == 0 else (again if q == 1 else changed[q - 1])
            if p == NONE or (q >= 2 and (p == i or p == again)):
                continue
            _predict(p, now, lists, events, particles, method, geometry, held, counters, shell, n)
        if kind != LEAVE_SHELL and status != SKIPPED:
            tally[1] += 1
        if kind != LEAVE_SHELL and status == OUT_OF_WORK:
            return RESTING_BUDGET
    return DONE
