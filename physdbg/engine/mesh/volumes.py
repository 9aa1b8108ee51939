"""Bounding-volume tests of the mesh BVH's nodes (numba): sphere, AABB and OBB, plus the
convex hulls' early-out. Each takes world-frame volumes (``mesh.descent.posed``); touching
counts as meeting (a volume may only ever be too generous, never too tight)."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..jit import borrowing

PARALLEL_GUARD = 1e-12  # added to |R_ij| in the OBB test (Ericson): near-parallel axes stay conservative


@njit(cache=True, inline="always")
def separating_axes_meet(t0, t1, t2, r00, r01, r02, r10, r11, r12, r20, r21, r22, ea0, ea1, ea2, eb0, eb1, eb2) -> bool:
    """The separating-axis test of two oriented boxes A and B, the one rule of both OBB tests
    (obbs_meet; the engine's walk, colliders/mesh._box_meets_obb): t (m) is B's centre less
    A's in A's axes, r_ij = a_i · b_j, ea, eb the half extents (m). The 3 + 3 face axes and
    the 9 edge-edge crosses (Gottschalk; Ericson 4.4.1), each |r_ij| grown by PARALLEL_GUARD
    so that near-parallel axes stay conservative. True when no axis separates them."""
    g = PARALLEL_GUARD
    a00, a01, a02 = abs(r00) + g, abs(r01) + g, abs(r02) + g
    a10, a11, a12 = abs(r10) + g, abs(r11) + g, abs(r12) + g
    a20, a21, a22 = abs(r20) + g, abs(r21) + g, abs(r22) + g
    # A's axes
    if abs(t0) > ea0 + eb0 * a00 + eb1 * a01 + eb2 * a02:
        return False
    if abs(t1) > ea1 + eb0 * a10 + eb1 * a11 + eb2 * a12:
        return False
    if abs(t2) > ea2 + eb0 * a20 + eb1 * a21 + eb2 * a22:
        return False
    # B's axes
    if abs(t0 * r00 + t1 * r10 + t2 * r20) > ea0 * a00 + ea1 * a10 + ea2 * a20 + eb0:
        return False
    if abs(t0 * r01 + t1 * r11 + t2 * r21) > ea0 * a01 + ea1 * a11 + ea2 * a21 + eb1:
        return False
    if abs(t0 * r02 + t1 * r12 + t2 * r22) > ea0 * a02 + ea1 * a12 + ea2 * a22 + eb2:
        return False
    # A_i x B_j
    if abs(t2 * r10 - t1 * r20) > ea1 * a20 + ea2 * a10 + eb1 * a02 + eb2 * a01:
        return False
    if abs(t2 * r11 - t1 * r21) > ea1 * a21 + ea2 * a11 + eb0 * a02 + eb2 * a00:
        return False
    if abs(t2 * r12 - t1 * r22) > ea1 * a22 + ea2 * a12 + eb0 * a01 + eb1 * a00:
        return False
    if abs(t0 * r20 - t2 * r00) > ea0 * a20 + ea2 * a00 + eb1 * a12 + eb2 * a11:
        return False
    if abs(t0 * r21 - t2 * r01) > ea0 * a21 + ea2 * a01 + eb0 * a12 + eb2 * a10:
        return False
    if abs(t0 * r22 - t2 * r02) > ea0 * a22 + ea2 * a02 + eb0 * a11 + eb1 * a10:
        return False
    if abs(t1 * r00 - t0 * r10) > ea0 * a10 + ea1 * a00 + eb1 * a22 + eb2 * a21:
        return False
    if abs(t1 * r01 - t0 * r11) > ea0 * a11 + ea1 * a01 + eb0 * a22 + eb2 * a20:
        return False
    if abs(t1 * r02 - t0 * r12) > ea0 * a12 + ea1 * a02 + eb0 * a21 + eb1 * a20:
        return False
    return True


@borrowing
def spheres_meet(ca, ra, i, cb, rb, j):
    """Do sphere i of (ca (M, 3), ra (M,)) and sphere j of (cb, rb) meet?"""
    d = 0.0
    for c in range(3):
        d += (ca[i, c] - cb[j, c]) ** 2
    r = ra[i] + rb[j]
    return d <= r * r


@borrowing
def aabbs_meet(lo_a, hi_a, i, lo_b, hi_b, j):
    """Do box i of (lo_a, hi_a) (M, 3) and box j of (lo_b, hi_b) meet?"""
    for c in range(3):
        if lo_a[i, c] > hi_b[j, c] or lo_b[j, c] > hi_a[i, c]:
            return False
    return True


@borrowing
def obbs_meet(ca, axes_a, half_a, i, cb, axes_b, half_b, j):
    """Separating-axis test of two oriented boxes (Gottschalk; Ericson, Real-Time Collision
    Detection 4.4.1): box i of (centres (M, 3), axes (M, 3, 3) rows unit, half extents
    (M, 3)) against box j; the 3 + 3 face axes and the 9 edge-edge cross axes."""
    r00 = axes_a[i, 0, 0] * axes_b[j, 0, 0] + axes_a[i, 0, 1] * axes_b[j, 0, 1] + axes_a[i, 0, 2] * axes_b[j, 0, 2]
    r01 = axes_a[i, 0, 0] * axes_b[j, 1, 0] + axes_a[i, 0, 1] * axes_b[j, 1, 1] + axes_a[i, 0, 2] * axes_b[j, 1, 2]
    r02 = axes_a[i, 0, 0] * axes_b[j, 2, 0] + axes_a[i, 0, 1] * axes_b[j, 2, 1] + axes_a[i, 0, 2] * axes_b[j, 2, 2]
    r10 = axes_a[i, 1, 0] * axes_b[j, 0, 0] + axes_a[i, 1, 1] * axes_b[j, 0, 1] + axes_a[i, 1, 2] * axes_b[j, 0, 2]
    r11 = axes_a[i, 1, 0] * axes_b[j, 1, 0] + axes_a[i, 1, 1] * axes_b[j, 1, 1] + axes_a[i, 1, 2] * axes_b[j, 1, 2]
    r12 = axes_a[i, 1, 0] * axes_b[j, 2, 0] + axes_a[i, 1, 1] * axes_b[j, 2, 1] + axes_a[i, 1, 2] * axes_b[j, 2, 2]
    r20 = axes_a[i, 2, 0] * axes_b[j, 0, 0] + axes_a[i, 2, 1] * axes_b[j, 0, 1] + axes_a[i, 2, 2] * axes_b[j, 0, 2]
    r21 = axes_a[i, 2, 0] * axes_b[j, 1, 0] + axes_a[i, 2, 1] * axes_b[j, 1, 1] + axes_a[i, 2, 2] * axes_b[j, 1, 2]
    r22 = axes_a[i, 2, 0] * axes_b[j, 2, 0] + axes_a[i, 2, 1] * axes_b[j, 2, 1] + axes_a[i, 2, 2] * axes_b[j, 2, 2]
    dx = cb[j, 0] - ca[i, 0]
    dy = cb[j, 1] - ca[i, 1]
    dz = cb[j, 2] - ca[i, 2]
    t0 = dx * axes_a[i, 0, 0] + dy * axes_a[i, 0, 1] + dz * axes_a[i, 0, 2]
    t1 = dx * axes_a[i, 1, 0] + dy * axes_a[i, 1, 1] + dz * axes_a[i, 1, 2]
    t2 = dx * axes_a[i, 2, 0] + dy * axes_a[i, 2, 1] + dz * axes_a[i, 2, 2]
    return separating_axes_meet(t0, t1, t2, r00, r01, r02, r10, r11, r12, r20, r21, r22, half_a[i, 0], half_a[i, 1],
                                half_a[i, 2], half_b[j, 0], half_b[j, 1], half_b[j, 2])


@borrowing
def _a_face_separates(normals, offsets, points):
    """Is every one of ``points`` (K, 3) strictly outside one face plane (normals (H, 3),
    offsets (H,): n·x ≤ offset inside)? Each plane stops at the first point inside it."""
    for h in range(normals.shape[0]):
        outside = True
        for k in range(points.shape[0]):
            if normals[h, 0] * points[k, 0] + normals[h, 1] * points[k, 1] + normals[h, 2] * points[k, 2] \
                    <= offsets[h]:
                outside = False
                break
        if outside:
            return True
    return False


def hull_test_work(faces_a: int, corners_a: int, faces_b: int, corners_b: int) -> int:
    """Plane-point products the hulls' early-out may take at most (faces of one × corners of the other, both ways)."""
    return faces_a * corners_b + faces_b * corners_a


def hulls_apart(normals_a: np.ndarray, offsets_a: np.ndarray, points_a: np.ndarray, normals_b: np.ndarray,
                offsets_b: np.ndarray, points_b: np.ndarray) -> bool:
    """Does a face plane of one convex hull (n·x ≤ offset inside; normals (H, 3), offsets
    (H,), corners (K, 3), world frame) have every corner of the other strictly outside?
    Face axes only: "apart" is certain, "not apart" may still be apart (an early-out)."""
    return bool(_a_face_separates(normals_a, offsets_a, points_b) or _a_face_separates(normals_b, offsets_b, points_a))
