"""engine/mesh: the triangle test, every node volume, and the two-tree descent against brute force."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physdbg.engine.broadphase.bvh import BUILD_NAMES
from physdbg.engine.mesh import VOLUME_NAMES, Pose, brute_force, build_mesh_tree, descend
from physdbg.engine.mesh.descent import APART, HULLS_APART, LEAVES_MEET, MEET, posed
from physdbg.engine.mesh.tree import AABB
from physdbg.engine.mesh.tritri import brute_force_pairs
from physdbg.meshes import convex_hull, load_mesh, mesh_tree
from physdbg.meshes.shapes import SHAPES


def _segment_crosses(p, q, a, b, c) -> bool:
    """Does segment pq meet triangle abc (Möller–Trumbore, touching counts)? An independent test."""
    d = q - p
    e1, e2 = b - a, c - a
    h = np.cross(d, e2)
    det = e1 @ h
    if abs(det) < 1e-15:
        return False
    s = p - a
    u = (s @ h) / det
    qv = np.cross(s, e1)
    v = (d @ qv) / det
    t = (e2 @ qv) / det
    return 0 <= u <= 1 and 0 <= v and u + v <= 1 and 0 <= t <= 1


def _edges_pierce(t1, t2) -> bool:
    """Two triangles in different planes meet iff an edge of one meets the other."""
    return any(_segment_crosses(x[i], x[(i + 1) % 3], *y) for x, y in ((t1, t2), (t2, t1)) for i in range(3))


def test_the_triangle_test_agrees_with_edge_piercing_on_random_triangles():
    rng = np.random.default_rng(7)
    met = 0
    for _ in range(4000):
        t1 = rng.uniform(-1, 1, (3, 3))
        t2 = rng.uniform(-1, 1, (3, 3)) + rng.uniform(-0.8, 0.8, 3)
        ours = len(brute_force_pairs(t1, np.array([[0, 1, 2]]), t2, np.array([[0, 1, 2]]))) == 1
        assert ours == _edges_pierce(t1, t2)
        met += ours
    assert 400 < met < 3600  # both answers are common


def test_touching_and_coplanar_triangles_meet_and_parallel_ones_do_not():
    one = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    face = np.array([[0, 1, 2]])

    def meet(other):
        return len(brute_force_pairs(one, face, np.asarray(other, dtype=float), face)) == 1

    assert meet([[1.0, 0, 0], [2, 0, 0], [1, 1, 1]])             # a shared corner
    assert meet([[0.2, 0.2, 0], [0.3, 0.2, 1], [0.2, 0.3, 1]])   # a corner on the face
    assert meet([[0.2, 0.2, 0], [1.2, 0.2, 0], [0.2, 1.2, 0]])   # coplanar, overlapping
    assert meet([[0.1, 0.1, 0], [0.2, 0.1, 0], [0.1, 0.2, 0]])   # coplanar, inside
    assert not meet([[1.1, 1.1, 0], [2, 1.1, 0], [1.1, 2, 0]])   # coplanar, apart
    assert not meet([[0.0, 0, 1e-6], [1, 0, 1e-6], [0, 1, 1e-6]])  # parallel, a micrometre above
    # the test does not depend on the unit: the same at a millionth of the size
    assert meet(np.array([[0.2, 0.2, 0], [0.3, 0.2, 1], [0.2, 0.3, 1]]) * 1e-6) == \
        (len(brute_force_pairs(one * 1e-6, face, np.array([[0.2, 0.2, 0], [0.3, 0.2, 1], [0.2, 0.3, 1]]) * 1e-6,
                               face)) == 1)


@pytest.mark.parametrize("shape", sorted(SHAPES))
@pytest.mark.parametrize("builder", BUILD_NAMES)
def test_every_node_volume_holds_every_corner_beneath_it(shape, builder):
    mesh = load_mesh(shape)
    tree = mesh_tree(mesh, builder)
    order, faces, vertices = tree.nodes.order, tree.faces, tree.vertices
    for node in range(tree.size):
        corners = vertices[faces[order[tree.first[node]:tree.end[node]]]].reshape(-1, 3)
        assert np.all(corners >= tree.nodes.lo[node] - 1e-12) and np.all(corners <= tree.nodes.hi[node] + 1e-12)
        assert np.all(np.linalg.norm(corners - tree.sphere_center[node], axis=1) <= tree.sphere_radius[node])
        local = (corners - tree.obb_center[node]) @ tree.obb_axes[node].T
        assert np.all(np.abs(local) <= tree.obb_half[node])
        assert np.allclose(tree.obb_axes[node] @ tree.obb_axes[node].T, np.eye(3))
    # a leaf holds one triangle and the leaves hold each triangle once
    assert sorted(tree.leaf_triangle(n) for n in tree.nodes.leaves) == list(range(mesh.triangles))


def test_an_obb_fits_a_turned_plate_closer_than_its_aabb():
    vertices, faces = SHAPES["paddle"]()
    turned = Pose.of(degrees=(0, 0, 45)).apply(vertices)
    tree = build_mesh_tree(turned, faces)
    root = tree.nodes.root
    assert tree.obb_from_pca[root]
    assert np.prod(tree.obb_half[root]) < 0.5 * np.prod(0.5 * (tree.nodes.hi[root] - tree.nodes.lo[root]))


_SHAPE_PAIRS = [("icosphere", "paddle"), ("funnel", "icosphere"), ("box-with-hole", "paddle"), ("ramp", "funnel")]
_TREES = {(s, b): mesh_tree(load_mesh(s), b) for s in SHAPES for b in BUILD_NAMES}

pose_strategy = st.tuples(st.tuples(*[st.floats(-1.2, 1.2)] * 3), st.tuples(*[st.floats(-180, 180)] * 3))


@settings(max_examples=40, deadline=None)
@given(pair=st.sampled_from(_SHAPE_PAIRS), builder_a=st.sampled_from(BUILD_NAMES),
       builder_b=st.sampled_from(BUILD_NAMES), pose_a=pose_strategy, pose_b=pose_strategy)
def test_the_descent_finds_exactly_the_brute_force_pairs_for_every_volume_and_builder(pair, builder_a, builder_b,
                                                                                      pose_a, pose_b):
    a, b = _TREES[(pair[0], builder_a)], _TREES[(pair[1], builder_b)]
    pa, pb = Pose.of(*pose_a), Pose.of(*pose_b)
    reference = brute_force(a, pa, b, pb)
    for volume in VOLUME_NAMES:
        for hull in (True, False):
            found = descend(a, pa, b, pb, volume, hull=hull)
            assert np.array_equal(found.pairs, reference), (volume, hull)
            if found.hull_test != "apart":
                # every leaf pair that met is in the log, and a test was counted per pair visited
                assert found.volume_tests == len(found.log)
                assert np.sum(found.log[:, 2] == LEAVES_MEET) == len(reference)
                assert found.triangle_tests <= a.faces.shape[0] * b.faces.shape[0]


def test_the_descent_log_is_the_search_tree():
    a, b = _TREES[("icosphere", "sah")], _TREES[("paddle", "sah")]
    found = descend(a, Pose(), b, Pose.of((0.5, 0.0, 0.0), (0, 0, 30)), "obb", hull=False)
    log = found.log
    assert tuple(log[0, :2]) == (a.nodes.root, b.nodes.root) and log[0, 2] == MEET
    # each pair after the root is a child pair of a pair that met, split on one side
    met = {(int(i), int(j)) for i, j, outcome, _ in log if outcome == MEET}
    for i, j, _, parent in log[1:]:
        pa, pb = a.nodes.parent[i], b.nodes.parent[j]
        assert (int(pa), int(j)) in met or (int(i), int(pb)) in met
        # and the row it names as its parent is that pair, which met
        assert log[parent, 2] == MEET and tuple(log[parent, :2]) in {(pa, j), (i, pb)}
    # culling did work: far fewer triangle tests than pairs of triangles
    assert found.triangle_tests < a.faces.shape[0] * b.faces.shape[0] / 20
    assert np.any(log[:, 2] == APART)


def test_a_turned_mesh_refits_its_aabbs_and_only_moves_its_obbs_and_spheres():
    tree = _TREES[("paddle", "sah")]
    _, moved = posed(tree, Pose.of((1.0, 2.0, 3.0)), AABB)
    _, turned = posed(tree, Pose.of(degrees=(0, 0, 30)), AABB)
    assert moved == 0 and turned == tree.size
    assert descend(tree, Pose(), tree, Pose.of((0.1, 0, 0), (0, 0, 30)), "obb").refitted == 0


def test_hulls_apart_end_the_search_before_any_node_test():
    a, b = _TREES[("icosphere", "sah")], _TREES[("icosphere", "sah")]
    far = descend(a, Pose(), b, Pose.of((1.02, 0.0, 0.0)), "aabb")  # radius 0.5 each: 2 cm apart
    assert far.hull_test == "apart" and far.volume_tests == 0 and far.log.tolist() == [[-1, -1, HULLS_APART, -1]]
    near = descend(a, Pose(), b, Pose.of((0.99, 0.0, 0.0)), "aabb")
    assert near.hull_test == "meet" and near.meet


def test_a_hull_bounds_its_mesh():
    mesh = load_mesh("funnel")
    normals, offsets, points = convex_hull(mesh.vertices)
    assert np.all(mesh.vertices @ normals.T <= offsets + 1e-12)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)


def test_a_hull_too_big_to_pay_is_skipped_and_said():
    from physdbg.engine.mesh.descent import HULL_TEST_WORK
    from physdbg.meshes import Mesh

    vertices, faces = SHAPES["icosphere"](0.5, 4)  # 5,120 triangles: a hull of 2,562 corners
    mesh = Mesh("fine", "shape", vertices, faces, hull=convex_hull(vertices))
    tree = mesh_tree(mesh)
    assert 2 * len(tree.hull_offsets) * len(tree.hull_points) > HULL_TEST_WORK
    found = descend(tree, Pose(), tree, Pose.of((1.02, 0.0, 0.0)), "aabb")
    assert found.hull_test == "too big" and not found.meet and found.volume_tests > 0


@settings(max_examples=30, deadline=None)
@given(shape=st.sampled_from(["icosphere", "funnel", "paddle", "box-with-hole"]), builder=st.sampled_from(BUILD_NAMES),
       pose=pose_strategy, seed=st.integers(0, 2**32 - 1))
def test_spheres_against_a_mesh_find_the_brute_force_triangles_with_every_volume(shape, builder, pose, seed):
    """engine/mesh/query.py: each sphere's lowest touching triangle, by a walk of the BVH
    with the sphere, the AABB or the OBB at every node, is the all-triangles answer; and
    the walk culls (fewer triangle tests than spheres × triangles)."""
    from physdbg.engine.mesh.query import brute_force as spheres_brute_force
    from physdbg.engine.mesh.query import query_spheres

    tree = _TREES[(shape, builder)]
    placed = Pose.of(*pose)
    corners = placed.apply(tree.vertices)
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    rng = np.random.default_rng(seed)
    centers = rng.uniform(lo - 0.2, hi + 0.2, (60, 3))
    radii = rng.uniform(0.01, 0.15, 60)
    expected = spheres_brute_force(tree, placed, centers, radii)
    for volume in VOLUME_NAMES:
        found = query_spheres(tree, placed, centers, radii, volume)
        assert found.first.tolist() == expected.tolist(), volume
        assert found.triangle_tests < 60 * tree.faces.shape[0]
