"""Sleeping spheres: a pile that has come to rest costs nothing until something disturbs it.

An exact pile under rain never rests on its own (docs/benchmarks.md, "fourth session"):
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
its stats (StepStats, the recording's /physdbg/stats). Periodic boxes are not supported
(a scene that asks for both is refused): their gaps need the minimum image, and their
scenes (gases) have no gravity to rest under.
"""

from __future__ import annotations

import math

import numpy as np

from ..events import KIND_PAIR
from .colliders.kinds import partner_sphere
from .jit import kernel
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


def woken_by_impact(rows: np.ndarray, asleep: np.ndarray, sleep_speed: float) -> np.ndarray:
    """Rule 2: the sleeping spheres this step's contact rows (events.CONTACT_ROW) hit
    closing faster than sleep_speed (m/s); int64 indices, sorted, unique."""
    if rows.shape[0] == 0:
        return np.zeros(0, np.int64)
    pair = rows["kind"] == KIND_PAIR
    fast = pair & (rows["closing_speed"] > sleep_speed)
    a = rows["a"][fast].astype(np.int64)
    b = rows["other"][fast].astype(np.int64)
    hit = np.concatenate((a[asleep[a] & ~asleep[b]], b[asleep[b] & ~asleep[a]]))
    return np.unique(hit)


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


def touching(pairs: np.ndarray, x: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """The pairs (P, 2) whose spheres touch (gap <= SUPPORT_GAP·(r_i + r_j)) at positions x."""
    if pairs.shape[0] == 0:
        return pairs
    i, j = pairs[:, 0], pairs[:, 1]
    reach = (1.0 + SUPPORT_GAP) * (radius[i] + radius[j])
    d = x[i] - x[j]
    return pairs[np.einsum("ij,ij->i", d, d) <= reach * reach]


def supports(pairs: np.ndarray, x: np.ndarray, down: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The touching pairs as (upper, lower) edges: lower is below upper along upper's
    ``down`` (N, 3) unit (its free acceleration's direction; 0 when it has none)."""
    i, j = pairs[:, 0], pairs[:, 1]
    d = x[j] - x[i]
    j_below = np.einsum("ij,ij->i", d, down[i]) > 0.0
    i_below = np.einsum("ij,ij->i", -d, down[j]) > 0.0
    upper = np.concatenate((i[j_below], j[i_below]))
    lower = np.concatenate((j[j_below], i[i_below]))
    return upper, lower


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

    def end_of_step(self, dt: float, x: np.ndarray, velocities: np.ndarray, radius: np.ndarray,
                    pairs: np.ndarray, disturbed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rules at the end of a step of dt seconds: wake the ``disturbed`` (rule 2,
        int64 indices) and what rests on the awake (rule 3), then rule 1 for the slow whose
        supports all sleep (rule 4). x, velocities: (N, 3) m, m/s at the step's end (the
        new sleepers' velocities are zeroed in place); radius (N,) m; pairs: (P, 2) every
        candidate pair of the step, sleeping ones included. Returns (fell asleep, woke),
        int64 indices."""
        asleep = self.asleep
        near = touching(pairs, x, radius)
        upper, lower = supports(near, x, self.down)
        # rule 3: a sleeper resting on an awake sphere wakes, and so on up the pile
        waking = np.zeros_like(asleep)
        waking[disturbed[asleep[disturbed]]] = True
        while True:
            awake_below = ~asleep[lower] | waking[lower]
            more = upper[awake_below & asleep[upper] & ~waking[upper]]
            if more.size == 0:
                break
            waking[more] = True
        woke = np.nonzero(waking)[0]
        asleep[woke] = False
        # rule 1, with rule 4: asleep only on sleepers (or walls), so the pile sleeps upwards
        speed2 = np.einsum("ij,ij->i", velocities, velocities)
        slow = self.allowed & ~asleep & ~waking & (speed2 <= self.sleep_speed * self.sleep_speed)
        self.still = np.where(slow, self.still + dt, 0.0)
        ready = slow & (self.still >= self.sleep_time)
        while True:
            blocked = upper[ready[upper] & ~(asleep[lower] | ready[lower])]
            if blocked.size == 0:
                break
            ready[blocked] = False
        fell = np.nonzero(ready)[0]
        asleep[fell] = True
        self.still[fell] = 0.0
        velocities[fell] = 0.0
        return fell, woke
