"""Mesh partners: spheres against the triangles of fixed meshes, one collider kind (events.KIND_MESH).

Why one module of this size: a collider kind is one module (the registry's rule:
the switch reaches each kind's functions in its own module), and the mesh kind has the
most to answer (moving triangles, the tree walks, features); its trees are the scene's
mesh set (mesh/mesh_set.py) and its tests toi.py's.

A contact's partner ``other`` is a triangle, numbered across every mesh of the scene (the
scene's meshes in order, each mesh's triangles in its file's order: ``mesh_of`` says whose
it is). Triangles are two-sided and immovable (the seed's inverse mass 0): a sphere bounces
off either face, an edge or a corner, whichever is closest at the touch. What the engine asks
about sphere i against triangle t, each function reached through the switch in
``colliders/switch.py``: its swept test (``toi.triangle_toi_swept``, along the integrator's
own path), its contact normal and gap (from the closest point, so the normal turns as a
sphere rolls over an edge), which triangles a sphere's box reaches, and the deepest overlap.

Which triangles a box reaches is asked of each mesh's own BVH (SAH over its triangles'
boxes in the frame the mesh has at run time 0, built once by the scene's mesh set,
engine/mesh/mesh_set.py: the tree the views draw), walked without a stack in pre-order with
skip links (``skip``), so that the contact loop, which allocates nothing, can ask it.
What a triangle reads is this kind's group, ``MeshGeometry``, unpacked by ``_unpack``
alone.

A kinematic mesh (state.Meshes: a prescribed velocity and angular velocity about a pivot)
is placed by the world at each step's start (``place``: its corners then, its pivot then,
and the frame change from the world to its run-time-0 frame). Its tree is never refitted:
a box asked of it is carried into its frame instead (``frame_box``: grown by the most the
mesh's motion over the step moves a point relative to it). Its triangles' tests run in the
mesh's own frame (toi.moving_triangle_toi_swept), its contact normal is turned with it,
its surface velocity at the contact point enters the impulse (``surface``), and a held
contact with it is measured from its surface's motion along the normal (``normal_motion``):
a sphere rests on a moving mesh as on a fixed one, and the world keeps it on the surface
at each step's end (resolve.keep_on_moving_partners).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..broadphase.bvh import build_lbvh
from ..jit import borrowing, kernel
from ..mesh.tree import AABB, OBB, SPHERE, VOLUME_NAMES
from ..mesh.volumes import separating_axes_meet
from ..mesh.closest import FACE, closest_on_triangle
from ..mesh.rigid_motion import in_body_frame, surface_acceleration, surface_velocity, turned_with
from .kinds import every_sphere_with  # noqa: F401 (the switch calls it: SWITCH["every_candidate"])
from ..toi import (DISCRETE, SWEPT, moving_triangle_toi_sampled, moving_triangle_toi_swept, triangle_toi_sampled,
                   triangle_toi_swept)


class MeshGeometry(NamedTuple):
    """This kind's group of the geometry (colliders.geometry_of): corners (T, 3, 3) m (world
    frame, a triangle's corners as rows), mesh_of (T,) int64, restitution (M,) per mesh, and
    every mesh's BVH in pre-order, one after another, each in the mesh's run-time-0 frame:
    box_lo, box_hi (Q, 3) m, leaf_triangle (Q,) int64 (the scene's triangle number; -1
    inside a tree), skip (Q,) int64 (the position after a node's subtree), tree_first
    (M + 1,) int64 (where each mesh's tree starts; it ends at the next one's start);
    motion (M, 9) per mesh: its pivot at the step's start (m), velocity (m/s), angular
    velocity (rad/s); moving (M,) bool; frame (M, 22) per mesh for the step: the mesh's
    turn since run time 0 transposed, Rᵀ, at the step's start and at its end (row-major,
    9 + 9), its pivot at run time 0 P₀ (3) and the step's length (s): a world point x at
    run time t is Rᵀ(t)·(x - P(t)) + P₀ in the mesh's run-time-0 frame; parent (Q,) int64:
    each node's parent (a position in the same pre-order; -1 for a root), for the recorded
    search (``search_visits``). A kinematic mesh's corners,
    pivot and frame are rewritten in place at each step's start (``place``); its tree and a
    fixed mesh's whole group never change."""

    corners: np.ndarray
    mesh_of: np.ndarray
    restitution: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    leaf_triangle: np.ndarray
    skip: np.ndarray
    tree_first: np.ndarray
    motion: np.ndarray
    moving: np.ndarray
    frame: np.ndarray
    parent: np.ndarray
    volume: np.ndarray
    node_sphere: np.ndarray
    node_obb: np.ndarray

    @classmethod
    def of(cls, walls, volume: np.ndarray | None = None, trees=None) -> MeshGeometry:
        """The group of a scene's meshes (state.Walls.meshes, a state.Meshes) at run time 0,
        from their trees (the scene's mesh set, state.Meshes.mesh_set: built once, its
        arrays shared by every group); the corners, motions and frames are this group's own,
        for ``place`` to rewrite. volume: (M,) codes (mesh/tree.VOLUME_NAMES) to walk with
        instead of the scene's; trees: another mesh.mesh_set.MeshSet of the same meshes
        (one by another builder, for a test)."""
        meshes = walls.meshes
        trees = meshes.mesh_set if trees is None else trees
        motion = np.ascontiguousarray(np.hstack([meshes.pivot, meshes.velocity, meshes.angular_velocity])
                                      if len(meshes) else np.zeros((0, 9)))
        frame = np.zeros((len(meshes), 22))
        frame[:, [0, 4, 8, 9, 13, 17]] = 1.0  # at run time 0 the world is every mesh's frame
        frame[:, 18:21] = meshes.pivot
        return cls(np.ascontiguousarray(meshes.corners, dtype=np.float64).reshape(-1, 3, 3).copy(),
                   np.ascontiguousarray(meshes.mesh_of, dtype=np.int64),
                   np.ascontiguousarray(meshes.restitution, dtype=np.float64), trees.box_lo, trees.box_hi,
                   trees.leaf_triangle, trees.skip, trees.tree_first, motion,
                   np.ascontiguousarray(meshes.moving, dtype=np.bool_), frame, trees.parent,
                   trees.volume if volume is None else np.ascontiguousarray(volume, dtype=np.int64),
                   trees.node_sphere, trees.node_obb)


