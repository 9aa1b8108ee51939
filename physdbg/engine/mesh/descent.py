"""Mesh against mesh: the seed's two-tree search, a simultaneous descent of both BVHs.

"A search tree … that records descent into each BVH" (the seed): from the pair of roots,
a pair of nodes whose volumes meet is split on the larger node (by bounding-sphere radius;
a leaf is never split) and both halves are pushed; a pair whose volumes are apart is
culled; a pair of leaves has its triangles tested (``mesh.tritri``). Every pair visited is
logged with its outcome, so the descent can be printed (``physdbg overlap``) and shown.

Both meshes are posed in the world first (``posed``): sphere centres move, OBBs move and
turn, and AABBs are refitted from the moved corners when the mesh is turned (a box stays a
box only under translation). The convex hulls, where both meshes carry one, are tested
before the roots: hulls apart ends the search at no node test.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..broadphase.bvh import refit
from ..jit import kernel
from .rigid_motion import Pose
from .tree import AABB, OBB, SPHERE, VOLUME_NAMES, MeshTree, triangle_boxes
from .tritri import brute_force_pairs, triangles_meet
from .volumes import aabbs_meet, hull_test_work, hulls_apart, obbs_meet, spheres_meet

# The hulls' early-out is skipped when it could cost more plane-point products than this: a
# finely tessellated round mesh has a hull of as many faces as the mesh, and its trees, not
# its hull, answer quickly (an icosphere of 20,480 triangles against itself: 2 s by its
# hull's 2·10^8 products, 13–18 ms by its trees).
HULL_TEST_WORK = 200_000

# outcomes of a visited node pair (the log's third column)
APART = 0          # volumes apart: culled
MEET = 1           # volumes meet: the larger node is split
LEAVES_MISS = 2    # two leaves whose triangles do not meet
LEAVES_MEET = 3    # two leaves whose triangles meet
HULLS_APART = 4    # the convex hulls are apart (nodes -1, -1): nothing else visited
OUTCOME_NAMES = ("volumes apart", "volumes meet", "triangles miss", "triangles meet", "hulls apart")


class WorldVolumes(NamedTuple):
    """One mesh's tree with its volumes in the world frame (M nodes, one triangle per leaf)."""

    left: np.ndarray        # (M,) int64, -1 at leaves
    right: np.ndarray       # (M,) int64
    triangle: np.ndarray    # (M,) int64 face index at leaves, -1 inside
    lo: np.ndarray          # (M, 3) AABB
    hi: np.ndarray          # (M, 3)
    center: np.ndarray      # (M, 3) bounding-sphere centre
    radius: np.ndarray      # (M,)
    obb_center: np.ndarray  # (M, 3)
    obb_axes: np.ndarray    # (M, 3, 3) rows: unit axes
    obb_half: np.ndarray    # (M, 3)
    vertices: np.ndarray    # (V, 3) the corners, moved
    faces: np.ndarray       # (F, 3) int64


def posed(tree: MeshTree, pose: Pose, volume: int) -> tuple[WorldVolumes, int]:
    """``tree``'s volumes moved by ``pose``, and how many AABB nodes were refitted (0 when
    the pose only translates, or the volume is not the AABB)."""
    nodes = tree.nodes
    rotation, position = pose.rotation, pose.position
    vertices = pose.apply(tree.vertices)
    refitted = 0
    pad = tree.pad
    if volume == AABB and not np.array_equal(rotation, np.eye(3)):
        lo, hi = triangle_boxes(vertices, tree.faces)
        box_lo, box_hi = nodes.lo.copy(), nodes.hi.copy()
        refit(lo, hi, box_lo, box_hi, nodes.left, nodes.right, nodes.parent, nodes.start, nodes.count, nodes.order)
        refitted = nodes.size
    else:
        box_lo, box_hi = nodes.lo + position, nodes.hi + position
    triangle = np.where(nodes.left < 0, nodes.order[np.minimum(nodes.start, max(len(nodes.order) - 1, 0))], -1)
    volumes = WorldVolumes(nodes.left, nodes.right, np.ascontiguousarray(triangle, dtype=np.int64),
                           np.ascontiguousarray(box_lo - pad), np.ascontiguousarray(box_hi + pad),
                           np.ascontiguousarray(tree.sphere_center @ rotation.T + position), tree.sphere_radius,
                           np.ascontiguousarray(tree.obb_center @ rotation.T + position),
                           np.ascontiguousarray(tree.obb_axes @ rotation.T), tree.obb_half, vertices, tree.faces)
    return volumes, refitted


@kernel
def _volumes_meet(volume, a, i, b, j):
    if volume == SPHERE:
        return spheres_meet(a.center, a.radius, i, b.center, b.radius, j)
    if volume == AABB:
        return aabbs_meet(a.lo, a.hi, i, b.lo, b.hi, j)
    return obbs_meet(a.obb_center, a.obb_axes, a.obb_half, i, b.obb_center, b.obb_axes, b.obb_half, j)


@kernel
def _room_for_one_more(rows, used):
    """``rows`` (R, C) int64, or a copy twice as long when all ``used`` rows are taken."""
    if used < rows.shape[0]:
        return rows
    bigger = np.empty((2 * rows.shape[0], rows.shape[1]), dtype=np.int64)
    bigger[:used] = rows[:used]
    return bigger


