"""Resting contact: spheres lying on a wall or on each other.

An impulse solver alone cannot hold a ball on a floor: with restitution c < 1 it bounces
ever lower (infinitely many bounces in finite time) and with a step-sized approach
speed (Euler) it jitters forever. The rule, applied identically under both orderings:

1. A contact is *resting* only where something presses it: its relative acceleration
   along the normal pushes the two together (a_n < 0: gravity, or a held neighbour), and
   it closes no faster than that acceleration adds in a fraction of a step,
   |a_n|·dt·(rest_fraction + f), with f = 1.5 for the two Euler integrators, whose
   straight paths arrive with about one step of acceleration, and 0 otherwise. The
   threshold scales with the scene (its accelerations and dt), and a contact nothing
   presses never rests: an e = 1 gas keeps its energy at any speed. A resting contact
   is resolved with restitution 0 (normal relative velocity set to 0) and *held*.
2. A held contact removes the part of the particles' acceleration that would push them
   into each other (a frictionless constraint): accelerations are projected by a
   projected Gauss–Seidel solve of  (a_a - a_b)·n >= 0,  lambda >= 0,  complementary,
   weighted by inverse masses (walls and immovable spheres take no share).
3. Held contacts are not swept-tested (they are touching by definition); they persist
   from step to step until the particle takes an impulse (all its held contacts are
   released and swept-tested again, so a knock into the floor is itself resolved), or
   the solve gives lambda = 0 (the acceleration pulls it away), or the gap exceeds the
   contact tolerance.

Hence a resting ball costs no event per step and stays exactly at its height.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def rests(closing: float, rel_acc: float, dt: float, step_factor: float, fraction: float) -> bool:
    """The resting rule (rule 1 above), the one place it is decided.

    closing: approach speed along the normal (m/s, >= 0); rel_acc: relative acceleration
    along the normal (m/s², < 0 when it presses the contact); dt: the step (s);
    step_factor: the integrator's f; fraction: Settings.rest_fraction.
    """
    return rel_acc < 0.0 and closing <= -rel_acc * dt * (step_factor + fraction)


# Separation speeds below this fraction of |a_n|·dt are rounding, not separation.
ROUNDING_FRACTION = 1e-9


@njit(cache=True)
def pressed_closing(closing: float, rel_acc: float, dt: float) -> float:
    """The closing speed to judge a contact by (m/s): 0 for a rounding-sized separation
    (below ROUNDING_FRACTION·|a_n|·dt) while an acceleration presses the two together.

    A swept test finds such a contact at the instant the pair stops separating, but its
    time rounds to the anchor, where the velocity still points (by ~1e-16 m/s) away: taken
    as separating, the contact would be dropped and, with nothing re-predicted, the sphere
    would fall through what it rests on for the rest of the step.
    """
    if rel_acc < 0.0 and closing < 0.0 and -closing <= -rel_acc * dt * ROUNDING_FRACTION:
        return 0.0
    return closing


# A held contact: ("wall", particle, wall) or ("pair", a, b) with a < b.
WallKey = tuple[str, int, int]


def solve_accelerations(free_accel: np.ndarray, inverse_mass: np.ndarray, positions: np.ndarray,
                        held: dict[tuple, np.ndarray], iterations: int = 200,
                        tolerance: float = 1e-15) -> tuple[np.ndarray, dict[tuple, float], int]:
    """Accelerations (N, 3) that satisfy every held contact, each contact's lambda, and the
    work done (sweeps × contacts, counted against Settings.max_resting_work_per_step).

    free_accel: (N, 3) accelerations without contacts (m/s²). held maps a key to the
    wall normal (3,) for wall contacts; pair normals are taken from ``positions``.
    """
    accel = free_accel.copy()
    if not held:
        return accel, {}, 0
    keys = list(held)
    normals = []
    for key in keys:
        if key[0] == "wall":
            normals.append(held[key])
        else:
            d = positions[key[1]] - positions[key[2]]
            normals.append(d / np.linalg.norm(d))
    lam = np.zeros(len(keys))
    scale = max(1.0, float(np.abs(free_accel).max()))
    sweeps = 0
    for _ in range(iterations):
        sweeps += 1
        worst = 0.0
        for c, key in enumerate(keys):
            n = normals[c]
            i = key[1]
            if key[0] == "wall":
                w_i, w_j = inverse_mass[i], 0.0
                rel = float(accel[i] @ n)
            else:
                j = key[2]
                w_i, w_j = inverse_mass[i], inverse_mass[j]
                rel = float((accel[i] - accel[j]) @ n)
            if w_i + w_j == 0.0:
                continue
            new = max(lam[c] - rel / (w_i + w_j), 0.0)
            delta = new - lam[c]
            if delta != 0.0:
                lam[c] = new
                accel[i] += (w_i * delta) * n
                if key[0] == "pair":
                    accel[key[2]] -= (w_j * delta) * n
            if rel < 0.0 and lam[c] > 0.0:
                worst = max(worst, -rel)
        if worst <= tolerance * scale:
            break
    # clean tiny residuals along held normals so a resting particle does not creep
    for c, key in enumerate(keys):
        if lam[c] > 0.0 and key[0] == "wall":
            n = normals[c]
            i = key[1]
            along = float(accel[i] @ n)
            if along < 0.0:
                accel[i] -= along * n
    return accel, {key: float(lam[c]) for c, key in enumerate(keys)}, sweeps * len(keys)