def place(group: tuple, meshes, time: float, span: float) -> int:
    """Put the kinematic meshes of ``group`` (a MeshGeometry as a tuple, rewritten in place)
    where they are at run time ``time`` s for a step of ``span`` s: corners and pivots
    (state.Meshes.placed) and each one's frame change (MeshGeometry.frame). Returns how
    many meshes were placed (0 when none moves); no tree is refitted."""
    moving = meshes.moving
    if not moving.any():
        return 0
    corners, motion, frame = group[0], group[8], group[10]
    now, pivots = meshes.placed(time)
    corners[...] = now
    motion[:, 0:3] = pivots
    start, end = meshes.rotations(time), meshes.rotations(time + span)
    for k in np.nonzero(moving)[0]:
        frame[k, 0:9] = start[k].T.reshape(9)
        frame[k, 9:18] = end[k].T.reshape(9)
    frame[:, 21] = span
    return int(np.count_nonzero(moving))


@njit(cache=True, inline="always")
def frame_box(k, l0, l1, l2, h0, h1, h2, meshes):
    """The box (lo0, lo1, lo2, hi0, hi1, hi2) that holds, in mesh k's run-time-0 frame
    (its tree's), every point of the world box (l0, l1, l2)–(h0, h1, h2) as the mesh moves
    through the step: the box itself for a fixed mesh. For a moving one, a point x is at
    Rᵀ(t)(x - P(t)) + P₀ = Rᵀ(t)(x - P_s) + P₀ - Rᵀ(t)·v·(t - s) (P_s: the pivot at the
    step's start s): the first part runs on an arc about the turning axis, inside the box
    of its two ends grown by the arc's sagitta ρ(1 - cos(θ/2)) (2ρ past a half turn), and
    the second is at most |v|·span long. The box's centre is carried so, and the box grown
    by its half diagonal too."""
    moving, motion = meshes[9][k], meshes[8][k]
    if not moving:
        return l0, l1, l2, h0, h1, h2
    f = meshes[10][k]
    z0 = 0.5 * (l0 + h0) - motion[0]
    z1 = 0.5 * (l1 + h1) - motion[1]
    z2 = 0.5 * (l2 + h2) - motion[2]
    e0 = 0.5 * (h0 - l0)
    e1 = 0.5 * (h1 - l1)
    e2 = 0.5 * (h2 - l2)
    span = f[21]
    rho = math.sqrt(z0 * z0 + z1 * z1 + z2 * z2)
    angle = math.sqrt(motion[6] * motion[6] + motion[7] * motion[7] + motion[8] * motion[8]) * span
    sagitta = rho * (1.0 - math.cos(0.5 * angle)) if angle < math.pi else 2.0 * rho
    grow = (math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) + sagitta
            + math.sqrt(motion[3] * motion[3] + motion[4] * motion[4] + motion[5] * motion[5]) * span)
    a0 = f[0] * z0 + f[1] * z1 + f[2] * z2
    a1 = f[3] * z0 + f[4] * z1 + f[5] * z2
    a2 = f[6] * z0 + f[7] * z1 + f[8] * z2
    b0 = f[9] * z0 + f[10] * z1 + f[11] * z2
    b1 = f[12] * z0 + f[13] * z1 + f[14] * z2
    b2 = f[15] * z0 + f[16] * z1 + f[17] * z2
    return (min(a0, b0) + f[18] - grow, min(a1, b1) + f[19] - grow, min(a2, b2) + f[20] - grow,
            max(a0, b0) + f[18] + grow, max(a1, b1) + f[19] + grow, max(a2, b2) + f[20] + grow)


GEOMETRY = MeshGeometry  # this kind's group (colliders.geometry_of)
# the event calendar (engine/calendar.py) takes the triangles of fixed meshes (colliders.
# CALENDAR_TAKES): each sphere lists those its shell's box reaches (the walk of each
# mesh's tree, ``partners_of``) whenever its shell is made. A kinematic mesh's triangles
# move into shells the lists do not watch: World keeps such a scene on the time-ordered loop.
CALENDAR = True
# what the collider switch (colliders/switch.py, written by physdbg/write_switch.py) answers for
# this kind: one expression per function of the switch, in its parameters' names,
# ``group`` this kind's geometry (MeshGeometry)
SWITCH = {
    "time_of_impact": "time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, "
                      "tolerance, group)",
    "contact_normal": "normal(x, sigma, ia, other, group)",
    "contact_feature": "1 + feature(x, sigma, ia, other, group)",
    "partner_surface": "surface(x, sigma, radius, ia, other, n0, n1, n2, group)",
    "partner_normal_motion": "normal_motion(x, v, sigma, radius, ia, other, n0, n1, n2, group)",
    "partner_moves": "moves(other, group)",
    "surface_gap": "surface_gap(x, radius, ia, other, group)",
    "contact_gap": "gap(x, radius, ia, other, group)",
    "partner_restitution": "restitution(other, group)",
    "partners_of": "partners_of(p, path_lo, path_hi, group, out)",
    "immovable_partners_in": "partners_of(p, lo, hi, group, out)",
    "partner_count": "count(group)",
    "deepest_of_kind": "deepest_where(x, radius, group, ignore_tunnelled)",
    "narrow_candidates": "reachable_together(lo, hi, group)[:2] if together else reachable(lo, hi, group)",
    "every_candidate": "every_sphere_with(count, count(group))",
}

