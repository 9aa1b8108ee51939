"""Mesh partners: spheres against the triangles of fixed meshes, one collider kind (events.KIND_MESH).

A contact's partner ``other`` is a triangle, numbered across every mesh of the scene (the
scene's meshes in order, each mesh's triangles in its file's order: ``mesh_of`` says whose
it is). Triangles are two-sided and immovable (the seed's inverse mass 0): a sphere bounces
off either face, an edge or a corner, whichever is closest at the touch. What the engine asks
about sphere i against triangle t, each function reached through the switch in
``colliders/__init__``: its swept test (``toi.triangle_toi_swept``, along the integrator's
own path), its contact normal and gap (from the closest point, so the normal turns as a
sphere rolls over an edge), which triangles a sphere's box reaches, and the deepest overlap.

Which triangles a box reaches is asked of a BVH over every triangle's box (world frame,
built once: the meshes do not move), walked without a stack in pre-order with skip links
(``preorder``, ``skip``), so that the contact loop, which allocates nothing, can ask it.
What a triangle reads is this kind's group, ``MeshGeometry``, unpacked by ``_unpack`` alone.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..broadphase.bvh import build
from ..jit import borrowing, kernel
from ..mesh.closest import closest_on_triangle
from ..toi import DISCRETE, SWEPT, triangle_toi_sampled, triangle_toi_swept


class MeshGeometry(NamedTuple):
    """This kind's group of the geometry (colliders.geometry_of): corners (T, 3, 3) m (world
    frame, a triangle's corners as rows), mesh_of (T,) int64, restitution (M,) per mesh, and
    the triangles' BVH in pre-order: box_lo, box_hi (Q, 3) m, leaf_triangle (Q,) int64 (-1
    inside the tree), skip (Q,) int64 (the position after a node's subtree)."""

    corners: np.ndarray
    mesh_of: np.ndarray
    restitution: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    leaf_triangle: np.ndarray
    skip: np.ndarray

    @classmethod
    def of(cls, walls) -> MeshGeometry:
        """The group of a scene's meshes (state.Walls.meshes, a state.Meshes)."""
        meshes = walls.meshes
        corners = np.ascontiguousarray(meshes.corners, dtype=np.float64).reshape(-1, 3, 3)
        lo = np.ascontiguousarray(corners.min(axis=1)) if len(corners) else np.zeros((0, 3))
        hi = np.ascontiguousarray(corners.max(axis=1)) if len(corners) else np.zeros((0, 3))
        box_lo, box_hi, leaf, skip = preorder(lo, hi)
        return cls(corners, np.ascontiguousarray(meshes.mesh_of, dtype=np.int64),
                   np.ascontiguousarray(meshes.restitution, dtype=np.float64), box_lo, box_hi, leaf, skip)


GEOMETRY = MeshGeometry  # this kind's group (colliders.geometry_of)


def preorder(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A BVH (SAH) over boxes lo, hi (T, 3) laid out in pre-order: (box_lo, box_hi (Q, 3),
    leaf_triangle (Q,) (-1 inside), skip (Q,): where the walk goes when a node's box is missed)."""
    if lo.shape[0] == 0:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    tree = build(lo, hi, "sah", 1)
    order: list[int] = []
    stack = [tree.root]
    while stack:
        node = stack.pop()
        order.append(node)
        if tree.left[node] >= 0:
            stack.append(int(tree.right[node]))
            stack.append(int(tree.left[node]))
    position = np.empty(tree.size, dtype=np.int64)
    position[order] = np.arange(len(order))
    size = np.ones(tree.size, dtype=np.int64)
    for node in reversed(order):  # subtree sizes, children before parents
        if tree.left[node] >= 0:
            size[node] = 1 + size[tree.left[node]] + size[tree.right[node]]
    nodes = np.array(order, dtype=np.int64)
    leaf = np.where(tree.left[nodes] < 0, tree.order[np.minimum(tree.start[nodes], len(tree.order) - 1)], -1)
    skip = np.arange(len(order), dtype=np.int64) + size[nodes]
    return (np.ascontiguousarray(tree.lo[nodes]), np.ascontiguousarray(tree.hi[nodes]),
            np.ascontiguousarray(leaf, dtype=np.int64), skip)


@njit(cache=True, inline="always")
def _unpack(meshes):
    """The group's fields (MeshGeometry's order), the one place a kernel reads them."""
    return meshes[0], meshes[1], meshes[2], meshes[3], meshes[4], meshes[5], meshes[6]


@njit(cache=True, inline="always")
def count(meshes) -> int:
    """How many triangles."""
    return meshes[0].shape[0]


@njit(cache=True, inline="always")
def restitution(t, meshes) -> float:
    """Triangle t's restitution coefficient: its mesh's."""
    return meshes[2][meshes[1][t]]


@borrowing
def _closest(x, i, corners, t):
    """(q0, q1, q2, feature): the point of triangle t closest to sphere i's centre x[i]."""
    return closest_on_triangle(x[i, 0], x[i, 1], x[i, 2], corners[t, 0, 0], corners[t, 0, 1], corners[t, 0, 2],
                               corners[t, 1, 0], corners[t, 1, 1], corners[t, 1, 2], corners[t, 2, 0],
                               corners[t, 2, 1], corners[t, 2, 2])


@njit(cache=True, inline="always")
def time_of_impact(i, t, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, tolerance, meshes):
    """Swept test of sphere i against triangle t from i's anchor: (start, time), the test's
    start in the step (s) and the time of impact after it (s; inf or beyond the step: none)."""
    corners = meshes[0]
    start = sigma[i]
    horizon = step_end - start
    if detection == SWEPT:
        found, _feature = triangle_toi_swept(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2], a[i, 0], a[i, 1],
                                             a[i, 2], radius[i], corners[t], integrator, k, horizon, tolerance)
    else:
        found, _feature = triangle_toi_sampled(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2], a[i, 0],
                                               a[i, 1], a[i, 2], radius[i], corners[t], integrator, k, horizon,
                                               1 if detection == DISCRETE else samples)
    return start, found


@borrowing
def _away(x, i, corners, t):
    """(d0, d1, d2, length): from triangle t's point closest to sphere i's centre to the centre."""
    q0, q1, q2, _feature = _closest(x, i, corners, t)
    d0 = x[i, 0] - q0
    d1 = x[i, 1] - q1
    d2 = x[i, 2] - q2
    return d0, d1, d2, math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@njit(cache=True, inline="always")
def normal(x, ia, t, meshes):
    """Unit normal (3 floats) from triangle t to sphere a: from the closest point to the
    centre (the face's own normal if the centre lies on the face)."""
    corners = meshes[0]
    d0, d1, d2, length = _away(x, ia, corners, t)
    if length > 0.0:
        return d0 / length, d1 / length, d2 / length
    e0 = corners[t, 1, 0] - corners[t, 0, 0]
    e1 = corners[t, 1, 1] - corners[t, 0, 1]
    e2 = corners[t, 1, 2] - corners[t, 0, 2]
    f0 = corners[t, 2, 0] - corners[t, 0, 0]
    f1 = corners[t, 2, 1] - corners[t, 0, 1]
    f2 = corners[t, 2, 2] - corners[t, 0, 2]
    n0 = e1 * f2 - e2 * f1
    n1 = e2 * f0 - e0 * f2
    n2 = e0 * f1 - e1 * f0
    length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    return n0 / length, n1 / length, n2 / length


@borrowing
def gap(x, radius, i, t, meshes):
    """(gap (m, < 0: overlap), n0, n1, n2, True): the gap from the closest point and the
    normal now (it turns as a sphere rolls over an edge or a corner)."""
    corners = meshes[0]
    d0, d1, d2, length = _away(x, i, corners, t)
    if length == 0.0:
        return -radius[i], 0.0, 0.0, 0.0, False
    return length - radius[i], d0 / length, d1 / length, d2 / length, True


@njit(cache=True, inline="always")
def _box_meets(lo, hi, p, box_lo, box_hi, q) -> bool:
    return (lo[p, 0] <= box_hi[q, 0] and box_lo[q, 0] <= hi[p, 0] and lo[p, 1] <= box_hi[q, 1]
            and box_lo[q, 1] <= hi[p, 1] and lo[p, 2] <= box_hi[q, 2] and box_lo[q, 2] <= hi[p, 2])


@borrowing
def _sift_down(column, root, end):
    while 2 * root + 1 < end:
        child = 2 * root + 1
        if child + 1 < end and column[child, 1] < column[child + 1, 1]:
            child += 1
        if column[root, 1] >= column[child, 1]:
            return
        column[root, 1], column[child, 1] = column[child, 1], column[root, 1]
        root = child


@borrowing
def _sort_triangles(out, m):
    """Sort rows 0..m-1 of out (K, 2) by their triangle (column 1), in place (heapsort:
    the contact loop allocates nothing)."""
    for start in range(m // 2 - 1, -1, -1):
        _sift_down(out, start, m)
    for end in range(m - 1, 0, -1):
        out[0, 1], out[end, 1] = out[end, 1], out[0, 1]
        _sift_down(out, 0, end)


@borrowing
def partners_of(p, path_lo, path_hi, meshes, out) -> int:
    """The triangles (rows (p, t) of out (K, 2)) sphere p's new path must be tested against,
    in the order of their numbers; returns how many: those whose boxes the box of that path
    (row p of path_lo, path_hi) meets, found by the stackless walk. In number order because
    a sphere meets the triangles that share an edge or a corner at one instant, and a tie
    in the contact loop goes to the test made first: the triangle with the lower number,
    however the tree is laid out (as in the reference loop)."""
    _corners, _mesh_of, _restitution, box_lo, box_hi, leaf, skip = _unpack(meshes)
    m = 0
    q = 0
    while q < box_lo.shape[0]:
        if _box_meets(path_lo, path_hi, p, box_lo, box_hi, q):
            if leaf[q] >= 0:
                out[m, 0] = p
                out[m, 1] = leaf[q]
                m += 1
            q += 1
        else:
            q = skip[q]
    _sort_triangles(out, m)
    return m


@kernel
def reachable(lo, hi, meshes):
    """Sphere–triangle candidates (spheres (K,), triangles (K,)) whose boxes meet the
    spheres' path boxes lo, hi (N, 3) (radius included)."""
    n = lo.shape[0]
    total = count(meshes)
    capacity = max(4 * n, 16)
    ip = np.empty(capacity, dtype=np.int64)
    it = np.empty(capacity, dtype=np.int64)
    scratch = np.empty((max(total, 1), 2), dtype=np.int64)
    m = 0
    for i in range(n):
        found = partners_of(i, lo, hi, meshes, scratch)
        if m + found > ip.shape[0]:
            grown = max(2 * ip.shape[0], m + found)
            ip2 = np.empty(grown, dtype=np.int64)
            it2 = np.empty(grown, dtype=np.int64)
            ip2[:m] = ip[:m]
            it2[:m] = it[:m]
            ip = ip2
            it = it2
        for r in range(found):
            ip[m] = i
            it[m] = scratch[r, 1]
            m += 1
    return ip[:m], it[:m]


@borrowing
def deepest(x, radius, meshes, ignore_tunnelled):
    """Deepest overlap (m, >= 0) of any sphere with any triangle. ignore_tunnelled: a centre
    on a triangle (an overlap of a whole radius: it is passing through a thin mesh wall,
    with discrete or sampled detection) is not counted."""
    return deepest_where(x, radius, meshes, ignore_tunnelled)[0]


@borrowing
def deepest_where(x, radius, meshes, ignore_tunnelled):
    """(depth m >= 0, sphere, triangle) of the deepest overlap of a sphere with a
    triangle ((0, -1, -1) when none); ignore_tunnelled as in ``deepest``."""
    corners, _mesh_of, _restitution, box_lo, box_hi, leaf, skip = _unpack(meshes)
    worst = 0.0
    who = -1
    which = -1
    for i in range(x.shape[0]):
        r = radius[i]
        q = 0
        while q < box_lo.shape[0]:
            if (x[i, 0] - r <= box_hi[q, 0] and box_lo[q, 0] <= x[i, 0] + r and x[i, 1] - r <= box_hi[q, 1]
                    and box_lo[q, 1] <= x[i, 1] + r and x[i, 2] - r <= box_hi[q, 2] and box_lo[q, 2] <= x[i, 2] + r):
                t = leaf[q]
                if t >= 0:
                    pen = r - _away(x, i, corners, t)[3]
                    if not (ignore_tunnelled and pen >= r) and pen > worst:
                        worst = pen
                        who = i
                        which = t
                q += 1
            else:
                q = skip[q]
    return worst, who, which
