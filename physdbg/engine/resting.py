"""Resting contact: spheres lying on a wall or on each other.

An impulse solver alone cannot hold a ball on a floor: with restitution c < 1 it bounces
ever lower (infinitely many bounces in finite time) and with a step-sized approach
speed (Euler) it jitters forever. The rule, applied identically under both orderings:

1. A contact whose closing speed is at most ``rest_speed`` (plus, for the two Euler
   integrators whose straight paths arrive with one step of acceleration, |a_n|·dt) is
   *resting*: it is resolved with restitution 0 (normal relative velocity set to 0)
   and the contact is *held*.
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

# A held contact: ("wall", particle, wall) or ("pair", a, b) with a < b.
WallKey = tuple[str, int, int]


def solve_accelerations(free_accel: np.ndarray, inverse_mass: np.ndarray, positions: np.ndarray,
                        held: dict[tuple, np.ndarray], iterations: int = 200,
                        tolerance: float = 1e-15) -> tuple[np.ndarray, dict[tuple, float]]:
    """Accelerations (N, 3) that satisfy every held contact, and each contact's lambda.

    free_accel: (N, 3) accelerations without contacts (m/s²). held maps a key to the
    wall normal (3,) for wall contacts; pair normals are taken from ``positions``.
    """
    accel = free_accel.copy()
    if not held:
        return accel, {}
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
    for _ in range(iterations):
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
    return accel, {key: float(lam[c]) for c, key in enumerate(keys)}