# how a step's spheres are searched against the meshes' trees (Settings.mesh_search)
MESH_SEARCH_NAMES = ("auto", "walk", "together")

# the volume a mesh's tree is walked with (MeshGeometry.volume; scene field bounding_volume):
# the one table of volume codes, mesh/tree.py's
VOLUMES = VOLUME_NAMES
VOLUME_AABB, VOLUME_SPHERE, VOLUME_OBB = AABB, SPHERE, OBB


def triangle_boxes(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's box (lo, hi (T, 3)) from its corners (T, 3, 3)."""
    if len(corners) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.ascontiguousarray(corners.min(axis=1)), np.ascontiguousarray(corners.max(axis=1))


@njit(cache=True, inline="always")
def _unpack(meshes):
    """The group's first eight fields (MeshGeometry's order; _motion_of and frame_box read the rest)."""
    return meshes[0], meshes[1], meshes[2], meshes[3], meshes[4], meshes[5], meshes[6], meshes[7]


@njit(cache=True, inline="always")
def _motion_of(t, meshes):
    """(moving, motion (9,)) of triangle t's mesh."""
    k = meshes[1][t]
    return meshes[9][k], meshes[8][k]


@njit(cache=True, inline="always")
def moves(t, meshes) -> bool:
    """Whether triangle t's mesh is kinematic (moves by its prescribed motion)."""
    return meshes[9][meshes[1][t]]


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
        found, _feature, y0, y1, y2 = moving_triangle_toi_sampled(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1],
                                                                  v[i, 2], a[i, 0], a[i, 1], a[i, 2], radius[i],
                                                                  corners[t], motion, start, integrator, k, horizon,
                                                                  1 if detection == DISCRETE else samples)
        if found != math.inf:
            if motion[6] != 0.0 or motion[7] != 0.0 or motion[8] != 0.0:
                # a turning mesh bends the path in its frame, so the chord from the test's
                # start to the sample is no test of a crossing: the nearest-face rule alone
                if not nearest_of_its_mesh(y0, y1, y2, t, meshes):
                    found = math.inf
            else:
                s0, s1, s2, _r0, _r1, _r2 = in_body_frame(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2],
                                                          motion, start)
                if not one_contact_with_its_mesh(s0, s1, s2, y0, y1, y2, t, meshes):
                    found = math.inf
        return start, found, 1
    if detection == SWEPT:
        found, _feature, _passes = triangle_toi_swept(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2], a[i, 0],
                                                      a[i, 1], a[i, 2], radius[i], corners[t], integrator, k, horizon,
                                                      tolerance)
    else:
        found, _feature, y0, y1, y2 = triangle_toi_sampled(x[i, 0], x[i, 1], x[i, 2], v[i, 0], v[i, 1], v[i, 2],
                                                           a[i, 0], a[i, 1], a[i, 2], radius[i], corners[t],
                                                           integrator, k, horizon,
                                                           1 if detection == DISCRETE else samples)
        if found != math.inf and not one_contact_with_its_mesh(x[i, 0], x[i, 1], x[i, 2], y0, y1, y2, t, meshes):
            found = math.inf
    return start, found, 1


@borrowing
def one_contact_with_its_mesh(s0, s1, s2, y0, y1, y2, t, meshes) -> bool:
    """Whether a sampled or discrete test's overlap with triangle t, found with the centre
    at y after starting the test at s (m; both in the frame of the corners at the step's
    start), is a contact of the sphere with t's mesh: its centre went through none of the
    mesh's triangles on the way (through_its_mesh: it has tunnelled, and the audit names
    it), and no nearer triangle of the mesh lies on the other side of the centre
    (nearest_of_its_mesh).

    Why: a sphere that ends a step deep in a closed mesh overlaps faces on both sides of
    its centre and approaches the far one; bounced off it, it approaches the near one, and
    so on without end (a storm of contacts at one instant, up to the budget). The seed's
    discrete test looks where the step ends: a centre past a face went through it, and an
    overlap of a thin part of a mesh is one contact, with its face nearest the centre,
    resolved if the sphere approaches it. Faces on the same side of the centre (a ball in
    a crease) are each a contact, as two walls are."""
    return not through_its_mesh(s0, s1, s2, y0, y1, y2, t, meshes) and nearest_of_its_mesh(y0, y1, y2, t, meshes)


@borrowing
def _through_triangle(s0, s1, s2, e0, e1, e2, corners, u) -> bool:
    """Whether the segment from s to e (m) passes through triangle u's face (from one side
    of its plane strictly to the other, across the face or its edges)."""
    a0, a1, a2 = corners[u, 0, 0], corners[u, 0, 1], corners[u, 0, 2]
    b0, b1, b2 = corners[u, 1, 0], corners[u, 1, 1], corners[u, 1, 2]
    c0, c1, c2 = corners[u, 2, 0], corners[u, 2, 1], corners[u, 2, 2]
    u0, u1, u2 = b0 - a0, b1 - a1, b2 - a2
    w0, w1, w2 = c0 - a0, c1 - a1, c2 - a2
    n0 = u1 * w2 - u2 * w1
    n1 = u2 * w0 - u0 * w2
    n2 = u0 * w1 - u1 * w0
    before = n0 * (s0 - a0) + n1 * (s1 - a1) + n2 * (s2 - a2)
    after = n0 * (e0 - a0) + n1 * (e1 - a1) + n2 * (e2 - a2)
    if not ((before > 0.0 and after < 0.0) or (before < 0.0 and after > 0.0)):
        return False
    f = before / (before - after)
    p0, p1, p2 = s0 + f * (e0 - s0), s1 + f * (e1 - s1), s2 + f * (e2 - s2)
    # on the inner side of each edge (or on it): the crossing point is on the face
    for k in range(3):
        if k == 0:
            q0, q1, q2, d0, d1, d2 = a0, a1, a2, u0, u1, u2
        elif k == 1:
            q0, q1, q2, d0, d1, d2 = b0, b1, b2, c0 - b0, c1 - b1, c2 - b2
        else:
            q0, q1, q2, d0, d1, d2 = c0, c1, c2, a0 - c0, a1 - c1, a2 - c2
        r0, r1, r2 = p0 - q0, p1 - q1, p2 - q2
        if n0 * (d1 * r2 - d2 * r1) + n1 * (d2 * r0 - d0 * r2) + n2 * (d0 * r1 - d1 * r0) < 0.0:
            return False
    return True


