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
built once), walked without a stack in pre-order with skip links (``preorder``, ``skip``),
so that the contact loop, which allocates nothing, can ask it. What a triangle reads is
this kind's group, ``MeshGeometry``, unpacked by ``_unpack`` alone.

A kinematic mesh (state.Meshes: a prescribed velocity and angular velocity about a pivot)
is placed by the world at each step's start (``place``: its corners then, its pivot then,
and each triangle's box swept over the step, refitted up the same tree): its triangles'
tests run in the mesh's own frame (toi.moving_triangle_toi_swept), its contact normal is
turned with it, and its surface velocity at the contact point enters the impulse
(``surface``). A moving triangle never holds a sphere: every contact with it is the seed's
impulse alone (a resting contact on a moving mesh is not modelled).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..broadphase.bvh import build
from ..jit import borrowing, kernel
from ..mesh.closest import closest_on_triangle
from ..toi import (DISCRETE, SWEPT, in_body_frame, moving_triangle_toi_sampled, moving_triangle_toi_swept,
                   surface_velocity, triangle_toi_sampled, triangle_toi_swept, turned)


class MeshGeometry(NamedTuple):
    """This kind's group of the geometry (colliders.geometry_of): corners (T, 3, 3) m (world
    frame, a triangle's corners as rows), mesh_of (T,) int64, restitution (M,) per mesh, and
    the triangles' BVH in pre-order: box_lo, box_hi (Q, 3) m, leaf_triangle (Q,) int64 (-1
    inside the tree), skip (Q,) int64 (the position after a node's subtree); motion (M, 9)
    per mesh: its pivot at the step's start (m), velocity (m/s), angular velocity (rad/s);
    moving (M,) bool. A kinematic mesh's corners, pivot and boxes are rewritten in place
    at each step's start (``place``); a fixed mesh's never change."""

    corners: np.ndarray
    mesh_of: np.ndarray
    restitution: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    leaf_triangle: np.ndarray
    skip: np.ndarray
    motion: np.ndarray
    moving: np.ndarray

    @classmethod
    def of(cls, walls) -> MeshGeometry:
        """The group of a scene's meshes (state.Walls.meshes, a state.Meshes) at run time 0."""
        meshes = walls.meshes
        corners = np.ascontiguousarray(meshes.corners, dtype=np.float64).reshape(-1, 3, 3)
        lo = np.ascontiguousarray(corners.min(axis=1)) if len(corners) else np.zeros((0, 3))
        hi = np.ascontiguousarray(corners.max(axis=1)) if len(corners) else np.zeros((0, 3))
        box_lo, box_hi, leaf, skip = preorder(lo, hi)
        motion = np.ascontiguousarray(np.hstack([meshes.pivot, meshes.velocity, meshes.angular_velocity])
                                      if len(meshes) else np.zeros((0, 9)))
        return cls(corners.copy(), np.ascontiguousarray(meshes.mesh_of, dtype=np.int64),
                   np.ascontiguousarray(meshes.restitution, dtype=np.float64), box_lo, box_hi, leaf, skip,
                   motion, np.ascontiguousarray(meshes.moving, dtype=np.bool_))


