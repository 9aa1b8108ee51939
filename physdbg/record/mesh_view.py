"""What the views draw of a mesh: its BVH by level with every volume, and each step's search.

A recording keeps each mesh's triangles at run time 0 (and a kinematic mesh's motion), so
its trees are the header's mesh set (state.Meshes.mesh_set, engine/mesh/mesh_set.py: built
once, SAH, the engine's own): per node an AABB, an OBB and a bounding sphere, in the
mesh's own frame (the frame the mesh had at run time 0; a view turns them with the mesh).

The search drawn for a step is the seed's "search tree … that records descent into each
BVH", for spheres against the triangles, as the engine made it: the recording's
events.MeshSearch (the boxes the engine asked each mesh's tree with, and every node its
walk visited), nodes numbered by the set's pre-order positions (``tree_table`` is the
recording's /physdbg/mesh_tree). ``search`` is the reference
walk the recorded one is tested against: a Python stack walk from each tree's root with a
box carried into the mesh's frame as the engine carries it (``colliders.mesh.frame_box``,
for a kinematic mesh grown by its motion over the step); a node whose box meets it is
descended into (met), one whose box does not ends that branch (culled), and the leaves met
are the triangles the narrow phase tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..events import SEARCH_CULLED as CULLED, SEARCH_MET as MET, SEARCH_REACHED as REACHED  # a visit's outcome


@dataclass
class ReferenceSearch:
    """The reference walk's search (``search``): ``met`` and ``culled`` (nodes of the engine's
    tree, each visited node once: met when any sphere's box met it), ``pairs`` (how many
    sphere–node pairs were visited), ``triangles`` (the triangles reached, numbered in the
    scene) and ``spheres`` (those whose box reached a triangle).

    The search tree itself: ``visits`` (P, 4) int64, one row per sphere–node pair in the
    order visited: sphere, node, outcome (MET, CULLED or REACHED), the row of the pair it
    was descended from (-1 for a sphere's root pair)."""

    met: np.ndarray
    culled: np.ndarray
    pairs: int
    triangles: np.ndarray
    spheres: np.ndarray
    visits: np.ndarray


def search(meshes, lo: np.ndarray, hi: np.ndarray, time: float, dt: float) -> ReferenceSearch:
    """Walk the engine's triangle trees (the mesh set of ``meshes``, a state.Meshes, placed
    here for the step that begins at run time ``time`` and lasts ``dt`` s) with each box
    lo, hi (K, 3) (world frame), each mesh's tree from its root with the box carried into
    its frame. Nodes are the set's pre-order positions and tested with the volume each
    mesh is walked with (``_meets``); a triangle is its number in the scene
    (state.Meshes.triangle_words names it)."""
    from ..engine.colliders.mesh import MeshGeometry, frame_box, place
    from ..engine.mesh.tree import VOLUME_NAMES
    from ..engine.state import Walls

    trees = meshes.mesh_set
    group = tuple(MeshGeometry.of(Walls(meshes=meshes)))
    place(group, meshes, time, dt)
    box_lo, box_hi, leaf, skip, tree_first = trees.box_lo, trees.box_hi, trees.leaf_triangle, trees.skip, trees.tree_first
    volume, node_sphere, node_obb = trees.volume, trees.node_sphere, trees.node_obb
    size = len(leaf)
    met = np.zeros(size, dtype=bool)
    visited = np.zeros(size, dtype=bool)
    reached, who = set(), set()
    visits = []
    for k in range(len(lo) if size else 0):
        for mesh in range(len(tree_first) - 1):
            carried = np.array(frame_box(mesh, *lo[k], *hi[k], group))  # lo then hi, in the mesh's frame
            low, high = carried[:3], carried[3:]
            stack = [(int(tree_first[mesh]), -1)]
            while stack:
                q, parent = stack.pop()
                row = len(visits)
                visited[q] = True
                if not _meets(VOLUME_NAMES[volume[mesh]], low, high, q, box_lo, box_hi, node_sphere, node_obb):
                    visits.append((k, q, CULLED, parent))
                    continue
                met[q] = True
                if leaf[q] >= 0:
                    visits.append((k, q, REACHED, parent))
                    reached.add(int(leaf[q]))
                    who.add(k)
                else:
                    visits.append((k, q, MET, parent))
                    stack += [(int(skip[q + 1]), row), (q + 1, row)]
    return ReferenceSearch(np.flatnonzero(met), np.flatnonzero(visited & ~met), len(visits),
                      np.array(sorted(reached), dtype=np.int64), np.array(sorted(who), dtype=np.int64),
                      np.array(visits, dtype=np.int64).reshape(-1, 4))


def tree_table(trees) -> dict[str, np.ndarray]:
    """A mesh set's trees (engine/mesh/mesh_set.MeshSet) as the columns of the recording's
    mesh-tree channel (format.MESH_TREE_FIELDS): node, mesh, parent, depth, triangle (-1
    inside a tree), skip (the position after the node's subtree), lo, hi (Q, 3) m in the
    mesh's frame, volume (the walked one: engine/mesh/tree.VOLUME_NAMES), and every node's
    sphere and OBB."""
    obb = trees.node_obb
    return {"node": np.arange(len(trees.leaf_triangle)), "mesh": trees.node_mesh, "parent": trees.parent,
            "depth": trees.depth, "triangle": trees.leaf_triangle, "skip": trees.skip, "lo": trees.box_lo,
            "hi": trees.box_hi, "volume": trees.volume[trees.node_mesh], "sphere_center": trees.node_sphere[:, :3],
            "sphere_radius": trees.node_sphere[:, 3], "obb_center": obb[:, :3], "obb_axis_0": obb[:, 3:6],
            "obb_axis_1": obb[:, 6:9], "obb_axis_2": obb[:, 9:12], "obb_half": obb[:, 12:]}


def led_to_contacts(search, contacts, leaf_triangle: np.ndarray):
    """The part of a step's search (events.MeshSearch) that led to its contacts on meshes
    (contacts: the step's events.Contacts): for each such contact, the visits from the root
    down to its triangle in the walk of the query that predicted it (the sphere's last query
    before the contact); the queries renumbered to those kept. leaf_triangle (Q,): each
    node's triangle (-1 inside a tree)."""
    from ..events import KIND_MESH, SEARCH_REACHED, MeshSearch

    keep = np.zeros(len(search.visit_node), dtype=bool)
    if contacts is not None:
        reached = np.flatnonzero(search.visit_outcome == SEARCH_REACHED)
        for row in np.flatnonzero(np.asarray(contacts.kind) == KIND_MESH).tolist():
            sphere, triangle = int(contacts.a[row]), int(contacts.other[row])
            asked = np.flatnonzero((search.query_sphere == sphere) & (search.query_after < row))
            if not len(asked):
                continue
            query = asked[-1]
            hit = reached[(search.visit_query[reached] == query) & (leaf_triangle[search.visit_node[reached]] == triangle)]
            for visit in hit.tolist():
                while visit >= 0 and not keep[visit]:
                    keep[visit] = True
                    visit = int(search.visit_parent[visit])
    rows = np.flatnonzero(keep)
    queries = np.unique(search.visit_query[rows])
    new_row = np.full(len(search.visit_node), -1, dtype=np.int64)
    new_row[rows] = np.arange(len(rows))
    parent = search.visit_parent[rows]
    return MeshSearch(search.step, search.query_sphere[queries], search.query_after[queries],
                      search.query_lo[queries], search.query_hi[queries],
                      np.searchsorted(queries, search.visit_query[rows]).astype(np.int32),
                      search.visit_node[rows], search.visit_outcome[rows],
                      np.where(parent >= 0, new_row[np.maximum(parent, 0)], -1).astype(np.int32))


def searched_spheres(search, contacts, most: int) -> list[int]:
    """The spheres whose walks of the meshes' trees the views draw for a step (at most
    ``most``): those with a contact on a mesh in the step (contacts: its events.Contacts);
    if none, those whose walk reached a triangle; if none, the first asked."""
    from ..events import KIND_MESH, SEARCH_REACHED

    spheres = search.query_sphere
    for chosen in (np.unique(contacts.a[contacts.kind == KIND_MESH]) if contacts is not None else [],
                   np.unique(spheres[search.visit_query[search.visit_outcome == SEARCH_REACHED]]),
                   spheres):
        if len(chosen):
            return [int(i) for i in dict.fromkeys(np.asarray(chosen).tolist())][:most]
    return []


def _meets(volume: str, low: np.ndarray, high: np.ndarray, q: int, box_lo, box_hi, node_sphere, node_obb) -> bool:
    """The reference's test of the query box low, high (3,) against node q's volume: the
    AABB's overlap, the sphere's distance to the box, and for the OBB engine/mesh/volumes'
    own oriented-box test (the box as an oriented box with the world's axes)."""
    if volume == "sphere":
        centre, radius = node_sphere[q, :3], node_sphere[q, 3]
        return float(np.sum((np.clip(centre, low, high) - centre) ** 2)) <= radius * radius
    if volume == "obb":
        from ..engine.mesh.volumes import obbs_meet

        box = (np.array([0.5 * (low + high)]), np.eye(3)[None], np.array([0.5 * (high - low)]))
        obb = node_obb[q]
        return bool(obbs_meet(*box, 0, obb[None, :3], obb[None, 3:12].reshape(1, 3, 3), obb[None, 12:], 0))
    return not (np.any(low > box_hi[q]) or np.any(box_lo[q] > high))


def tree_layout(visits: np.ndarray) -> np.ndarray:
    """(P, 2) positions of the search tree's pairs for a graph view: depth down (y), and
    across (x) each pair over the middle of the pairs below it, leaves side by side in the
    order visited, one sphere's tree after another."""
    count = len(visits)
    children: list[list[int]] = [[] for _ in range(count)]
    roots = []
    for row, (_k, _q, _outcome, parent) in enumerate(visits.tolist()):
        (children[parent] if parent >= 0 else roots).append(row)
    position = np.zeros((count, 2))
    next_x = 0.0
    for root in roots:  # iteratively: post-order, so a pair is placed after those below it
        stack = [(root, 0, False)]
        while stack:
            row, depth, done = stack.pop()
            if not done:
                stack.append((row, depth, True))
                stack += [(child, depth + 1, False) for child in reversed(children[row])]
                continue
            if children[row]:
                position[row, 0] = position[children[row], 0].mean()
            else:
                position[row, 0] = next_x
                next_x += 1.0
            position[row, 1] = depth
        next_x += 1.0  # a gap between two spheres' trees
    return position


def path_boxes(x0: np.ndarray, x1: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (N, 3): each sphere's box from its centre x0 to x1, grown by its radius."""
    r = np.asarray(radius, dtype=np.float64)[:, None]
    return np.minimum(x0, x1) - r, np.maximum(x0, x1) + r


def quaternions(axes: np.ndarray) -> np.ndarray:
    """(M, 4) x, y, z, w quaternions of rotations whose columns are axes[m]'s rows (the OBBs'
    unit axes, (M, 3, 3)), made proper (a reflected frame has one axis flipped)."""
    out = np.empty((len(axes), 4))
    for m, rows in enumerate(axes):
        r = rows.T.copy()
        if np.linalg.det(r) < 0:
            r[:, 2] = -r[:, 2]
        w = np.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
        x = np.copysign(np.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
        y = np.copysign(np.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
        z = np.copysign(np.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
        out[m] = (x, y, z, w)
    return out