@borrowing
def through_its_mesh(s0, s1, s2, e0, e1, e2, t, meshes) -> bool:
    """Whether the segment from s to e (m, in the frame of the corners at the step's start)
    passes through a triangle of triangle t's mesh: a walk of the mesh's tree with the
    segment's box."""
    corners, _mesh_of, _restitution, box_lo, box_hi, leaf, skip, tree_first = _unpack(meshes)
    k = meshes[1][t]
    l0, l1, l2, h0, h1, h2 = frame_box(k, min(s0, e0), min(s1, e1), min(s2, e2), max(s0, e0), max(s1, e1),
                                       max(s2, e2), meshes)
    q = tree_first[k]
    while q < tree_first[k + 1]:
        if _box_meets(l0, l1, l2, h0, h1, h2, box_lo, box_hi, q):
            u = leaf[q]
            if u >= 0 and _through_triangle(s0, s1, s2, e0, e1, e2, corners, u):
                return True
            q += 1
        else:
            q = skip[q]
    return False


@borrowing
def nearest_of_its_mesh(y0, y1, y2, t, meshes) -> bool:
    """Whether no triangle of t's mesh nearer the point y (m; in the frame of the corners
    at the step's start) than t lies on the other side of y (their directions from their
    closest points to y opposed: y is between them, inside a thin part of the mesh), the
    lower number winning a tie: a walk of the mesh's tree with y's box grown by t's
    distance."""
    corners, _mesh_of, _restitution, box_lo, box_hi, leaf, skip, tree_first = _unpack(meshes)
    q0, q1, q2, _feature = closest_on_triangle(y0, y1, y2, corners[t, 0, 0], corners[t, 0, 1], corners[t, 0, 2],
                                               corners[t, 1, 0], corners[t, 1, 1], corners[t, 1, 2],
                                               corners[t, 2, 0], corners[t, 2, 1], corners[t, 2, 2])
    m0, m1, m2 = y0 - q0, y1 - q1, y2 - q2
    mine = m0 * m0 + m1 * m1 + m2 * m2
    reach = math.sqrt(mine)
    k = meshes[1][t]
    l0, l1, l2, h0, h1, h2 = frame_box(k, y0 - reach, y1 - reach, y2 - reach, y0 + reach, y1 + reach, y2 + reach,
                                       meshes)
    q = tree_first[k]
    while q < tree_first[k + 1]:
        if _box_meets(l0, l1, l2, h0, h1, h2, box_lo, box_hi, q):
            u = leaf[q]
            if u >= 0 and u != t:
                q0, q1, q2, _feature = closest_on_triangle(y0, y1, y2, corners[u, 0, 0], corners[u, 0, 1],
                                                           corners[u, 0, 2], corners[u, 1, 0], corners[u, 1, 1],
                                                           corners[u, 1, 2], corners[u, 2, 0], corners[u, 2, 1],
                                                           corners[u, 2, 2])
                theirs = (y0 - q0) * (y0 - q0) + (y1 - q1) * (y1 - q1) + (y2 - q2) * (y2 - q2)
                opposed = (y0 - q0) * m0 + (y1 - q1) * m1 + (y2 - q2) * m2 < 0.0
                if opposed and (theirs < mine or (theirs == mine and u < t)):
                    return False
            q += 1
        else:
            q = skip[q]
    return True


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
        d0, d1, d2 = turned_with(y0 - q0, y1 - q1, y2 - q2, motion, tau)
    else:
        d0, d1, d2, _length = _away(x, ia, corners, t)
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if length > 0.0:
        return d0 / length, d1 / length, d2 / length
    f0, f1, f2 = _face_normal(corners, t)
    if moving:
        return turned_with(f0, f1, f2, motion, sigma[ia])
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
def normal_motion(x, v, sigma, radius, ia, t, n0, n1, n2, meshes):
    """(velocity m/s, acceleration m/s²) along the normal n of triangle t's surface where
    sphere ia touches it, at ia's anchor time: what a held contact's relative normal
    velocity and acceleration are measured from. (0, 0) for a fixed mesh.

    The gap g = (x - p)·n - r to a plane through a surface point p turning with the mesh
    (ṅ = ω×n) has g' = (v - u)·n and g'' = (a - a_q)·n + 2(v - u)·(ω×n) - r|ω×n|² (u,
    a_q: the velocity and acceleration of the surface point q under the centre): the
    acceleration returned is what a·n must reach for g'' = 0."""
    moving, motion = _motion_of(t, meshes)
    if not moving:
        return 0.0, 0.0
    tau = sigma[ia]
    r = radius[ia]
    q0, q1, q2 = x[ia, 0] - n0 * r, x[ia, 1] - n1 * r, x[ia, 2] - n2 * r
    u0, u1, u2 = surface_velocity(q0, q1, q2, motion, tau)
    b0, b1, b2 = surface_acceleration(q0, q1, q2, motion, tau)
    w0, w1, w2 = motion[6], motion[7], motion[8]
    m0, m1, m2 = w1 * n2 - w2 * n1, w2 * n0 - w0 * n2, w0 * n1 - w1 * n0  # ω×n
    coriolis = 2.0 * ((v[ia, 0] - u0) * m0 + (v[ia, 1] - u1) * m1 + (v[ia, 2] - u2) * m2)
    turning = r * (m0 * m0 + m1 * m1 + m2 * m2)
    return u0 * n0 + u1 * n1 + u2 * n2, b0 * n0 + b1 * n1 + b2 * n2 - coriolis + turning


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


