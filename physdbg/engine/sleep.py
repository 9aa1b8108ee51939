"""Sleeping spheres: a pile that has come to rest costs nothing until something disturbs it.

An exact pile under rain never rests on its own (docs/benchmarks.md, "A pile: the rules
that let it rest"):
with the held contacts rigid, each impact is passed through the whole held cluster it
reaches and the far contacts separate and meet again (churn); with fast contacts kept
elastic, the bed rattles for ever. Box2D (b2_timeToSleep) and DynamO's sleeping particles
(S. González) answer the same way, and so does this module: a sphere that has been slow
for long enough is frozen, and a frozen sphere is an immovable obstacle (inverse mass 0,
no gravity) until something wakes it. What the engine then solves is the part of the pile
that moves; the swept tests stay exact, so no sphere ever overlaps a sleeping one.

The rules, decided at the end of each step (``Settings.sleep_speed`` v_s > 0 turns them on):

1. **Sleep**: a sphere falls asleep when its speed has been at most v_s at the end of every
   step for ``Settings.sleep_time`` seconds. Its velocity is set to zero: the energy
   removed is at most ½·m·v_s² a sphere (the step's kinetic energy shows it). Only a
   sphere its free acceleration (gravity, after drag) would carry through v_s and back
   in less than ``sleep_time`` can sleep (``can_sleep``): one in free flight is slow
   for less than that, so it never sleeps at the top of its flight; a sphere with no
   free acceleration (a gas, a sphere with gravity_scale 0) never sleeps.
2. **Wake by impact**: a sleeping sphere that a moving one hit in the step closing faster
   than v_s wakes at the step's end. Within that step it was immovable: the impact
   bounced off it as off a wall (its momentum went to the ground, as a pile on a floor
   would pass it on); from the next step on it moves.
3. **Wake what rests on the awake**: a sleeping sphere touching an awake one below it (along
   its gravity) wakes, and so on up: what a woken sphere held up may have to move. (A
   sleeper is held in place for the rest of the step in which its support woke: it floats
   by at most what its support fell in that step, and the swept tests keep every gap open.)
4. **Sleep from the bottom up**: a slow sphere falls asleep only if every sphere it touches
   below it sleeps (or falls asleep with it). So no awake sphere is ever left under a
   sleeping one, where a push from below would jam it between immovable spheres (a
   contact no impulse can satisfy). "Touch" in rules 3–4 is a gap of at most
   SUPPORT_GAP of the two radii (resting, or rattling a fraction of a millimetre high);
   "below" is any way down along the upper sphere's gravity, so a neighbour beside it but
   a hair lower counts: a sphere wedged between two it leans on sleeps after them.

A sphere woken in a step cannot fall asleep in the same step; its slow time starts again.
A held contact whose two ends are both immovable (a sleeping sphere and a wall, another
sleeping sphere, an immovable sphere) is released when the sphere falls asleep: nothing
is left to solve there, and it would hold a contact no swept test then watches.

The counts of each step (spheres asleep at its end, fallen asleep and woken in it) are in
its stats (StepEnd.counts, the recording's /physdbg/stats). Periodic boxes are not supported
(a scene that asks for both is refused): their gaps need the minimum image, and their
scenes (gases) have no gravity to rest under.
"""

from __future__ import annotations

import math

import numpy as np

from .broadphase.grid import bucket_starts
from .colliders.kinds import partner_sphere
from .jit import borrowing, kernel
from .resting import HELD, held_remove


def can_sleep(free_accel: np.ndarray, drag_k: float, sleep_speed: float, sleep_time: float) -> np.ndarray:
    """(N,) bool: the spheres rule 1 may put to sleep.

    free_accel: (N, 3) m/s², each sphere's acceleration with no contact (gravity ×
    gravity_scale; 0 for an immovable one); drag_k: -ln d (1/s; 0 = no drag);
    sleep_speed: v_s (m/s); sleep_time (s).

    A sphere in free flight under acceleration g and drag k is at most v_s fast for at
    most v_s/g on the way up (drag slows it more than g does) plus v_s/(g - k·v_s) on the
    way down (drag slows its fall by at most k·v_s): if that is shorter than sleep_time,
    a sphere slow for sleep_time is not in free flight. If g <= k·v_s it could drift
    slower than v_s for ever, and it never sleeps.
    """
    g = np.sqrt(np.einsum("ij,ij->i", free_accel, free_accel))
    falling = g - drag_k * sleep_speed
    with np.errstate(divide="ignore", invalid="ignore"):
        slow_flight = np.where(falling > 0.0, sleep_speed / np.where(g > 0, g, 1.0)
                               + sleep_speed / np.where(falling > 0.0, falling, 1.0), math.inf)
    return (g > 0.0) & (slow_flight < sleep_time)