def place(group: tuple, meshes, time: float, span: float) -> int:
    """Put the kinematic meshes of ``group`` (a MeshGeometry as a tuple, rewritten in place)
    where they are at run time ``time`` s: corners and pivots (state.Meshes.placed), and
    each triangle's box swept over the next ``span`` s (its corners then and at the span's
    end, grown by the most a turning corner leaves the chord between them), refitted up
    the tree. Returns how many tree nodes were refitted (0 when no mesh moves)."""
    moving = meshes.moving
    if not moving.any():
        return 0
    corners, _mesh_of, _restitution, box_lo, box_hi, leaf, skip, motion, _moving = group
    now, pivots = meshes.placed(time)
    corners[...] = now
    motion[:, 0:3] = pivots
    later = meshes.placed(time + span)[0] if span > 0 else now
    lo = np.minimum(now.min(axis=1), later.min(axis=1))
    hi = np.maximum(now.max(axis=1), later.max(axis=1))
    # a corner at distance ρ from the turning axis sweeps an arc of angle θ = |ω|·span; the
    # arc leaves its chord by at most ρ(1 - cos(θ/2)) (θ <= π), by ρ past a half turn
    spin = np.linalg.norm(meshes.angular_velocity, axis=1)
    angle = spin * span
    rho = np.zeros(len(meshes))
    for k in np.nonzero(moving & (spin > 0))[0]:
        rho[k] = float(np.linalg.norm(now[meshes.mesh_of == k] - pivots[k], axis=2).max())
    grow = np.where(angle >= np.pi, rho, rho * (1.0 - np.cos(0.5 * np.minimum(angle, np.pi))))
    grow = grow[meshes.mesh_of][:, None]
    return int(_refit(box_lo, box_hi, leaf, skip, np.ascontiguousarray(lo - grow), np.ascontiguousarray(hi + grow)))


@kernel
def _refit(box_lo, box_hi, leaf, skip, lo, hi) -> int:
    """Refit the pre-order tree's boxes bottom-up to the triangles' boxes lo, hi (T, 3): a
    leaf takes its triangle's, an inner node the union of its children (q + 1 and the
    node after that child's subtree). Returns the nodes refitted."""
    n = box_lo.shape[0]
    for q in range(n - 1, -1, -1):
        t = leaf[q]
        if t >= 0:
            for c in range(3):
                box_lo[q, c] = lo[t, c]
                box_hi[q, c] = hi[t, c]
        else:
            left = q + 1
            right = skip[left]
            for c in range(3):
                box_lo[q, c] = min(box_lo[left, c], box_lo[right, c])
                box_hi[q, c] = max(box_hi[left, c], box_hi[right, c])
    return n


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
    """The group's first seven fields (MeshGeometry's order; _motion_of reads the rest)."""
    return meshes[0], meshes[1], meshes[2], meshes[3], meshes[4], meshes[5], meshes[6]


@njit(cache=True, inline="always")
def _motion_of(t, meshes):
    """(moving, motion (9,)) of triangle t's mesh."""
    k = meshes[1][t]
    return meshes[8][k], meshes[7][k]


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
    """Swept test of sphere i against triangle t from i's anchor: (start, time, work), the
    test's start in the step (s), the time of impact after it (s; inf or beyond the step:
    none) and its work for the swept-test budget: the passes of the advancement against
    a moving triangle (a fast spin makes each pass short, and a test can take hundreds:
    counted, a step's time stays bounded by the budget), 1 otherwise."""
    corners = meshes[0]
    start = sigma[i]
    horizon = step_end - start
    moving, motion = _motion_of(t, meshes)
    if moving:
        if detection == SWEPT:
            found, _feature, passes = moving_triangle_toi_swept(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2],
                                                                a[i, 0], a[i, 1], a[i, 2], radius[i], corners[t],
                                                                motion, start, integrator, k, horizon, tolerance)
            return start, found, passes
        found, _feature = moving_triangle_toi_sampled(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2],
                                                      a[i, 0], a[i, 1], a[i, 2], radius[i], corners[t], motion,
                                                      start, integrator, k, horizon,
                                                      1 if detection == DISCRETE else samples)
        return start, found, 1
    if detection == SWEPT:
        found, _feature, _passes = triangle_toi_swept(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2], a[i, 0],
                                                      a[i, 1], a[i, 2], radius[i], corners[t], integrator, k, horizon,
                                                      tolerance)
    else:
        found, _feature = triangle_toi_sampled(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2], a[i, 0],
                                               a[i, 1], a[i, 2], radius[i], corners[t], integrator, k, horizon,
                                               1 if detection == DISCRETE else samples)
    return start, found, 1