@borrowing
def surface_gap(x, radius, i, t, meshes):
    """(gap m, n0, n1, n2, on_face) of sphere i to the surface of triangle t's mesh where it
    is nearest (the triangle of that mesh with the least gap, found by a walk of the
    mesh's tree with the sphere's box grown by its radius): the gap, the unit normal from
    there to the centre, and whether the nearest point is inside a triangle's face.
    (inf, 0, 0, 0, False) when no triangle is within a radius of the sphere's surface."""
    corners, _mesh_of, _restitution, box_lo, box_hi, leaf, skip, tree_first = _unpack(meshes)
    k = meshes[1][t]
    reach = 2.0 * radius[i]
    l0, l1, l2, h0, h1, h2 = frame_box(k, x[i, 0] - reach, x[i, 1] - reach, x[i, 2] - reach, x[i, 0] + reach,
                                       x[i, 1] + reach, x[i, 2] + reach, meshes)
    best = math.inf
    n0 = n1 = n2 = 0.0
    on_face = False
    q = tree_first[k]
    while q < tree_first[k + 1]:
        if _box_meets(l0, l1, l2, h0, h1, h2, box_lo, box_hi, q):
            u = leaf[q]
            if u >= 0:
                q0, q1, q2, where = _closest(x, i, corners, u)
                d0, d1, d2 = x[i, 0] - q0, x[i, 1] - q1, x[i, 2] - q2
                length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if length > 0.0 and length - radius[i] < best:
                    best = length - radius[i]
                    n0, n1, n2 = d0 / length, d1 / length, d2 / length
                    on_face = where == FACE
            q += 1
        else:
            q = skip[q]
    return best, n0, n1, n2, on_face


@njit(cache=True, inline="always")
def _box_meets(l0, l1, l2, h0, h1, h2, box_lo, box_hi, q) -> bool:
    return (l0 <= box_hi[q, 0] and box_lo[q, 0] <= h0 and l1 <= box_hi[q, 1] and box_lo[q, 1] <= h1
            and l2 <= box_hi[q, 2] and box_lo[q, 2] <= h2)


@njit(cache=True, inline="always")
def _box_meets_sphere(l0, l1, l2, h0, h1, h2, node_sphere, q) -> bool:
    """Does the box meet node q's sphere (node_sphere (Q, 4): centre, radius)? The squared
    distance from the centre to the box against the squared radius."""
    d0 = max(l0 - node_sphere[q, 0], 0.0, node_sphere[q, 0] - h0)
    d1 = max(l1 - node_sphere[q, 1], 0.0, node_sphere[q, 1] - h1)
    d2 = max(l2 - node_sphere[q, 2], 0.0, node_sphere[q, 2] - h2)
    r = node_sphere[q, 3]
    return d0 * d0 + d1 * d1 + d2 * d2 <= r * r


@njit(cache=True, inline="always")
def _box_meets_obb(l0, l1, l2, h0, h1, h2, node_obb, q) -> bool:
    """Does the box (axis-aligned) meet node q's oriented box (node_obb (Q, 15): centre,
    axes as rows, half extents)? The separating-axis test (Ericson 4.4.1) with the box's
    axes the world's: 3 + 3 face axes and the 9 edge-edge crosses, each |R| guarded by
    PARALLEL_GUARD so that near-parallel axes stay conservative."""
    o = node_obb[q]
    ea0, ea1, ea2 = 0.5 * (h0 - l0), 0.5 * (h1 - l1), 0.5 * (h2 - l2)
    t0, t1, t2 = o[0] - 0.5 * (l0 + h0), o[1] - 0.5 * (l1 + h1), o[2] - 0.5 * (l2 + h2)
    eb0, eb1, eb2 = o[12], o[13], o[14]
    # r_ij = a_i · b_j with a the world's axes: component i of B's axis j (row j of the axes)
    return separating_axes_meet(t0, t1, t2, o[3], o[6], o[9], o[4], o[7], o[10], o[5], o[8], o[11], ea0, ea1, ea2,
                                eb0, eb1, eb2)


@njit(cache=True, inline="always")
def _node_meets(volume, l0, l1, l2, h0, h1, h2, meshes, q) -> bool:
    """Does the box (l0, l1, l2)–(h0, h1, h2) (in the mesh's frame) meet node q of a tree
    walked with ``volume`` (VOLUME_AABB, VOLUME_SPHERE or VOLUME_OBB)? The one node test
    of every walk (``walk``, ``reachable_together``). Each test is monotone: a box inside
    another meets no node the other does not (so a node missed by a box holding many
    spheres' boxes is missed by each of them)."""
    if volume == VOLUME_SPHERE:
        return _box_meets_sphere(l0, l1, l2, h0, h1, h2, meshes[13], q)
    if volume == VOLUME_OBB:
        return _box_meets_obb(l0, l1, l2, h0, h1, h2, meshes[14], q)
    return _box_meets(l0, l1, l2, h0, h1, h2, meshes[3], meshes[4], q)


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


