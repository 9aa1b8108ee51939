"""A scene's meshes with their trees, built once: the one owner of every mesh's BVH.

Each mesh of a scene (state.Meshes) has one BVH (``tree.build_mesh_tree``, SAH over its
triangles' boxes, in the frame the mesh has at run time 0), and everything that reads a
tree reads it here: the engine's walks (colliders/mesh.MeshGeometry takes its arrays), the
advisor's choice of volume, the audit's overlaps, the tunnelling check, the recording's
mesh-tree channel and the views' drawings. ``state.Meshes.mesh_set`` builds the set at the
first ask and keeps it, so a scene, and a recording's header, builds each tree once.

The trees are laid out in pre-order one after another (``tree_first`` says where each
mesh's starts): a node's left child follows it, and ``skip`` is the position after its
subtree, so a walk needs no stack. Each position has its AABB (``box_lo``, ``box_hi``),
bounding sphere and OBB (``node_sphere``, ``node_obb``), its triangle (``leaf_triangle``,
numbered in the scene; -1 inside a tree), its parent, depth and mesh. The volume each mesh
is walked with is a code of ``tree.VOLUME_NAMES`` (``volume``; the scene's
bounding_volume). Nothing here moves: a kinematic mesh's placement at a time is its
collider group's (colliders/mesh.place), made from this set.
"""

from __future__ import annotations

import numpy as np

from .tree import VOLUME_NAMES, MeshTree, build_mesh_tree


def preorder_nodes(tree) -> tuple:
    """A built BVH (broadphase.bvh.BVHNodes) laid out in pre-order: (box_lo, box_hi (Q, 3),
    leaf_triangle (Q,), skip (Q,), nodes (Q,): the tree's node at each position)."""
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
            np.ascontiguousarray(leaf, dtype=np.int64), skip, nodes)


class MeshSet:
    """Every mesh of a scene with its tree (the module doc). Built by ``state.Meshes.mesh_set``
    (the engine's trees: SAH); builder: another of broadphase.bvh.BUILD_NAMES, for a test.

    meshes: the scene's state.Meshes; trees: each mesh's MeshTree (its triangles as
    separate corners, triangle t of the mesh at corners 3t..3t+2), in the mesh's run-time-0
    frame. The pre-order layout, Q positions over every tree: box_lo, box_hi (Q, 3) m;
    leaf_triangle (Q,) int64 (the scene's triangle number; -1 inside a tree); skip (Q,)
    int64; parent (Q,) int64 (-1 at a root); depth (Q,) int64 (0 at a root); node_mesh (Q,)
    int64; node_sphere (Q, 4): centre (m) and radius; node_obb (Q, 15): centre, the three
    unit axes as rows, half extents; tree_first (M + 1,) int64."""

    def __init__(self, meshes, builder: str = "sah"):
        self.meshes = meshes
        self.builder = builder
        corners = np.ascontiguousarray(meshes.corners, dtype=np.float64).reshape(-1, 3, 3)
        self.trees: list[MeshTree] = []
        for k in range(len(meshes)):
            mine = corners[meshes.mesh_of == k].reshape(-1, 3)
            self.trees.append(build_mesh_tree(mine, np.arange(len(mine), dtype=np.int64).reshape(-1, 3), builder))
        laid = [preorder_nodes(tree.nodes) for tree in self.trees]
        sizes = [len(one[2]) for one in laid]
        self.tree_first = np.concatenate([[0], np.cumsum(sizes, dtype=np.int64)]).astype(np.int64)
        first = meshes.first
        self.box_lo = _joined([one[0] for one in laid], (0, 3))
        self.box_hi = _joined([one[1] for one in laid], (0, 3))
        # each tree's triangles and skip positions, numbered in the scene
        self.leaf_triangle = _joined([np.where(one[2] >= 0, one[2] + first[k], -1) for k, one in enumerate(laid)],
                                     (0,), np.int64)
        self.skip = _joined([one[3] + self.tree_first[k] for k, one in enumerate(laid)], (0,), np.int64)
        inner = np.flatnonzero(self.leaf_triangle < 0)  # in pre-order a node's left child follows it
        self.parent = np.full(len(self.leaf_triangle), -1, dtype=np.int64)
        self.parent[inner + 1] = inner
        self.parent[self.skip[inner + 1]] = inner  # its right child starts after the left's subtree
        self.depth = np.zeros(len(self.parent), dtype=np.int64)
        for q in np.flatnonzero(self.parent >= 0).tolist():  # pre-order: a parent comes before its children
            self.depth[q] = self.depth[self.parent[q]] + 1
        self.node_mesh = np.repeat(np.arange(len(sizes), dtype=np.int64), sizes)
        # each node's other volumes (tree.py: padded, in the mesh's frame), in pre-order
        self.node_sphere = _joined([np.hstack([tree.sphere_center[one[4]], tree.sphere_radius[one[4], None]])
                                    for tree, one in zip(self.trees, laid, strict=True)], (0, 4))
        self.node_obb = _joined([np.hstack([tree.obb_center[one[4]], tree.obb_axes[one[4]].reshape(-1, 9),
                                            tree.obb_half[one[4]]])
                                 for tree, one in zip(self.trees, laid, strict=True)], (0, 15))

    def __len__(self) -> int:
        return len(self.trees)

    @property
    def volume(self) -> np.ndarray:
        """(M,) int64: the code (tree.VOLUME_NAMES) of the volume each mesh's tree is walked
        with, from the scene's bounding_volume (ValueError while one is still auto)."""
        return np.array([VOLUME_NAMES.index(v) for v in self.meshes.volumes()], dtype=np.int64)

    def nodes_of(self, k: int) -> np.ndarray:
        """(Q_k,) int64: the positions of mesh k's tree, its root first."""
        return np.arange(self.tree_first[k], self.tree_first[k + 1], dtype=np.int64)

    def on_moving_mesh(self, triangles: np.ndarray) -> np.ndarray:
        """(K,) bool: whether each of ``triangles`` (numbered in the scene) is a kinematic mesh's."""
        return self.meshes.moving[self.meshes.mesh_of[np.asarray(triangles, dtype=np.int64)]]

    def trees_per_box(self) -> int:
        """How many trees a box is walked against at once by the simultaneous descent: one
        for every fixed mesh together, and one per kinematic mesh (its own frame)."""
        moving = int(np.count_nonzero(self.meshes.moving))
        return int(moving < len(self)) + moving


def _joined(parts: list, empty_shape: tuple, dtype=np.float64) -> np.ndarray:
    """The parts one after another (contiguous), or an empty array of ``empty_shape``."""
    return np.ascontiguousarray(np.concatenate(parts).astype(dtype, copy=False) if parts
                                else np.zeros(empty_shape, dtype=dtype))