@borrowing
def _away(x, i, corners, t):
    """(d0, d1, d2, length): from triangle t's point closest to sphere i's centre to the centre."""
    q0, q1, q2, _feature = _closest(x, i, corners, t)
    d0 = x[i, 0] - q0
    d1 = x[i, 1] - q1
    d2 = x[i, 2] - q2
    return d0, d1, d2, math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@njit(cache=True, inline="always")
def normal(x, sigma, ia, t, meshes):
    """Unit normal (3 floats) from triangle t to sphere a at its anchor time sigma[ia]: from
    the closest point to the centre (the face's own normal if the centre lies on the
    face); a moving triangle's is found in its mesh's frame and turned with it."""
    corners = meshes[0]
    moving, motion = _motion_of(t, meshes)
    if moving:
        tau = sigma[ia]
        y0, y1, y2, _r0, _r1, _r2 = in_body_frame(x[ia, 0], x[ia, 1], x[ia, 2], 0.0, 0.0, 0.0, motion, tau)
        q0, q1, q2, _feature = closest_on_triangle(y0, y1, y2, corners[t, 0, 0], corners[t, 0, 1], corners[t, 0, 2],
                                                   corners[t, 1, 0], corners[t, 1, 1], corners[t, 1, 2],
                                                   corners[t, 2, 0], corners[t, 2, 1], corners[t, 2, 2])
        d0, d1, d2 = _turned_with(y0 - q0, y1 - q1, y2 - q2, motion, tau)
    else:
        d0, d1, d2, _length = _away(x, ia, corners, t)
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if length > 0.0:
        return d0 / length, d1 / length, d2 / length
    f0, f1, f2 = _face_normal(corners, t)
    if moving:
        return _turned_with(f0, f1, f2, motion, sigma[ia])
    return f0, f1, f2


@njit(cache=True, inline="always")
def feature(x, sigma, ia, t, meshes) -> int:
    """The feature of triangle t (mesh.closest: FACE, an edge, a corner) closest to sphere
    ia's centre at its anchor time (in a moving mesh's frame)."""
    corners = meshes[0]
    moving, motion = _motion_of(t, meshes)
    y0, y1, y2 = x[ia, 0], x[ia, 1], x[ia, 2]
    if moving:
        y0, y1, y2, _r0, _r1, _r2 = in_body_frame(y0, y1, y2, 0.0, 0.0, 0.0, motion, sigma[ia])
    return closest_on_triangle(y0, y1, y2, corners[t, 0, 0], corners[t, 0, 1], corners[t, 0, 2], corners[t, 1, 0],
                               corners[t, 1, 1], corners[t, 1, 2], corners[t, 2, 0], corners[t, 2, 1],
                               corners[t, 2, 2])[3]


@njit(cache=True, inline="always")
def _turned_with(d0, d1, d2, motion, tau):
    """A direction fixed in a moving mesh's frame at the step's start, as it points at tau."""
    w0, w1, w2 = motion[6], motion[7], motion[8]
    speed = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if speed == 0.0:
        return d0, d1, d2
    return turned(d0, d1, d2, w0 / speed, w1 / speed, w2 / speed, math.cos(speed * tau), math.sin(speed * tau))


@njit(cache=True, inline="always")
def surface(x, sigma, radius, ia, t, n0, n1, n2, meshes):
    """(u0, u1, u2, moving): the velocity (m/s) of triangle t's surface where sphere ia
    touches it along the normal n, at ia's anchor time; (0, 0, 0, False) for a fixed mesh."""
    moving, motion = _motion_of(t, meshes)
    if not moving:
        return 0.0, 0.0, 0.0, False
    u0, u1, u2 = surface_velocity(x[ia, 0] - n0 * radius[ia], x[ia, 1] - n1 * radius[ia], x[ia, 2] - n2 * radius[ia],
                                  motion, sigma[ia])
    return u0, u1, u2, True


@njit(cache=True, inline="always")
def _face_normal(corners, t):
    """Triangle t's unit face normal (3 floats), from its corners' order."""
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