# outcomes of a visited node (events.SEARCH_MET, SEARCH_CULLED, SEARCH_REACHED)
_MET, _CULLED, _REACHED = 0, 1, 2


@njit(cache=True, inline="always")
def walk(k, l0, l1, l2, h0, h1, h2, meshes, p, out, m, log, logged):
    """The one walk of mesh k's tree (a stackless pre-order walk with skip links) with
    the box (l0, l1, l2)–(h0, h1, h2) in the mesh's frame: a node whose box meets it is
    descended into, one that does not ends its branch, and each triangle reached becomes
    a row (p, triangle) of out from row m on. Every node visited is also a row of ``log``
    (node, outcome: 0 met, 1 culled, 2 a triangle reached) from row ``logged`` on, when
    log has rows (``search_visits``; the contact loop passes none, ``out[:0]``). Returns (m,
    logged) after the walk."""
    leaf, skip, tree_first = meshes[5], meshes[6], meshes[7]
    volume = meshes[12][k]
    record = log.shape[0] > 0
    q = tree_first[k]
    while q < tree_first[k + 1]:
        meets = _node_meets(volume, l0, l1, l2, h0, h1, h2, meshes, q)
        if record:
            log[logged, 0] = q
            log[logged, 1] = (_REACHED if leaf[q] >= 0 else _MET) if meets else _CULLED
            logged += 1
        if meets:
            if leaf[q] >= 0:
                out[m, 0] = p
                out[m, 1] = leaf[q]
                m += 1
            q += 1
        else:
            q = skip[q]
    return m, logged


@borrowing
def partners_of(p, path_lo, path_hi, meshes, out) -> int:
    """The triangles (rows (p, t) of out (K, 2)) sphere p's new path must be tested against,
    in the order of their numbers; returns how many: those whose boxes the box of that path
    (row p of path_lo, path_hi) meets, found by the stackless walk of each mesh's tree with
    that box carried into the mesh's frame (``frame_box``). In number order because
    a sphere meets the triangles that share an edge or a corner at one instant, and a tie
    in the contact loop goes to the test made first: the triangle with the lower number,
    however the tree is laid out (as in the reference loop)."""
    tree_first = meshes[7]
    m = 0
    for k in range(tree_first.shape[0] - 1):
        l0, l1, l2, h0, h1, h2 = frame_box(k, path_lo[p, 0], path_lo[p, 1], path_lo[p, 2], path_hi[p, 0],
                                           path_hi[p, 1], path_hi[p, 2], meshes)
        m, _logged = walk(k, l0, l1, l2, h0, h1, h2, meshes, p, out, m, out[:0], 0)
    _sort_triangles(out, m)
    return m


@kernel
def search_visits(lo, hi, meshes):
    """Every node the engine's walk (``walk``) visits for each box lo[j], hi[j] (J, 3)
    (world frame: the boxes the contact loop asked with), each mesh's tree from its root
    with the box carried into the mesh's frame (``frame_box``) as the meshes are placed
    for the step: (query (V,), node (V,), outcome (V,), parent (V,)) int64, the visits in
    the order walked, each with the box's row j, the node (a position in the group's
    pre-order), its outcome (0 met, 1 culled, 2 a triangle reached) and the row of the
    visit it was reached from (-1 for a tree's root). The contact loop's walks are the
    same walks: what it tested is what these reach."""
    nodes = meshes[5].shape[0]
    tree_first, parent = meshes[7], meshes[11]
    log = np.empty((max(nodes, 1), 2), dtype=np.int64)  # one walk of one tree visits a node at most once
    row_of_node = np.empty(max(nodes, 1), dtype=np.int64)
    leaves = np.empty((max(nodes, 1), 2), dtype=np.int64)
    capacity = max(16, 4 * lo.shape[0])
    rows = np.empty((capacity, 4), dtype=np.int64)
    v = 0
    for j in range(lo.shape[0]):
        for k in range(tree_first.shape[0] - 1):
            l0, l1, l2, h0, h1, h2 = frame_box(k, lo[j, 0], lo[j, 1], lo[j, 2], hi[j, 0], hi[j, 1], hi[j, 2], meshes)
            _m, logged = walk(k, l0, l1, l2, h0, h1, h2, meshes, j, leaves, 0, log, 0)
            if v + logged > rows.shape[0]:
                grown = np.empty((max(2 * rows.shape[0], v + logged), 4), dtype=np.int64)
                grown[:v] = rows[:v]
                rows = grown
            for r in range(logged):
                q = log[r, 0]
                row_of_node[q] = v + r  # a node is visited after its parent
                rows[v + r, 0] = j
                rows[v + r, 1] = q
                rows[v + r, 2] = log[r, 1]
                rows[v + r, 3] = row_of_node[parent[q]] if parent[q] >= 0 else -1
            v += logged
    return rows[:v, 0].copy(), rows[:v, 1].copy(), rows[:v, 2].copy(), rows[:v, 3].copy()


@kernel
def search_work(lo, hi, meshes, k):
    """(node tests, triangles reached): what search_visits logs of mesh k's tree for the
    boxes lo[j], hi[j] (J, 3), counted, not kept (the advisor's counted work for a
    bounding volume: a soup of large triangles has every node visited by every box, and
    the logged visits of 256 boxes took 360 MB)."""
    nodes = meshes[5].shape[0]
    log = np.empty((max(nodes, 1), 2), dtype=np.int64)
    leaves = np.empty((max(nodes, 1), 2), dtype=np.int64)
    tests = 0
    reached = 0
    for j in range(lo.shape[0]):
        l0, l1, l2, h0, h1, h2 = frame_box(k, lo[j, 0], lo[j, 1], lo[j, 2], hi[j, 0], hi[j, 1], hi[j, 2], meshes)
        _m, logged = walk(k, l0, l1, l2, h0, h1, h2, meshes, j, leaves, 0, log, 0)
        tests += logged
        for r in range(logged):
            if log[r, 1] == _REACHED:
                reached += 1
    return tests, reached


