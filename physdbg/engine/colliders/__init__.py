"""Collider kinds: what a sphere can hit, as one table and one switch.

A contact is sphere ``a`` against a partner of some kind (events.KIND_*): another sphere
(sphere.py) or a wall (plane.py). The engine never branches on a kind itself; it asks

* the table (kinds.py) what a kind is in general: its name, and whether the partner is a
  sphere that moves (``partner_sphere``) or immovable;
* the switch below about its geometry: the swept test, the contact normal, the gap of a
  held contact, the partner's restitution, which partners a re-predicted sphere can meet,
  the narrow phase's candidates and the deepest overlap.

Adding a kind (next: triangle meshes) is one module beside sphere.py and plane.py, its row
in kinds.py, and one branch in each function here (docs/engine.md lists what else a kind
with new data needs). The world's arrays reach the kinds as kernel_args.LoopWalls
(``walls``: the planes, and the periodic axes the sphere pairs use).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...events import KIND_PAIR
from ..jit import borrowing
from . import plane, sphere
from .kinds import KIND_NAMES, KINDS, PARTNER_IS_SPHERE, partner_sphere

__all__ = ["KIND_NAMES", "KINDS", "PARTNER_IS_SPHERE", "partner_sphere", "time_of_impact", "contact_normal",
           "contact_gap", "partner_restitution", "partners_of", "max_overlap", "narrow_candidates",
           "every_candidate"]


@njit(cache=True, inline="always")
def time_of_impact(kind, ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, tolerance,
                   walls):
    """Swept test of (kind, ia, other) on the paths (x, v, a: (N, 3)) from their anchors
    sigma (s): (start, t), the test's start in the step and the time of impact after it
    (s; inf or beyond step_end: none). tolerance (m): the sphere pairs' root tolerance."""
    normals, offsets, half_thickness, two_sided, _restitution, period = walls
    if kind == KIND_PAIR:
        return sphere.time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples,
                                     tolerance, period)
    return plane.time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples,
                                normals, offsets, half_thickness, two_sided)


@njit(cache=True, inline="always")
def contact_normal(kind, x, ia, other, walls):
    """Unit normal (3 floats) from the partner to sphere ia at the anchors."""
    normals, offsets, _half_thickness, two_sided, _restitution, period = walls
    if kind == KIND_PAIR:
        return sphere.normal(x, ia, other, period)
    return plane.normal(x, ia, other, normals, offsets, two_sided)


@borrowing
def contact_gap(kind, x, v, a, radius, ia, other, walls):
    """(gap (m, < 0: overlap), n0, n1, n2, renewed) of a held contact at the anchors: where
    renewed, (n0, n1, n2) is the contact's normal now (a sphere pair turns as it rolls)."""
    normals, offsets, half_thickness, two_sided, _restitution, period = walls
    if kind == KIND_PAIR:
        return sphere.gap(x, radius, ia, other, period)
    return plane.gap(x, v, a, radius, ia, other, normals, offsets, half_thickness, two_sided)


@njit(cache=True, inline="always")
def partner_restitution(kind, other, restitution, walls):
    """The partner's restitution coefficient: restitution (N,) for spheres, the walls' own."""
    wall_restitution = walls[4]  # kernel_args.LoopWalls.restitution
    if kind == KIND_PAIR:
        return restitution[other]
    return wall_restitution[other]


@njit(cache=True, inline="always")
def partners_of(kind, p, box, adj_start, adj, path_lo, path_hi, batch_mark, batch, walls, out) -> int:
    """The candidates of ``kind`` that sphere p's new path must be swept-tested against, as
    rows (a, other) of out (K, 2); returns how many. box (2, 3): the new path's box, also
    p's row of path_lo, path_hi (N, 3), the boxes of every sphere's current path;
    adj_start, adj: the broad phase's partners (CSR); batch_mark (N,): the batch that last
    changed each sphere (batch: this one)."""
    normals, offsets, half_thickness, two_sided, _restitution, period = walls
    if kind == KIND_PAIR:
        return sphere.partners_of(p, box, path_lo, path_hi, adj_start, adj, batch_mark, batch, period, out)
    return plane.partners_of(p, path_lo, path_hi, normals, offsets, half_thickness, two_sided, out)


@borrowing
def max_overlap(x, radius, pairs, walls, ignore_tunnelled):
    """Deepest overlap (m, >= 0) of the candidate sphere pairs (M, 2) and of every sphere
    with every wall (ignore_tunnelled: see plane.deepest)."""
    normals, offsets, half_thickness, two_sided, _restitution, period = walls
    return max(sphere.deepest(x, radius, pairs, period),
               plane.deepest(x, radius, normals, offsets, half_thickness, two_sided, ignore_tunnelled))


def narrow_candidates(kind: int, pairs: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                      walls: tuple) -> tuple[np.ndarray, np.ndarray]:
    """The narrow phase's candidates of ``kind`` at step start, (a (M,), other (M,)) int64:
    the broad phase's sphere pairs (M, 2) whose path boxes lo, hi (N, 3) meet, or the walls
    each path box reaches."""
    normals, offsets, half_thickness, two_sided, _restitution, period = walls
    if kind == KIND_PAIR:
        return sphere.candidates(pairs, lo, hi, period)
    return plane.reachable(lo, hi, normals, offsets, half_thickness, two_sided)


def every_candidate(kind: int, count: int, walls: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Every candidate of ``kind`` among ``count`` spheres, with no broad phase (the slow
    reference loop's): (a (M,), other (M,)) int64, every pair i < j or every sphere–wall."""
    if kind == KIND_PAIR:
        a, other = np.triu_indices(count, 1)
        return a.astype(np.int64), other.astype(np.int64)
    walls_count = walls[0].shape[0]
    return (np.repeat(np.arange(count, dtype=np.int64), walls_count),
            np.tile(np.arange(walls_count, dtype=np.int64), count))
