"""The held-contact store: the contacts held now, as arrays (:class:`HeldContacts`), and
the operations on them: add, find, remove, grow, renumber, list a sphere's contacts.
Each sphere lists its own (``slots``), so finding one is a scan of at most a dozen
entries."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..colliders.kinds import PARTNER_IS_SPHERE, partner_sphere
from ..jit import borrowing


# ----------------------------------------------------------------------------- the store
# HeldContacts.count's slots: the contacts held now, the last solve's id, then those that
# count one step's work (World zeroes them as a step begins): held-solve updates, whole
# clusters solved, held contacts released; then the stop switch (World.request_stop sets
# it, from any thread: the solves and the event loop end at once when it is set), then a
# pinned sphere and its two contacts (PINNED: the run cannot go on past that step)
HELD = 0
SOLVE_ID = 1
STEP_WORK = 2
STEP_WHOLE_SOLVES = 3
STEP_RELEASED = 4
STOP = 5
# a sphere pinned by a prescribed motion against something immovable (solves.pinned_by):
# 1 + the sphere (0: none), then the kind and partner of each of the two contacts
PINNED = 6
PINNED_CONTACTS = 7  # kind, other, kind, other in slots 7..10
COUNT_SLOTS = 11

# The most contacts of one sphere a resolve holds at once: its contacts with immovable
# partners at one instant, solved together (resolve.resolve_at_one_instant). The store
# keeps room for that many before each contact.
AT_ONE_INSTANT = 4


class HeldContacts(NamedTuple):
    """The held contacts of a world, as arrays (capacity C, N spheres, K per sphere).

    kind, a, other: (C,) int64 — a contact as colliders names it: sphere pairs with a < other,
    or sphere a against an immovable partner (a wall); normal: (C, 3) unit, from other to a
    (walls: towards a's side); lam: (C,) acceleration
    multiplier (N: the contact force; kept between steps as the warm start);
    jv: (C,) impulse of the current velocity solve (N·s); target: (C,) separation speed the
    velocity solve must reach (m/s; 0 for held contacts); surface: (C, 2) the partner's
    surface along the normal, its velocity (m/s) and acceleration (m/s²): what the
    contact's relative normal velocity and acceleration are measured from (0 but for a
    moving mesh's triangle, whose surface moves: ``partner_normal_motion``); seen: (C,) int64 id of the last
    solve that used jv; count: (COUNT_SLOTS,) int64 — contacts held, solve id, then this
    step's counts: work done (updates, STEP_WORK), clusters solved whole (_solve_connected,
    STEP_WHOLE_SOLVES), contacts released (STEP_RELEASED), then the stop switch (STOP);
    slots: (N, K) each
    sphere's contact ids; deg: (N,) how many; queue: (C,) the
    worklist; mark: (N,) int64 solve id of the last visit; touched: (N + 1,) spheres visited
    by the current solve, count first; before: (N, 3) each visited sphere's velocity when
    first visited (to tell which ones the solve changed); renew: (N,) int64 id of the last
    solve that released a contact of the sphere (its pair must be swept-tested again);
    place: (N,) int64 the sphere's number in the current connected solve (-1 between
    solves).

    A NamedTuple of arrays, so compiled code takes the whole store as one argument.
    """

    kind: np.ndarray
    a: np.ndarray
    other: np.ndarray
    normal: np.ndarray
    lam: np.ndarray
    jv: np.ndarray
    target: np.ndarray
    surface: np.ndarray
    seen: np.ndarray
    count: np.ndarray
    slots: np.ndarray
    deg: np.ndarray
    queue: np.ndarray
    mark: np.ndarray
    touched: np.ndarray
    before: np.ndarray
    renew: np.ndarray
    place: np.ndarray


def new_held(n: int, capacity: int = 64, per_particle: int = 16) -> HeldContacts:
    """An empty store for ``n`` spheres."""
    return HeldContacts(np.zeros(capacity, np.int64), np.zeros(capacity, np.int64), np.zeros(capacity, np.int64),
                        np.zeros((capacity, 3)), np.zeros(capacity), np.zeros(capacity), np.zeros(capacity),
                        np.zeros((capacity, 2)), np.full(capacity, -1, np.int64), np.zeros(COUNT_SLOTS, np.int64),
                        np.zeros((n, per_particle), np.int64), np.zeros(n, np.int64), np.zeros(capacity, np.int64),
                        np.full(n, -1, np.int64), np.zeros(n + 1, np.int64), np.zeros((n, 3)),
                        np.full(n, -1, np.int64), np.full(n, -1, np.int64))


def renumber_held(h: HeldContacts, old_of_new: np.ndarray, new_of_old: np.ndarray) -> None:
    """Renumber the spheres of the held contacts in place (space_order.py): sphere i is now
    the one that was old_of_new[i] (new_of_old its inverse). A pair whose two ends come
    out the other way round is turned over (a < other, the normal reversed: the same
    contact, its force multiplier unchanged). Contact ids and each sphere's list of them
    keep their order."""
    held = int(h.count[HELD])
    kind, a, other = h.kind[:held], h.a[:held], h.other[:held]
    pair = np.asarray(PARTNER_IS_SPHERE)[kind]
    new_a = new_of_old[a]
    new_other = np.where(pair, new_of_old[np.where(pair, other, 0)], other)
    turn = pair & (new_a > new_other)
    h.a[:held] = np.where(turn, new_other, new_a)
    h.other[:held] = np.where(turn, new_a, new_other)
    h.normal[:held][turn] *= -1.0
    for name in ("slots", "deg", "mark", "renew", "place", "before"):
        rows = getattr(h, name)
        rows[:] = np.take(rows, old_of_new, axis=0)
    visited = int(h.touched[0])
    h.touched[1:visited + 1] = new_of_old[h.touched[1:visited + 1]]


def grow_held(h: HeldContacts) -> HeldContacts:
    """The same contacts with room for more (called when :func:`held_room` said no): twice
    the capacity if the store is full, twice the room per sphere if a sphere's list is.

    Each grows only when it is what ran out: the per-sphere lists are an (N, K) array, and
    doubling K with every doubling of the capacity (as this once did) made it 8 192 wide
    for a pile of 19 000 held contacts, 6.5 GB at 100 000 spheres, when no sphere touches
    more than a dozen others.
    """
    c = h.kind.shape[0]
    k = h.slots.shape[1]
    capacity = 2 * c if h.count[HELD] + AT_ONE_INSTANT > c else c
    per_sphere = 2 * k if h.deg.shape[0] and int(h.deg.max()) + AT_ONE_INSTANT > k else k
    if capacity == c and per_sphere == k:  # asked to grow with room left: grow the store anyway
        capacity = 2 * c
    big = new_held(h.deg.shape[0], capacity, per_sphere)
    for name in ("kind", "a", "other", "normal", "lam", "jv", "target", "surface", "seen"):
        getattr(big, name)[:c] = getattr(h, name)
    big.count[:] = h.count
    big.slots[:, :h.slots.shape[1]] = h.slots
    big.deg[:] = h.deg
    big.mark[:] = h.mark
    big.renew[:] = h.renew
    return big


@borrowing
def held_room(h, a, b) -> bool:
    """Whether AT_ONE_INSTANT more contacts of sphere a, or one of spheres a and b (b = -1:
    an immovable partner), fit without growing."""
    return (h.count[HELD] + AT_ONE_INSTANT <= h.kind.shape[0] and h.deg[a] + AT_ONE_INSTANT <= h.slots.shape[1]
            and (b < 0 or h.deg[b] < h.slots.shape[1]))


@borrowing
def held_find(h, kind, a, other) -> int:
    """The id of held contact (kind, a, other) (pairs with a < other), or -1."""
    for s in range(h.deg[a]):
        c = h.slots[a, s]
        if h.kind[c] == kind and h.a[c] == a and h.other[c] == other:
            return c
    return -1


@borrowing
def held_add(h, kind, a, other, nx, ny, nz) -> int:
    """Hold contact (kind, a, other) with normal n; returns its id (room checked by held_room)."""
    c = h.count[HELD]
    h.kind[c] = kind
    h.a[c] = a
    h.other[c] = other
    h.normal[c, 0] = nx
    h.normal[c, 1] = ny
    h.normal[c, 2] = nz
    h.lam[c] = 0.0
    h.jv[c] = 0.0
    h.target[c] = 0.0
    h.surface[c, 0] = 0.0
    h.surface[c, 1] = 0.0
    h.seen[c] = -1
    h.count[HELD] = c + 1
    h.slots[a, h.deg[a]] = c
    h.deg[a] += 1
    if partner_sphere(kind, other) >= 0:
        h.slots[other, h.deg[other]] = c
        h.deg[other] += 1
    return c


@borrowing
def _unlist(h, p, c):
    for s in range(h.deg[p]):
        if h.slots[p, s] == c:
            h.deg[p] -= 1
            h.slots[p, s] = h.slots[p, h.deg[p]]
            return


@borrowing
def _relist(h, p, old, new):
    for s in range(h.deg[p]):
        if h.slots[p, s] == old:
            h.slots[p, s] = new
            return


@borrowing
def held_remove(h, c) -> None:
    """Release contact c (the last contact takes its id)."""
    _unlist(h, h.a[c], c)
    if partner_sphere(h.kind[c], h.other[c]) >= 0:
        _unlist(h, h.other[c], c)
    last = h.count[HELD] - 1
    if c != last:
        _relist(h, h.a[last], last, c)
        if partner_sphere(h.kind[last], h.other[last]) >= 0:
            _relist(h, h.other[last], last, c)
        h.kind[c] = h.kind[last]
        h.a[c] = h.a[last]
        h.other[c] = h.other[last]
        for k in range(3):
            h.normal[c, k] = h.normal[last, k]
        h.lam[c] = h.lam[last]
        h.jv[c] = h.jv[last]
        h.target[c] = h.target[last]
        h.surface[c, 0] = h.surface[last, 0]
        h.surface[c, 1] = h.surface[last, 1]
        h.seen[c] = h.seen[last]
    h.count[HELD] = last


@borrowing
def contacts_of(h, spheres, n_spheres, out) -> int:
    """The ids of every held contact of ``spheres[:n_spheres]`` into ``out`` (each once,
    in sphere order); returns how many. out must hold h.count[HELD] entries."""
    m = 0
    solve = h.count[SOLVE_ID]
    for s in range(n_spheres):
        p = spheres[s]
        for t in range(h.deg[p]):
            c = h.slots[p, t]
            if h.seen[c] != -(solve + 3):
                h.seen[c] = -(solve + 3)
                out[m] = c
                m += 1
    return m