@kernel
def reachable(lo, hi, meshes):
    """Sphere–triangle candidates (spheres (K,), triangles (K,)) whose boxes meet the
    spheres' path boxes lo, hi (N, 3) (radius included)."""
    n = lo.shape[0]
    total = count(meshes)
    if total == 0:  # no mesh: nothing to walk (and no room to make: 0.8 ms a step at 10,000 spheres)
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
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


# a box of the spheres' tree is grown by this much of its largest coordinate (and this much
# of a metre) before a node test: a rounding of the OBB test (whose centre and half extents
# are computed apart) can never then cull a node one of its spheres' boxes meets
_TOGETHER_PAD = 1e-9


@njit(cache=True, inline="always")
def _grow_box(l0, l1, l2, h0, h1, h2):
    """A box grown by _TOGETHER_PAD of its largest coordinate's size, and of a metre."""
    pad = _TOGETHER_PAD * (1.0 + max(abs(l0), abs(l1), abs(l2), abs(h0), abs(h1), abs(h2)))
    return l0 - pad, l1 - pad, l2 - pad, h0 + pad, h1 + pad, h2 + pad


@njit(cache=True, inline="always")
def _half_perimeter(l0, l1, l2, h0, h1, h2) -> float:
    return (h0 - l0) + (h1 - l1) + (h2 - l2)


@njit(cache=True, inline="always")
def _on_the_way(volume, l0, l1, l2, h0, h1, h2, meshes, q) -> tuple:
    """(meets, tests): whether the box meets every node above q on the way from its tree's
    root (parent links), as a walk from the root requires, and how many it tested."""
    parent = meshes[11]
    up = parent[q]
    tests = 0
    while up >= 0:
        tests += 1
        if not _node_meets(volume, l0, l1, l2, h0, h1, h2, meshes, up):
            return False, tests
        up = parent[up]
    return True, tests


@kernel
def _boxes_in_frame(k, lo, hi, meshes):
    """The boxes lo, hi (N, 3) carried into mesh k's frame (``frame_box``) without those with
    a NaN or infinite bound (which meet nothing): (lo (n, 3), hi (n, 3), sphere (n,))."""
    n = lo.shape[0]
    flo = np.empty((n, 3))
    fhi = np.empty((n, 3))
    keep = np.empty(n, dtype=np.int64)
    kept = 0
    for i in range(n):
        l0, l1, l2, h0, h1, h2 = frame_box(k, lo[i, 0], lo[i, 1], lo[i, 2], hi[i, 0], hi[i, 1], hi[i, 2], meshes)
        if not (math.isfinite(l0) and math.isfinite(l1) and math.isfinite(l2) and math.isfinite(h0)
                and math.isfinite(h1) and math.isfinite(h2)):
            continue
        flo[kept, 0], flo[kept, 1], flo[kept, 2] = l0, l1, l2
        fhi[kept, 0], fhi[kept, 1], fhi[kept, 2] = h0, h1, h2
        keep[kept] = i
        kept += 1
    return flo[:kept], fhi[:kept], keep[:kept]


@kernel
def _descend_together(k, flo, fhi, keep, spheres, meshes, keys, m, tests):
    """The simultaneous descent of the spheres' tree ``spheres`` (build_lbvh's arrays over
    flo, fhi; row r is sphere keep[r]) and mesh k's tree: each pair of a sphere and a
    triangle it reaches appended to keys (sphere * triangles + triangle) from row m on.
    Returns (keys, m, tests)."""
    node_lo, node_hi, left, right, start, order = spheres[0], spheres[1], spheres[2], spheres[3], spheres[6], spheres[8]
    tree_first, leaf, skip, box_lo, box_hi = meshes[7], meshes[5], meshes[6], meshes[3], meshes[4]
    volume = meshes[12][k]
    total = count(meshes)
    root = tree_first[k]
    # pairs (spheres' node, mesh node, whether the nodes above the mesh node are known to
    # meet the sphere's own box), depth first: never deeper than both trees' depths
    capacity = node_lo.shape[0] + (tree_first[k + 1] - root) + 8
    pair_a = np.empty(capacity, dtype=np.int64)
    pair_q = np.empty(capacity, dtype=np.int64)
    pair_known = np.empty(capacity, dtype=np.bool_)
    # each node's box as tested: a leaf's the sphere's own, an inner node's grown (_grow_box)
    size = node_lo.shape[0]
    test_box = np.empty((size, 6))
    half = np.empty(size)
    for a in range(size):
        if left[a] < 0:
            r = order[start[a]]
            l0, l1, l2, h0, h1, h2 = flo[r, 0], flo[r, 1], flo[r, 2], fhi[r, 0], fhi[r, 1], fhi[r, 2]
        else:
            l0, l1, l2, h0, h1, h2 = _grow_box(node_lo[a, 0], node_lo[a, 1], node_lo[a, 2],
                                               node_hi[a, 0], node_hi[a, 1], node_hi[a, 2])
        test_box[a, 0], test_box[a, 1], test_box[a, 2] = l0, l1, l2
        test_box[a, 3], test_box[a, 4], test_box[a, 5] = h0, h1, h2
        half[a] = _half_perimeter(l0, l1, l2, h0, h1, h2)
    pair_a[0], pair_q[0], pair_known[0] = 0, root, True
    top = 1
    while top > 0:
        top -= 1
        a, q, known = pair_a[top], pair_q[top], pair_known[top]
        a_leaf = left[a] < 0
        l0, l1, l2 = test_box[a, 0], test_box[a, 1], test_box[a, 2]
        h0, h1, h2 = test_box[a, 3], test_box[a, 4], test_box[a, 5]
        tests += 1
        if not _node_meets(volume, l0, l1, l2, h0, h1, h2, meshes, q):
            continue
        if a_leaf and not known and volume != VOLUME_AABB:
            ok, up_tests = _on_the_way(volume, l0, l1, l2, h0, h1, h2, meshes, q)
            tests += up_tests
            if not ok:
                continue
        q_leaf = leaf[q] >= 0
        if a_leaf and q_leaf:
            if m == keys.shape[0]:
                grown = np.empty(2 * m, dtype=np.int64)
                grown[:m] = keys[:m]
                keys = grown
            keys[m] = keep[order[start[a]]] * total + leaf[q]
            m += 1
            continue
        # split the mesh node when the spheres' node is a leaf or the smaller of the two
        if a_leaf or (not q_leaf and _half_perimeter(box_lo[q, 0], box_lo[q, 1], box_lo[q, 2], box_hi[q, 0],
                                                     box_hi[q, 1], box_hi[q, 2]) >= half[a]):
            # in pre-order q's left child follows it; its right child starts where that one's subtree ends
            pair_a[top], pair_q[top], pair_known[top] = a, skip[q + 1], a_leaf
            pair_a[top + 1], pair_q[top + 1], pair_known[top + 1] = a, q + 1, a_leaf
        else:
            pair_a[top], pair_q[top], pair_known[top] = right[a], q, False
            pair_a[top + 1], pair_q[top + 1], pair_known[top + 1] = left[a], q, False
        top += 2
    return keys, m, tests


