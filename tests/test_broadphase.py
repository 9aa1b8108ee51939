"""Every broad phase returns exactly the brute-force pair set; BVH invariants hold."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physdbg.engine.broadphase import BruteForce, choose_broad_phase, make_broad_phase
from physdbg.engine.broadphase.bvh import BUILD_NAMES, BVH, build, sah_cost
from physdbg.events import BroadPhaseInfo
from physdbg.observe import ListObserver
from physdbg.api import load_scene

FAST = ["grid", "bvh-sah", "bvh-median", "bvh-mean", "bvh-lbvh"]


@st.composite
def boxes(draw):
    """Sphere boxes with the awkward cases the issue names."""
    n = draw(st.integers(0, 60))
    layout = draw(st.sampled_from(["random", "one point", "cell boundaries", "mixed 100x", "one far away"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    if layout == "one point":
        centres = np.full((n, 3), 0.5)
        radius = np.full(n, 0.1)
    elif layout == "cell boundaries":
        # centres and box faces on multiples of the cell size the grid will pick (0.2)
        centres = rng.integers(0, 5, size=(n, 3)) * 0.2
        radius = np.full(n, 0.1)
    elif layout == "mixed 100x":
        centres = rng.uniform(0.0, 3.0, size=(n, 3))
        radius = 0.01 * 100.0 ** rng.uniform(0.0, 1.0, size=n)
    elif layout == "one far away":
        # a sparse grid (far more cells than boxes: the grid looks cells up by search)
        centres = rng.uniform(0.0, 2.0, size=(n, 3))
        radius = rng.uniform(0.05, 0.2, size=n)
        if n:
            centres[rng.integers(n)] = rng.uniform(1e3, 1e4, size=3)
    else:
        centres = rng.uniform(0.0, 2.0, size=(n, 3))
        radius = rng.uniform(0.05, 0.2, size=n)
    return centres - radius[:, None], centres + radius[:, None]


@settings(max_examples=150, deadline=None)
@given(box=boxes(), name=st.sampled_from(FAST))
def test_every_broad_phase_finds_exactly_the_brute_force_pairs(box, name):
    lo, hi = box
    expected = BruteForce().pairs(lo, hi)
    got = make_broad_phase(name).pairs(lo, hi)
    np.testing.assert_array_equal(got, expected)
    assert got.dtype == np.int64 and got.shape[1:] == (2,)


@pytest.mark.parametrize("name", FAST + ["brute-force"])
def test_single_box_queries_match_brute_force(name):
    rng = np.random.default_rng(5)
    c = rng.uniform(0, 1, (300, 3))
    r = rng.uniform(0.01, 0.05, (300, 1))
    lo, hi = c - r, c + r
    bp = make_broad_phase(name)
    bp.pairs(lo, hi)
    for k in range(20):
        box_lo, box_hi = c[k] - 0.1, c[k] + 0.1
        expected = np.nonzero(np.all((box_lo <= hi) & (lo <= box_hi), axis=1))[0]
        np.testing.assert_array_equal(bp.query(lo, hi, box_lo, box_hi), expected)


@pytest.mark.parametrize("method", BUILD_NAMES)
@pytest.mark.parametrize("n", [1, 2, 3, 17, 256, 1000])
def test_bvh_invariants(method, n):
    rng = np.random.default_rng(n)
    c = rng.uniform(0, 1, (n, 3)) * [1.0, 0.3, 2.0]
    r = 0.01 * 50 ** rng.uniform(0, 1, (n, 1))
    lo, hi = c - r, c + r
    tree = build(lo, hi, method, leaf_size=1)
    assert tree.size == 2 * n - 1  # one-primitive leaves: a full binary tree
    leaves = tree.leaves
    assert len(leaves) == n
    covered = np.sort(np.concatenate([tree.order[tree.start[k]:tree.start[k] + tree.count[k]] for k in leaves]))
    np.testing.assert_array_equal(covered, np.arange(n))  # every particle in exactly one leaf
    for node in range(tree.size):
        if tree.left[node] >= 0:
            for child in (tree.left[node], tree.right[node]):
                assert np.all(tree.lo[node] <= tree.lo[child]) and np.all(tree.hi[child] <= tree.hi[node])
                assert tree.parent[child] == node and tree.depth[child] == tree.depth[node] + 1
        else:
            p = tree.order[tree.start[node]]
            np.testing.assert_array_equal(tree.lo[node], lo[p])
            np.testing.assert_array_equal(tree.hi[node], hi[p])
    assert tree.parent[tree.root] == -1
    if method == "median":
        assert tree.max_depth == math.ceil(math.log2(n)) if n > 1 else tree.max_depth == 0


def test_larger_leaves_use_fewer_nodes_and_find_the_same_pairs():
    rng = np.random.default_rng(2)
    c = rng.uniform(0, 1, (500, 3))
    lo, hi = c - 0.03, c + 0.03
    tree = build(lo, hi, "sah", leaf_size=4)
    assert tree.size < 2 * 500 - 1 and np.all(tree.count[tree.leaves] <= 4)
    bvh = BVH(method="median", leaf_size=4)
    np.testing.assert_array_equal(bvh.pairs(lo, hi), BruteForce().pairs(lo, hi))


def test_sah_split_beats_median_on_clustered_boxes():
    rng = np.random.default_rng(3)
    # two dense clusters far apart along x, plus a sprinkle between them
    c = np.concatenate([rng.normal([0, 0, 0], 0.05, (400, 3)), rng.normal([10, 0, 0], 0.05, (100, 3)),
                        rng.uniform([0, -1, -1], [10, 1, 1], (20, 3))])
    lo, hi = c - 0.02, c + 0.02
    costs = {m: sah_cost(*(lambda t: (t.lo, t.hi, t.left, t.count, t.root))(build(lo, hi, m))) for m in BUILD_NAMES}
    assert costs["sah"] <= costs["median"]


def test_refit_keeps_the_tree_until_it_degrades_then_rebuilds():
    rng = np.random.default_rng(4)
    c = rng.uniform(0, 1, (200, 3))
    bvh = BVH(method="sah")
    bvh.pairs(c - 0.02, c + 0.02)
    assert bvh.stats["rebuilt"] is True
    c += rng.normal(0, 1e-4, c.shape)  # small motion: refit is enough
    np.testing.assert_array_equal(bvh.pairs(c - 0.02, c + 0.02), BruteForce().pairs(c - 0.02, c + 0.02))
    assert bvh.stats["rebuilt"] is False
    shuffled = rng.permutation(c)  # everything moved far: the refitted tree is poor
    np.testing.assert_array_equal(bvh.pairs(shuffled - 0.02, shuffled + 0.02),
                                  BruteForce().pairs(shuffled - 0.02, shuffled + 0.02))
    assert bvh.stats["rebuilt"] is True


@pytest.mark.parametrize("scene, overrides", [
    ("rain", ["steps=40"]),
    ("billiards", ["steps=60"]),
    ("gas", ["steps=40", "generate.count=125"]),
])
def test_worlds_are_bit_identical_whatever_the_broad_phase(scene, overrides):
    """Pairs come out sorted and identical, so the whole run must not change."""
    hashes = {}
    for name in ["brute-force"] + FAST:
        loaded = load_scene(scene, overrides + [f"broad_phase={name}"])
        world = loaded.build_world()
        hashes[name] = [world.step(loaded.dt).state_hash for _ in range(loaded.steps)]
    reference = hashes.pop("brute-force")
    for name, run in hashes.items():
        assert run == reference, name


def test_auto_explains_its_choice():
    assert choose_broad_phase("auto", np.full(10, 0.1))[0] == "brute-force"
    name, reason = choose_broad_phase("auto", np.full(500, 0.1))
    assert name == "grid" and "similar radii" in reason
    name, reason = choose_broad_phase("auto", np.r_[np.full(499, 0.01), 1.0])
    assert name == "bvh-lbvh" and "100x" in reason
    assert choose_broad_phase("bvh-lbvh", np.full(500, 0.1)) == ("bvh-lbvh", "chosen in the scene")


def test_observers_get_the_bvh_nodes_every_step():
    scene = load_scene("rain", ["steps=3", "broad_phase=bvh-sah"])
    obs = ListObserver()
    world = scene.build_world(obs)
    for _ in range(3):
        world.step(scene.dt)
    infos = obs.of_type(BroadPhaseInfo)
    assert len(infos) == 3
    nodes = infos[0].nodes
    assert nodes["lo"].shape == (2 * 100 - 1, 3)
    assert set(infos[0].stats) >= {"build_seconds", "query_seconds", "nodes_visited", "box_tests", "sah_cost",
                                   "rebuilt"}
    assert infos[0].stats["rebuilt"] is True and infos[1].stats["rebuilt"] is False
