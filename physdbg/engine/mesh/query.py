"""Spheres against one mesh's BVH, with any bounding volume: which volume pays, counted.

A sphere (centre c, radius r) walks down the mesh's tree (tree.py) from the root: at a
node whose volume it meets it goes on to both children, at one it misses the branch ends;
at a leaf it is tested against the triangle itself (the point of the triangle closest to
c, mesh.closest, within r). The node's volume is the one asked for: its bounding sphere
(|c - centre| <= r + R), its AABB (the point of the box closest to c within r) or its OBB
(the same in the box's own axes), each posed with the mesh (descent.posed: an AABB is
refitted when the mesh is turned, an OBB and a sphere only move). Every node test and
every triangle test is counted, so a benchmark can say which volume pays for which shape
and pose (docs/meshes.md, "Which volume pays"); ``brute_force`` is the reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..jit import borrowing, kernel
from .closest import closest_on_triangle
from .descent import posed
from .rigid_motion import Pose
from .tree import AABB, OBB, SPHERE, VOLUME_NAMES, MeshTree


@borrowing
def _sphere_meets_node(volume, w, q, c0, c1, c2, r) -> bool:
    if volume == SPHERE:
        d0 = c0 - w.center[q, 0]
        d1 = c1 - w.center[q, 1]
        d2 = c2 - w.center[q, 2]
        reach = r + w.radius[q]
        return d0 * d0 + d1 * d1 + d2 * d2 <= reach * reach
    if volume == AABB:
        e0 = max(w.lo[q, 0] - c0, 0.0, c0 - w.hi[q, 0])
        e1 = max(w.lo[q, 1] - c1, 0.0, c1 - w.hi[q, 1])
        e2 = max(w.lo[q, 2] - c2, 0.0, c2 - w.hi[q, 2])
        return e0 * e0 + e1 * e1 + e2 * e2 <= r * r
    # OBB: the centre in the box's axes, then as for an AABB centred on the origin
    d0 = c0 - w.obb_center[q, 0]
    d1 = c1 - w.obb_center[q, 1]
    d2 = c2 - w.obb_center[q, 2]
    out = 0.0
    for k in range(3):
        along = d0 * w.obb_axes[q, k, 0] + d1 * w.obb_axes[q, k, 1] + d2 * w.obb_axes[q, k, 2]
        beyond = abs(along) - w.obb_half[q, k]
        if beyond > 0.0:
            out += beyond * beyond
    return out <= r * r


@borrowing
def _touches_triangle(w, t, c0, c1, c2, r) -> bool:
    v = w.vertices
    f = w.faces
    a = f[t, 0]
    b = f[t, 1]
    c = f[t, 2]
    q0, q1, q2, _feature = closest_on_triangle(c0, c1, c2, v[a, 0], v[a, 1], v[a, 2], v[b, 0], v[b, 1], v[b, 2],
                                               v[c, 0], v[c, 1], v[c, 2])
    return (c0 - q0) ** 2 + (c1 - q1) ** 2 + (c2 - q2) ** 2 <= r * r


@kernel
def _query(volume, w, root, centers, radii, first):
    """Each sphere's lowest-numbered touching triangle into first (K,) (-1: none); returns
    (node tests, triangle tests)."""
    stack = np.empty(64, dtype=np.int64)
    node_tests = 0
    triangle_tests = 0
    for k in range(centers.shape[0]):
        c0 = centers[k, 0]
        c1 = centers[k, 1]
        c2 = centers[k, 2]
        r = radii[k]
        best = -1
        top = 1
        stack[0] = root
        while top > 0:
            top -= 1
            q = stack[top]
            node_tests += 1
            if not _sphere_meets_node(volume, w, q, c0, c1, c2, r):
                continue
            if w.left[q] < 0:
                t = w.triangle[q]
                triangle_tests += 1
                if (best < 0 or t < best) and _touches_triangle(w, t, c0, c1, c2, r):
                    best = t
                continue
            if top + 2 > stack.shape[0]:
                grown = np.empty(2 * stack.shape[0], dtype=np.int64)
                grown[:top] = stack[:top]
                stack = grown
            stack[top] = w.right[q]
            stack[top + 1] = w.left[q]
            top += 2
        first[k] = best
    return node_tests, triangle_tests


@dataclass
class SphereQuery:
    """What one batch of sphere queries found and cost: ``first`` (K,) each sphere's
    lowest-numbered touching triangle (-1: none), ``node_tests``, ``triangle_tests``,
    ``refitted`` (AABB nodes refitted for the pose), ``volume``."""

    volume: str
    first: np.ndarray
    node_tests: int
    triangle_tests: int
    refitted: int

    @property
    def touching(self) -> int:
        return int(np.count_nonzero(self.first >= 0))


def query_spheres(tree: MeshTree, pose: Pose, centers: np.ndarray, radii: np.ndarray,
                  volume: str = "aabb") -> SphereQuery:
    """Spheres (centres (K, 3) m, radii (K,) m) against the mesh of ``tree`` posed by
    ``pose``, each by a walk of its BVH with ``volume`` (one of VOLUME_NAMES) at every node."""
    if volume not in VOLUME_NAMES:
        raise ValueError(f"volume {volume!r}: one of {', '.join(VOLUME_NAMES)}")
    code = VOLUME_NAMES.index(volume)
    w, refitted = posed(tree, pose, code)
    centers = np.ascontiguousarray(centers, dtype=np.float64).reshape(-1, 3)
    radii = np.ascontiguousarray(radii, dtype=np.float64).reshape(-1)
    first = np.empty(len(centers), dtype=np.int64)
    node_tests, triangle_tests = _query(code, w, tree.nodes.root, centers, radii, first)
    return SphereQuery(volume, first, int(node_tests), int(triangle_tests), refitted)


def brute_force(tree: MeshTree, pose: Pose, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(K,) each sphere's lowest-numbered touching triangle (-1: none), every triangle tested."""
    corners = pose.apply(tree.vertices)[tree.faces]
    out = np.full(len(centers), -1, dtype=np.int64)
    for k, (c, r) in enumerate(zip(np.asarray(centers, dtype=np.float64), radii, strict=True)):
        for t, tri in enumerate(corners):
            q = np.array(closest_on_triangle(*c, *tri.ravel())[:3])
            if float(np.sum((c - q) ** 2)) <= float(r) ** 2:
                out[k] = t
                break
    return out


__all__ = ["SphereQuery", "brute_force", "query_spheres"]