@kernel
def _descend(volume, a, b, root_a, root_b):
    """The simultaneous descent; returns (pairs (K, 2) face indices, log (L, 4): node of
    a, node of b, outcome, the row of the pair that led to it (-1 for the roots); volume
    tests, triangle tests)."""
    stack = np.empty((64, 3), dtype=np.int64)  # node of a, node of b, the row that pushed them
    log = np.empty((64, 4), dtype=np.int64)
    pairs = np.empty((16, 2), dtype=np.int64)
    scratch = np.empty((4, 3))
    top = 0
    logged = 0
    found = 0
    volume_tests = 0
    triangle_tests = 0
    stack[0, 0] = root_a
    stack[0, 1] = root_b
    stack[0, 2] = -1
    top = 1
    while top > 0:
        top -= 1
        i = stack[top, 0]
        j = stack[top, 1]
        volume_tests += 1
        log = _room_for_one_more(log, logged)
        log[logged, 0] = i
        log[logged, 1] = j
        log[logged, 3] = stack[top, 2]
        if not _volumes_meet(volume, a, i, b, j):
            log[logged, 2] = APART
            logged += 1
            continue
        leaf_a = a.left[i] < 0
        leaf_b = b.left[j] < 0
        if leaf_a and leaf_b:
            triangle_tests += 1
            ta = a.triangle[i]
            tb = b.triangle[j]
            va = a.vertices
            vb = b.vertices
            fa = a.faces
            fb = b.faces
            if triangles_meet(va[fa[ta, 0]], va[fa[ta, 1]], va[fa[ta, 2]], vb[fb[tb, 0]], vb[fb[tb, 1]],
                              vb[fb[tb, 2]], scratch):
                log[logged, 2] = LEAVES_MEET
                pairs = _room_for_one_more(pairs, found)
                pairs[found, 0] = ta
                pairs[found, 1] = tb
                found += 1
            else:
                log[logged, 2] = LEAVES_MISS
            logged += 1
            continue
        log[logged, 2] = MEET
        logged += 1
        stack = _room_for_one_more(stack, top + 1)
        if leaf_b or (not leaf_a and a.radius[i] >= b.radius[j]):
            stack[top, 0] = a.right[i]
            stack[top, 1] = j
            stack[top + 1, 0] = a.left[i]
            stack[top + 1, 1] = j
        else:
            stack[top, 0] = i
            stack[top, 1] = b.right[j]
            stack[top + 1, 0] = i
            stack[top + 1, 1] = b.left[j]
        stack[top, 2] = logged - 1
        stack[top + 1, 2] = logged - 1
        top += 2
    return pairs[:found], log[:logged], volume_tests, triangle_tests


@dataclass
class Descent:
    """What one mesh-against-mesh search found and did.

    ``pairs`` (K, 2): meeting triangles (face of a, face of b), sorted; ``log`` (L, 4): each
    node pair visited in order (node of a, node of b, outcome, one of OUTCOME_NAMES, and
    the row of the pair whose split led to it, -1 for the roots);
    ``volume_tests``, ``triangle_tests``, ``refitted`` (AABB nodes refitted for the pose),
    ``hull_test``: "apart", "meet", "off" (not asked for, or a mesh has none) or "too big"
    (skipped: over HULL_TEST_WORK).
    """

    volume: str
    pairs: np.ndarray
    log: np.ndarray
    volume_tests: int
    triangle_tests: int
    refitted: int
    hull_test: str

    @property
    def meet(self) -> bool:
        return len(self.pairs) > 0


def descend(tree_a: MeshTree, pose_a: Pose, tree_b: MeshTree, pose_b: Pose, volume: str = "aabb",
            hull: bool = True) -> Descent:
    """The triangle pairs of two posed meshes that meet, by simultaneous descent of their
    BVHs with ``volume`` (one of VOLUME_NAMES) at every node; ``hull``: test the convex
    hulls first where both meshes carry one."""
    if volume not in VOLUME_NAMES:
        raise ValueError(f"volume {volume!r}: one of {', '.join(VOLUME_NAMES)}")
    code = VOLUME_NAMES.index(volume)
    hull_test = "off"
    if hull and tree_a.has_hull and tree_b.has_hull and hull_test_work(
            len(tree_a.hull_offsets), len(tree_a.hull_points), len(tree_b.hull_offsets),
            len(tree_b.hull_points)) > HULL_TEST_WORK:
        hull_test = "too big"
    elif hull and tree_a.has_hull and tree_b.has_hull:
        apart = hulls_apart(tree_a.hull_normals @ pose_a.rotation.T,
                            tree_a.hull_offsets + tree_a.hull_normals @ pose_a.rotation.T @ pose_a.position,
                            pose_a.apply(tree_a.hull_points),
                            tree_b.hull_normals @ pose_b.rotation.T,
                            tree_b.hull_offsets + tree_b.hull_normals @ pose_b.rotation.T @ pose_b.position,
                            pose_b.apply(tree_b.hull_points))
        hull_test = "apart" if apart else "meet"
        if apart:
            return Descent(volume, np.zeros((0, 2), dtype=np.int64), np.array([[-1, -1, HULLS_APART, -1]]), 0, 0, 0,
                           hull_test)
    a, refit_a = posed(tree_a, pose_a, code)
    b, refit_b = posed(tree_b, pose_b, code)
    pairs, log, volume_tests, triangle_tests = _descend(code, a, b, tree_a.nodes.root, tree_b.nodes.root)
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))] if len(pairs) else pairs
    return Descent(volume, pairs, log, int(volume_tests), int(triangle_tests), refit_a + refit_b, hull_test)


def brute_force(tree_a: MeshTree, pose_a: Pose, tree_b: MeshTree, pose_b: Pose) -> np.ndarray:
    """Every meeting triangle pair (K, 2) of two posed meshes by testing all F_a × F_b pairs
    (the reference the descent is tested against)."""
    return brute_force_pairs(pose_a.apply(tree_a.vertices), tree_a.faces, pose_b.apply(tree_b.vertices), tree_b.faces)
