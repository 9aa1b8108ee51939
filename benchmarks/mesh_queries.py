"""Spheres against a mesh: physdbg's BVH walk with each bounding volume, beside python-fcl.

    .venv/bin/pip install python-fcl      # only this benchmark uses it
    .venv/bin/python benchmarks/mesh_queries.py [--spheres 20000]
    .venv/bin/python benchmarks/mesh_queries.py --together

``--together``: the engine's two searches of a step's path boxes against a mesh
(colliders/mesh.reachable, a walk per box, and reachable_together, the simultaneous
descent) on random triangles and boxes: milliseconds (best of 5), the node tests of each
and the time of the descent's LBVH over the boxes, whence the weights of
engine/mesh_steps.py's TOGETHER_PAIR_COST and TOGETHER_BOX_COST (docs/meshes.md, "Walks or the
simultaneous descent"); the candidates are checked equal.

For each built-in shape (an icosphere of 5,120 triangles, the funnel, the paddle turned
30° about z and x, the box with a hole) the same spheres (random centres in the mesh's
box grown by 10 %, radius 2 % of its diagonal) are asked which touch the mesh:

* physdbg: ``engine.mesh.query.query_spheres`` (one compiled loop over the spheres, a walk
  of the mesh's SAH tree each) with the sphere, AABB and OBB volumes, best of 5 after a
  warm-up; node tests and triangle tests counted; the answers checked against each other;
* python-fcl (FCL's own BVH: OBBRSS, its default): ``fcl.collide`` of a sphere object
  against the mesh object, one call per sphere from Python (its Python API has no batch
  query), with ``num_max_contacts = 1``; the same calls for spheres moved far from the
  mesh (culled at the root) measure the per-call overhead, reported beside it.

Every figure is printed by one run; docs/meshes.md quotes one and names the machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from physdbg.engine.mesh.rigid_motion import Pose
from physdbg.engine.mesh.query import query_spheres
from physdbg.engine.mesh.tree import build_mesh_tree
from physdbg.meshes import SHAPES

VOLUMES = ("sphere", "aabb", "obb")


def cases():
    """(label, vertices, faces, pose) of the meshes compared."""
    ico = SHAPES["icosphere"](0.5, 4)
    yield "icosphere (5,120 triangles)", *ico, Pose()
    yield "funnel", *SHAPES["funnel"](), Pose()
    yield "paddle, turned 30° about z and x", *SHAPES["paddle"](), Pose.of((0.0, 0.0, 0.0), (30.0, 0.0, 30.0))
    yield "box with a hole", *SHAPES["box-with-hole"](), Pose()


def best_of(fn, repeats: int = 5) -> float:
    best = float("inf")
    for _ in range(repeats):
        started = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - started)
    return best


def fcl_queries(vertices, faces, pose, centers, radii):
    """(seconds, touching (K,) bool) of one fcl.collide per sphere."""
    import fcl

    model = fcl.BVHModel()
    model.beginModel(len(vertices), len(faces))
    model.addSubModel(pose.apply(vertices), faces.astype(np.int32))
    model.endModel()
    mesh = fcl.CollisionObject(model, fcl.Transform())
    spheres = [fcl.CollisionObject(fcl.Sphere(float(r)), fcl.Transform(c)) for c, r in zip(centers, radii, strict=True)]
    request = fcl.CollisionRequest(num_max_contacts=1)
    touching = np.zeros(len(spheres), dtype=bool)

    def run():
        for k, sphere in enumerate(spheres):
            touching[k] = fcl.collide(sphere, mesh, request, fcl.CollisionResult()) > 0

    return best_of(run, 3), touching


def together(seed: int) -> None:
    """The walk per box against the simultaneous descent (``--together``), a markdown table."""
    from physdbg.engine.broadphase.bvh import build_lbvh
    from physdbg.engine.colliders.mesh import MeshGeometry, reachable, reachable_together, walk_tests
    from physdbg.engine.state import Meshes, Walls

    rng = np.random.default_rng(seed)
    print("| triangles | path boxes (half side) | walk: ms, node tests | together: ms (of which the tree), node pairs |")
    print("|---|---|---|---|")
    for triangles, half in ((5_000, 0.05), (50_000, 0.05), (50_000, 0.5)):
        corners = rng.uniform(-10, 10, (triangles, 3, 3))
        corners[:, 1:] = corners[:, :1] + rng.normal(0, 0.2, (triangles, 2, 3))
        meshes = Meshes(["m"], np.ones(1), corners, np.zeros(triangles, dtype=np.int64), ["random"],
                        bounding_volume=["aabb"])
        group = tuple(MeshGeometry.of(Walls(meshes=meshes)))
        for boxes in (1_000, 20_000):
            centres = rng.uniform(-10, 10, (boxes, 3))
            lo, hi = centres - half, centres + half
            walked, descended = reachable(lo, hi, group), reachable_together(lo, hi, group)
            assert np.array_equal(walked[0], descended[0]) and np.array_equal(walked[1], descended[1])
            walk_ms = 1e3 * best_of(lambda: reachable(lo, hi, group))
            together_ms = 1e3 * best_of(lambda: reachable_together(lo, hi, group))
            build_lbvh(lo[:10], hi[:10])
            tree_ms = 1e3 * best_of(lambda: build_lbvh(lo, hi))
            print(f"| {triangles:,} | {boxes:,} ({half} m) | {walk_ms:.2f}, {walk_tests(lo, hi, group):,} | "
                  f"{together_ms:.2f} ({tree_ms:.2f}), {descended[2]:,} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--together", action="store_true",
                        help="the engine's walk per path box against its simultaneous descent")
    args = parser.parse_args()
    if args.together:
        together(args.seed)
        return
    rng = np.random.default_rng(args.seed)
    try:
        import fcl  # noqa: F401
        have_fcl = True
    except ImportError:
        have_fcl = False
        print("python-fcl is not installed (pip install python-fcl): physdbg's volumes only")
    print(f"{args.spheres:,} spheres against each mesh; times are the best of several runs in this process")
    print(f"{'mesh':36s} {'query':14s} {'ms':>9s} {'µs/sphere':>10s} {'node tests':>11s} {'tri tests':>10s} "
          f"{'touching':>9s}")
    for label, vertices, faces, pose in cases():
        tree = build_mesh_tree(vertices, faces, "sah")
        corners = pose.apply(vertices)
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        grow = 0.1 * (hi - lo)
        centers = rng.uniform(lo - grow, hi + grow, (args.spheres, 3))
        radii = np.full(args.spheres, 0.02 * float(np.linalg.norm(hi - lo)))
        answers = {}
        for volume in VOLUMES:
            query_spheres(tree, pose, centers[:10], radii[:10], volume)  # compile and warm
            result = query_spheres(tree, pose, centers, radii, volume)
            seconds = best_of(lambda v=volume: query_spheres(tree, pose, centers, radii, v))
            answers[volume] = result.first
            refit = f" (+{result.refitted} refitted)" if result.refitted else ""
            print(f"{label:36s} {'physdbg ' + volume:14s} {1e3 * seconds:9.2f} {1e6 * seconds / args.spheres:10.3f} "
                  f"{result.node_tests:11,d} {result.triangle_tests:10,d} {result.touching:9,d}{refit}")
        assert all(np.array_equal(answers["aabb"], a) for a in answers.values()), "the volumes disagree"
        if have_fcl:
            seconds, touching = fcl_queries(vertices, faces, pose, centers, radii)
            far = centers + 100.0 * float(np.linalg.norm(hi - lo))
            overhead, _ = fcl_queries(vertices, faces, pose, far, radii)
            agree = int(np.count_nonzero(touching == (answers["aabb"] >= 0)))
            print(f"{label:36s} {'fcl OBBRSS':14s} {1e3 * seconds:9.2f} {1e6 * seconds / args.spheres:10.3f} "
                  f"{'':11s} {'':10s} {int(touching.sum()):9,d}  (agrees on {agree:,}; a far sphere: "
                  f"{1e6 * overhead / args.spheres:.2f} µs a call)")


if __name__ == "__main__":
    main()