@kernel
def release_static(h, inverse_mass) -> int:
    """Release every held contact whose two ends are immovable (inverse_mass 0; a wall
    always is); returns how many. h: the held store (resting.HeldContacts)."""
    released = 0
    c = h.count[HELD] - 1
    while c >= 0:
        b = partner_sphere(h.kind[c], h.other[c])
        if inverse_mass[h.a[c]] == 0.0 and (b < 0 or inverse_mass[b] == 0.0):
            held_remove(h, c)  # the last contact takes id c: already visited
            released += 1
        c -= 1
    return released


# Two spheres touch, for the support rules, when their gap is at most this fraction of the
# sum of their radii (1 mm for two 5 cm spheres): a sphere resting on another, or one
# rattling on it a fraction of a millimetre high.
SUPPORT_GAP = 0.01


@kernel
def split_sleeping(pairs, asleep):
    """(pairs (P, 2) with an awake sphere, pairs whose two spheres sleep), each in the order
    of ``pairs``: two sleeping spheres cannot meet, so the step does not test them."""
    m = pairs.shape[0]
    both = 0
    for t in range(m):
        if asleep[pairs[t, 0]] and asleep[pairs[t, 1]]:
            both += 1
    awake = np.empty((m - both, 2), dtype=np.int64)
    sleeping = np.empty((both, 2), dtype=np.int64)
    na = ns = 0
    for t in range(m):
        if asleep[pairs[t, 0]] and asleep[pairs[t, 1]]:
            sleeping[ns, 0] = pairs[t, 0]
            sleeping[ns, 1] = pairs[t, 1]
            ns += 1
        else:
            awake[na, 0] = pairs[t, 0]
            awake[na, 1] = pairs[t, 1]
            na += 1
    return awake, sleeping


@kernel
def _support_edges(pair_lists, x, radius, down):
    """Every (upper, lower) of the touching pairs of each (P, 2) list in pair_lists: lower is
    below upper along upper's ``down``. As CSR by the lower sphere: (start (N+1,), uppers),
    and the edges in order (upper (E,), lower (E,))."""
    n = x.shape[0]
    total = 0
    for pairs in pair_lists:
        total += 2 * pairs.shape[0]
    upper = np.empty(total, dtype=np.int64)
    lower = np.empty(total, dtype=np.int64)
    e = 0
    for pairs in pair_lists:
        for t in range(pairs.shape[0]):
            i = pairs[t, 0]
            j = pairs[t, 1]
            reach = (1.0 + SUPPORT_GAP) * (radius[i] + radius[j])
            d0 = x[i, 0] - x[j, 0]
            d1 = x[i, 1] - x[j, 1]
            d2 = x[i, 2] - x[j, 2]
            if d0 * d0 + d1 * d1 + d2 * d2 > reach * reach:
                continue
            if -d0 * down[i, 0] + -d1 * down[i, 1] + -d2 * down[i, 2] > 0.0:  # j below i
                upper[e] = i
                lower[e] = j
                e += 1
            if d0 * down[j, 0] + d1 * down[j, 1] + d2 * down[j, 2] > 0.0:  # i below j
                upper[e] = j
                lower[e] = i
                e += 1
    start = bucket_starts(lower[:e], n)  # the counting sort the grid files its boxes with
    fill = start[:-1].copy()
    uppers = np.empty(e, dtype=np.int64)
    for k in range(e):
        uppers[fill[lower[k]]] = upper[k]
        fill[lower[k]] += 1
    return start, uppers, upper[:e], lower[:e]


@borrowing
def _spread_up(stack, top, start, uppers, mark, before, gate):
    """Follow the support edges up (start, uppers: CSR by the lower sphere) from the spheres
    on stack[:top]: every upper sphere u with mark[u] == before and gate[u] flips its mark
    and is followed in turn, so each sphere is pushed at most once (stack (N,)). The stack
    is left empty."""
    while top > 0:
        top -= 1
        s = stack[top]
        for k in range(start[s], start[s + 1]):
            u = uppers[k]
            if mark[u] == before and gate[u]:
                mark[u] = not before
                stack[top] = u
                top += 1