@kernel
def reachable_together(lo, hi, meshes):
    """``reachable`` by the seed's simultaneous descent: for each mesh, a tree over the
    spheres' path boxes (carried into the mesh's frame, ``frame_box``; an LBVH, built once
    for the fixed meshes and once for each moving one) descended together with the mesh's
    tree, a pair of nodes whose volumes miss ending both branches at once, the larger node
    of a meeting pair split. Returns (spheres (K,), triangles (K,), tests): the same
    candidates in the same order as ``reachable``, and the node tests made.

    The same candidates: the walk's triangles for a box are those whose every node on the
    way down from the root meets it. A pair of a spheres' node and a mesh node is culled
    only when the spheres' box (grown: _TOGETHER_PAD) misses the node, and a box inside it
    misses it too (each node test is monotone); when a sphere's own box first meets a mesh
    node below the root, the nodes above it are tested with that box too (``_on_the_way``),
    except with AABBs, whose parents hold their children exactly. A box with a NaN or
    infinite bound is left out (the walk's AABB test misses it too)."""
    total = count(meshes)
    tree_first, moving = meshes[7], meshes[9]
    keys = np.empty(max(4 * lo.shape[0], 16), dtype=np.int64)
    m = 0
    tests = 0
    fixed_built = False
    fixed_lo, fixed_hi, fixed_keep = _boxes_in_frame(0, lo[:0], hi[:0], meshes)
    fixed = build_lbvh(fixed_lo, fixed_hi)
    for k in range(tree_first.shape[0] - 1):
        if tree_first[k] == tree_first[k + 1]:
            continue
        if moving[k]:
            flo, fhi, keep = _boxes_in_frame(k, lo, hi, meshes)
            if keep.shape[0] == 0:
                continue
            keys, m, tests = _descend_together(k, flo, fhi, keep, build_lbvh(flo, fhi), meshes, keys, m, tests)
        else:
            if not fixed_built:  # a fixed mesh's frame is the world's: one tree serves them all
                fixed_lo, fixed_hi, fixed_keep = _boxes_in_frame(k, lo, hi, meshes)
                fixed = build_lbvh(fixed_lo, fixed_hi)
                fixed_built = True
            if fixed_keep.shape[0] == 0:
                continue
            keys, m, tests = _descend_together(k, fixed_lo, fixed_hi, fixed_keep, fixed, meshes, keys, m, tests)
    if total == 0 or m == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), tests
    keys = np.sort(keys[:m])  # sphere by sphere, each one's triangles in number order, as reachable
    return keys // total, keys % total, tests


@kernel
def walk_tests(lo, hi, meshes) -> int:
    """How many node tests ``reachable`` makes for the boxes lo, hi (N, 3) (each visit of
    its walks, ``walk``): its work, in the unit of ``reachable_together``'s."""
    tree_first = meshes[7]
    log = np.empty((max(meshes[5].shape[0], 1), 2), dtype=np.int64)  # a walk visits a node at most once
    leaves = np.empty((max(count(meshes), 1), 2), dtype=np.int64)
    tests = 0
    for i in range(lo.shape[0]):
        for k in range(tree_first.shape[0] - 1):
            l0, l1, l2, h0, h1, h2 = frame_box(k, lo[i, 0], lo[i, 1], lo[i, 2], hi[i, 0], hi[i, 1], hi[i, 2], meshes)
            _m, logged = walk(k, l0, l1, l2, h0, h1, h2, meshes, i, leaves, 0, log, 0)
            tests += logged
    return tests


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
    corners, _mesh_of, _restitution, box_lo, box_hi, leaf, skip, tree_first = _unpack(meshes)
    worst = 0.0
    who = -1
    which = -1
    for i in range(x.shape[0]):
        r = radius[i]
        for k in range(tree_first.shape[0] - 1):
            l0, l1, l2, h0, h1, h2 = frame_box(k, x[i, 0] - r, x[i, 1] - r, x[i, 2] - r, x[i, 0] + r, x[i, 1] + r,
                                               x[i, 2] + r, meshes)
            q = tree_first[k]
            while q < tree_first[k + 1]:
                if _box_meets(l0, l1, l2, h0, h1, h2, box_lo, box_hi, q):
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

