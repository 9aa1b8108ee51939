"""A mesh's own BVH, in its local frame, with every bounding volume of the seed per node.

The tree is built once by the scene BVH's builders (``broadphase.bvh``: median, mean, SAH
top-down; LBVH bottom-up) over the triangles' boxes, one triangle per leaf, in the mesh's
local frame; a pose moves it (``mesh.descent``). Each node carries three volumes around
the corners of every triangle beneath it:

* **AABB** ``lo, hi`` (M, 3): the builder's own boxes. Under a rotation an AABB no longer
  bounds its triangles, so a turned mesh's boxes are *refitted* from its moved corners
  (the seed: bounds "need to be updated as objects move"), O(M) per pose;
* **sphere** ``sphere_center`` (M, 3), ``sphere_radius`` (M,): centred on the node's box,
  the radius reaching its farthest corner; a pose moves the centre only;
* **OBB** ``obb_center`` (M, 3), ``obb_axes`` (M, 3, 3) (rows: unit axes), ``obb_half``
  (M, 3): the smaller of two candidate frames, the principal axes of the node's corners
  (PCA) and the local axes; a pose turns it, never refits it.

and the mesh as a whole may carry its **convex hull** (``hull_normals`` (H, 3),
``hull_offsets`` (H,), ``hull_points`` (K, 3): n·x ≤ offset inside), computed by qhull in
``physdbg.meshes`` and used as an early-out before the descent.

Every volume is padded by ``VOLUME_PAD`` times the mesh's size so that rounding in a pose
never makes a volume miss a triangle it bounds (the descent must find exactly the pairs the
brute-force test finds).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..broadphase.bvh import BUILD_NAMES, BVHNodes, build
from ..jit import kernel

VOLUME_PAD = 1e-9  # times the mesh's bounding-box diagonal
# the one table of the three volume kinds, by code: a mesh's walk (colliders/mesh.py), its
# recorded tree (the mesh-tree channel's ``volume``), the views and the pair descent all read it
VOLUME_NAMES = ("aabb", "sphere", "obb")
AABB, SPHERE, OBB = 0, 1, 2


@kernel
def _node_ranges(left, right, start, count, root):
    """Each node's range [first, end) of the tree's triangle order (leaves are contiguous
    there for every builder, so a node covers one range: its leaves')."""
    m = left.shape[0]
    first = np.empty(m, dtype=np.int64)
    end = np.empty(m, dtype=np.int64)
    visit = np.empty(m, dtype=np.int64)
    stack = np.empty(m, dtype=np.int64)
    top = 0
    n = 0
    if m == 0:
        return first, end
    stack[0] = root
    top = 1
    while top > 0:  # pre-order; children are then fitted before parents in reverse
        top -= 1
        node = stack[top]
        visit[n] = node
        n += 1
        if left[node] >= 0:
            stack[top] = left[node]
            stack[top + 1] = right[node]
            top += 2
    for k in range(n - 1, -1, -1):
        node = visit[k]
        if left[node] < 0:
            first[node] = start[node]
            end[node] = start[node] + count[node]
        else:
            first[node] = min(first[left[node]], first[right[node]])
            end[node] = max(end[left[node]], end[right[node]])
    return first, end


@kernel
def _corner_moments(vertices, faces, order, first, end):
    """Mean (M, 3) and covariance (M, 3, 3) of the corners of each node's triangles."""
    m = first.shape[0]
    mean = np.zeros((m, 3))
    cov = np.zeros((m, 3, 3))
    for node in range(m):
        k = 0
        for t in range(first[node], end[node]):
            for c in range(3):
                p = vertices[faces[order[t], c]]
                for i in range(3):
                    mean[node, i] += p[i]
                k += 1
        for i in range(3):
            mean[node, i] /= k
        for t in range(first[node], end[node]):
            for c in range(3):
                p = vertices[faces[order[t], c]]
                for i in range(3):
                    for j in range(3):
                        cov[node, i, j] += (p[i] - mean[node, i]) * (p[j] - mean[node, j])
        for i in range(3):
            for j in range(3):
                cov[node, i, j] /= k
    return mean, cov


@kernel
def _boxes_in_frames(vertices, faces, order, first, end, axes):
    """Centre (M, 3) in local coordinates and half extents (M, 3) of each node's corners
    along its frame ``axes`` (M, 3, 3) (rows: unit axes)."""
    m = first.shape[0]
    center = np.empty((m, 3))
    half = np.empty((m, 3))
    lo = np.empty(3)
    hi = np.empty(3)
    for node in range(m):
        lo[:] = np.inf
        hi[:] = -np.inf
        for t in range(first[node], end[node]):
            for c in range(3):
                p = vertices[faces[order[t], c]]
                for a in range(3):
                    s = axes[node, a, 0] * p[0] + axes[node, a, 1] * p[1] + axes[node, a, 2] * p[2]
                    lo[a] = min(lo[a], s)
                    hi[a] = max(hi[a], s)
        for i in range(3):
            center[node, i] = 0.0
        for a in range(3):
            half[node, a] = 0.5 * (hi[a] - lo[a])
            mid = 0.5 * (hi[a] + lo[a])
            for i in range(3):
                center[node, i] += mid * axes[node, a, i]
    return center, half


@kernel
def _sphere_radii(vertices, faces, order, first, end, center):
    """Radius (M,) reaching the farthest corner of each node's triangles from ``center`` (M, 3)."""
    m = first.shape[0]
    radius = np.zeros(m)
    for node in range(m):
        r2 = 0.0
        for t in range(first[node], end[node]):
            for c in range(3):
                p = vertices[faces[order[t], c]]
                d = 0.0
                for i in range(3):
                    d += (p[i] - center[node, i]) ** 2
                r2 = max(r2, d)
        radius[node] = np.sqrt(r2)
    return radius


def triangle_boxes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's box (lo, hi) (F, 3) from ``vertices`` (V, 3) and ``faces`` (F, 3)."""
    corners = vertices[faces]  # (F, 3 corners, 3)
    return np.ascontiguousarray(corners.min(axis=1)), np.ascontiguousarray(corners.max(axis=1))


@dataclass
class MeshTree:
    """A mesh's BVH with every node's volumes (the module doc), all in its local frame.

    ``vertices`` (V, 3) m, ``faces`` (F, 3) int64 vertex indices; ``nodes`` the BVH
    (``broadphase.bvh.BVHNodes``; leaves hold one triangle: ``nodes.order[nodes.start[leaf]]``);
    ``first, end`` (M,) each node's range of ``nodes.order``; ``pad`` m, added to every volume.
    """

    vertices: np.ndarray
    faces: np.ndarray
    builder: str
    nodes: BVHNodes
    first: np.ndarray
    end: np.ndarray
    sphere_center: np.ndarray
    sphere_radius: np.ndarray
    obb_center: np.ndarray
    obb_axes: np.ndarray
    obb_half: np.ndarray
    obb_from_pca: np.ndarray
    pad: float
    hull_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    hull_offsets: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hull_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def size(self) -> int:
        """Number of nodes M."""
        return self.nodes.size

    @property
    def has_hull(self) -> bool:
        return self.hull_normals.shape[0] > 0

    def leaf_triangle(self, node: int) -> int:
        """The triangle (face index) of leaf ``node``."""
        return int(self.nodes.order[self.nodes.start[node]])


def build_mesh_tree(vertices: np.ndarray, faces: np.ndarray, builder: str = "sah",
                    hull: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> MeshTree:
    """The BVH of one mesh (``vertices`` (V, 3) m, ``faces`` (F ≥ 1, 3)) by ``builder``
    (one of ``broadphase.bvh.BUILD_NAMES``), with every node's volumes; ``hull`` the
    convex hull's (normals (H, 3), offsets (H,), points (K, 3)) if the caller has one."""
    if builder not in BUILD_NAMES:
        raise ValueError(f"builder {builder!r}: one of {', '.join(BUILD_NAMES)}")
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.shape[0] == 0:
        raise ValueError(f"faces: a (F >= 1, 3) array of vertex indices, not shape {faces.shape}")
    lo, hi = triangle_boxes(vertices, faces)
    nodes = build(lo, hi, builder, 1)
    first, end = _node_ranges(nodes.left, nodes.right, nodes.start, nodes.count, nodes.root)
    diagonal = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    pad = VOLUME_PAD * max(diagonal, np.finfo(float).tiny)
    order = nodes.order
    # sphere: centred on the node's box
    sphere_center = np.ascontiguousarray(0.5 * (nodes.lo + nodes.hi))
    sphere_radius = _sphere_radii(vertices, faces, order, first, end, sphere_center) + pad
    # OBB: the smaller of the principal frame and the local axes
    _, cov = _corner_moments(vertices, faces, order, first, end)
    _, vectors = np.linalg.eigh(cov)  # columns: principal axes
    pca_axes = np.ascontiguousarray(np.transpose(vectors, (0, 2, 1)))
    pca_center, pca_half = _boxes_in_frames(vertices, faces, order, first, end, pca_axes)
    box_half = 0.5 * (nodes.hi - nodes.lo)
    pca_volume = np.prod(pca_half + pad, axis=1)
    box_volume = np.prod(box_half + pad, axis=1)
    from_pca = pca_volume < box_volume
    obb_axes = np.where(from_pca[:, None, None], pca_axes, np.eye(3)[None, :, :])
    obb_center = np.where(from_pca[:, None], pca_center, sphere_center)
    obb_half = np.where(from_pca[:, None], pca_half, box_half) + pad
    tree = MeshTree(vertices, faces, builder, nodes, first, end, sphere_center, sphere_radius,
                    np.ascontiguousarray(obb_center), np.ascontiguousarray(obb_axes),
                    np.ascontiguousarray(obb_half), from_pca, pad)
    if hull is not None:
        tree.hull_normals, tree.hull_offsets, tree.hull_points = (np.ascontiguousarray(a, dtype=np.float64)
                                                                  for a in hull)
        tree.hull_offsets = tree.hull_offsets + pad
    return tree