@kernel
def sleep_rules(asleep, still, allowed, down, dt, x, velocities, radius, pair_lists, hit_kind, hit_a, hit_b,
                hit_closing, sleep_speed, sleep_time):
    """The rules at the end of a step of dt seconds (module doc), in place on asleep (N,)
    bool, still (N,) s and velocities (N, 3) m/s (the new sleepers' are zeroed); returns
    (fell asleep, woke), int64 indices, sorted.

    allowed (N,) bool: can_sleep; down (N, 3) unit: each sphere's way down; x (N, 3) m at
    the step's end; radius (N,) m; pair_lists: the step's candidate pairs (P, 2), awake
    and sleeping; hit_kind, hit_a, hit_b, hit_closing: the step's contact rows' kind,
    sphere, partner and closing speed (m/s). A sphere is woken, or kept awake, as soon as
    one reason holds, and each support edge is followed once from each end (a worklist):
    the fixed points the rules define, in O(N + pairs).
    """
    n = asleep.shape[0]
    start, uppers, upper, lower = _support_edges(pair_lists, x, radius, down)
    # rule 2: a sleeper hit by an awake sphere closing faster than sleep_speed
    waking = np.zeros(n, dtype=np.bool_)
    for t in range(hit_kind.shape[0]):
        b = partner_sphere(hit_kind[t], hit_b[t])  # an immovable partner wakes no one
        if b < 0 or not hit_closing[t] > sleep_speed:
            continue
        a = hit_a[t]
        if asleep[a] and not asleep[b]:
            waking[a] = True
        if asleep[b] and not asleep[a]:
            waking[b] = True
    # rule 3: a sleeper resting on an awake (or waking) sphere wakes, and so on up the pile
    stack = np.empty(n, dtype=np.int64)
    top = 0
    for s in range(n):
        if not asleep[s] or waking[s]:
            stack[top] = s
            top += 1
    _spread_up(stack, top, start, uppers, waking, False, asleep)
    top = 0  # _spread_up empties the stack
    woke = np.nonzero(waking)[0]
    for s in woke:
        asleep[s] = False
    # rule 1: slow for sleep_time (a sphere woken now starts again)
    ready = np.zeros(n, dtype=np.bool_)
    limit = sleep_speed * sleep_speed
    for s in range(n):
        v0 = velocities[s, 0]
        v1 = velocities[s, 1]
        v2 = velocities[s, 2]
        if allowed[s] and not asleep[s] and not waking[s] and v0 * v0 + v1 * v1 + v2 * v2 <= limit:
            still[s] += dt
            ready[s] = still[s] >= sleep_time
        else:
            still[s] = 0.0
    # rule 4: only on sleepers (or walls): one not ready below keeps its uppers awake, on up
    for k in range(upper.shape[0]):
        if ready[upper[k]] and not (asleep[lower[k]] or ready[lower[k]]):
            ready[upper[k]] = False
            stack[top] = upper[k]
            top += 1
    _spread_up(stack, top, start, uppers, ready, True, ready)
    fell = np.nonzero(ready)[0]
    for s in fell:
        asleep[s] = True
        still[s] = 0.0
        velocities[s, 0] = 0.0
        velocities[s, 1] = 0.0
        velocities[s, 2] = 0.0
    return fell, woke


class Sleepers:
    """Which spheres sleep, and for how long each has been slow (the run's sleep state).

    asleep: (N,) bool; still: (N,) s each sphere has been at most sleep_speed fast at the
    end of consecutive steps; allowed: (N,) bool, ``can_sleep``; down: (N, 3) unit,
    the direction of each sphere's free acceleration (0 when it has none).
    """

    def __init__(self, free_accel: np.ndarray, drag_k: float, sleep_speed: float, sleep_time: float):
        n = free_accel.shape[0]
        self.sleep_speed = float(sleep_speed)
        self.sleep_time = float(sleep_time)
        self.asleep = np.zeros(n, dtype=np.bool_)
        self.still = np.zeros(n)
        self.allowed = can_sleep(free_accel, drag_k, sleep_speed, sleep_time)
        size = np.sqrt(np.einsum("ij,ij->i", free_accel, free_accel))
        self.down = free_accel / np.where(size > 0, size, 1.0)[:, None]

    @property
    def count(self) -> int:
        return int(np.count_nonzero(self.asleep))

    def renumber(self, old_of_new: np.ndarray) -> None:
        """The spheres renumbered (space_order.py): sphere i is now the one that was old_of_new[i]."""
        for name in ("asleep", "still", "allowed", "down"):
            setattr(self, name, np.take(getattr(self, name), old_of_new, axis=0))

    def wake(self, spheres: np.ndarray) -> None:
        """Wake ``spheres`` (int64 indices) before a step: a kinematic mesh is about to
        reach them (World._wake_where_meshes_move). Their slow time starts again."""
        self.asleep[spheres] = False
        self.still[spheres] = 0.0

    def end_of_step(self, dt: float, x: np.ndarray, velocities: np.ndarray, radius: np.ndarray,
                    pair_lists: tuple[np.ndarray, ...], rows: np.ndarray,
                    carried: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The rules at the end of a step of dt seconds (sleep_rules): x, velocities (N, 3)
        m, m/s at the step's end (the new sleepers' velocities are zeroed in place);
        radius (N,) m; pair_lists: the step's candidate pairs, (P, 2) arrays (awake and
        sleeping); rows: the step's contact rows (events.CONTACT_ROW); carried: (N,) bool,
        the spheres a moving mesh carries, which may not sleep this step (None: none).
        Returns (fell asleep, woke), int64 indices, sorted."""
        # contiguous columns: a field of two or more rows is a strided view, of none or one
        # a contiguous one, and each layout would be a version of its own to compile and load
        kind, a, other, closing = (np.ascontiguousarray(rows[name]) for name in ("kind", "a", "other", "closing_speed"))
        allowed = self.allowed if carried is None else self.allowed & ~carried
        return sleep_rules(self.asleep, self.still, allowed, self.down, dt, x, velocities, radius, pair_lists,
                           kind, a, other, closing, self.sleep_speed, self.sleep_time)
