"""Do two meshes overlap, and how did the two-tree search find out? (``physdbg overlap``)

Loads two meshes (files or built-in shapes), poses them, runs the BVH-against-BVH descent
(``engine.mesh.descent``) and reports the meeting triangle pairs, the work counted and the
search tree itself: every node pair visited, indented by depth, with its outcome.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..engine.mesh import OUTCOME_NAMES, VOLUME_NAMES, Descent, MeshTree, Pose, descend
from ..engine.mesh.descent import APART, LEAVES_MEET, LEAVES_MISS, MEET
from ..engine.broadphase.bvh import BUILD_NAMES
from ..errors import PhysdbgError
from ..limits import MAX_MAGNITUDE
from ..meshes import Mesh, load_mesh, mesh_tree

AUTO_RULE = ("obb where either mesh is turned (its AABBs would have to be refitted from its moved corners; "
             "an OBB only turns), aabb otherwise (the cheapest test, and boxes move for free)")


def parse_pose(text: str | None, option: str) -> tuple[Pose, tuple[float, ...]]:
    """A pose from "x,y,z" (m) or "x,y,z,rx,ry,rz" (m, then degrees about x, y, z)."""
    if not text:
        return Pose(), (0.0,) * 6
    parts = [p.strip() for p in text.split(",")]
    try:
        numbers = tuple(float(p) for p in parts)
    except ValueError:
        raise PhysdbgError(f"{option} {text!r}: give x,y,z or x,y,z,rx,ry,rz (metres, then degrees)") from None
    if len(numbers) not in (3, 6) or not all(np.isfinite(numbers)) or max(map(abs, numbers)) > MAX_MAGNITUDE:
        raise PhysdbgError(f"{option} {text!r}: give 3 or 6 finite numbers, each within ±{MAX_MAGNITUDE:g}: x,y,z "
                           f"or x,y,z,rx,ry,rz (metres, then degrees about x, y and z)")
    numbers = numbers + (0.0,) * (6 - len(numbers))
    return Pose.of(numbers[:3], numbers[3:]), numbers


@dataclass
class OverlapReport:
    """Two posed meshes, their trees and what the descent found (``descent``)."""

    meshes: tuple[Mesh, Mesh]
    trees: tuple[MeshTree, MeshTree]
    poses: tuple[tuple[float, ...], tuple[float, ...]]
    volume: str
    volume_reason: str
    descent: Descent
    hull: bool = True

    @property
    def exit_code(self) -> int:
        """1 when the meshes meet (a scene's prescribed poses interpenetrate), 0 when apart."""
        return 1 if self.descent.meet else 0

    def counts(self) -> dict[str, int]:
        outcome = self.descent.log[:, 2]
        return {"visited": int(len(outcome)), "split": int(np.sum(outcome == MEET)),
                "apart": int(np.sum(outcome == APART)),
                "leaf_pairs": int(np.sum((outcome == LEAVES_MISS) | (outcome == LEAVES_MEET))),
                "volume_tests": self.descent.volume_tests, "triangle_tests": self.descent.triangle_tests,
                "refitted": self.descent.refitted}

    def as_dict(self) -> dict:
        d = self.descent
        return {"meet": d.meet, "volume": self.volume, "volume_reason": self.volume_reason, "hulls": d.hull_test,
                "meshes": [{"name": m.name, "source": m.source, "triangles": m.triangles, "nodes": t.size,
                            "depth": t.nodes.max_depth, "pose": list(p), "skipped": m.skipped}
                           for m, t, p in zip(self.meshes, self.trees, self.poses)],
                "counts": self.counts(), "pairs": d.pairs.tolist(),
                # each visited node pair, with the pair whose split led to it (its row here) and its
                # depth in the search tree: enough to rebuild the tree
                "tree": [{"a": int(i), "b": int(j), "outcome": OUTCOME_NAMES[o], "parent": int(p), "depth": depth}
                         for (i, j, o, p), depth in zip(d.log.tolist(), search_depths(d.log), strict=True)]}


def overlap(a: str, b: str, pose_a: str | None = None, pose_b: str | None = None, volume: str = "auto",
            builder: str = "sah", hull: bool = True) -> OverlapReport:
    """Load meshes ``a`` and ``b`` (file or shape), pose them and search for meeting triangles."""
    if volume != "auto" and volume not in VOLUME_NAMES:
        raise PhysdbgError(f"--volume {volume!r}: one of auto, {', '.join(VOLUME_NAMES)}")
    if builder not in BUILD_NAMES:
        raise PhysdbgError(f"--builder {builder!r}: one of {', '.join(BUILD_NAMES)}")
    place_a, numbers_a = parse_pose(pose_a, "--pose-a")
    place_b, numbers_b = parse_pose(pose_b, "--pose")
    meshes = (load_mesh(a, hull=hull), load_mesh(b, hull=hull))
    for mesh, place, option in zip(meshes, (place_a, place_b), ("--pose-a", "--pose")):
        reach = float(np.abs(place.apply(mesh.vertices)).max())
        if reach > MAX_MAGNITUDE:  # the file's corners are within range; the pose may carry them out
            raise PhysdbgError(f"{option}: places {mesh.source} {reach:.3g} m from the origin; every coordinate "
                               f"must be within ±{MAX_MAGNITUDE:g} m")
    trees = (mesh_tree(meshes[0], builder), mesh_tree(meshes[1], builder))
    if volume == "auto":
        turned = [name for name, numbers in (("A", numbers_a), ("B", numbers_b)) if any(numbers[3:])]
        volume = "obb" if turned else "aabb"
        reason = (f"auto: {' and '.join(turned)} turned, so AABBs would be refitted; an OBB only turns" if turned
                  else "auto: neither mesh is turned, so the boxes only move")
    else:
        reason = "chosen"
    found = descend(trees[0], place_a, trees[1], place_b, volume, hull=hull)
    return OverlapReport(meshes, trees, (numbers_a, numbers_b), volume, reason, found, hull)


def _where(numbers: tuple[float, ...]) -> str:
    if not any(numbers):
        return ""
    text = "; at ({:g}, {:g}, {:g})".format(*numbers[:3])
    if any(numbers[3:]):
        text += ", turned ({:g}, {:g}, {:g})°".format(*numbers[3:])
    return text


def overlap_text(report: OverlapReport, max_lines: int = 40) -> str:
    """The report in words: the meshes, the verdict, the work, and the search tree
    (``max_lines`` node pairs of it; 0 for all)."""
    lines = []
    for label, mesh, tree, numbers in zip("AB", report.meshes, report.trees, report.poses):
        hull = (f", hull of {len(mesh.hull[2])} corners" if mesh.hull is not None else
                ", no hull (flat)" if report.hull else "")
        lines.append(f"{label}: {mesh.name} ({mesh.source}): {mesh.triangles} triangles, BVH {tree.builder} of "
                     f"{tree.size} nodes, depth {tree.nodes.max_depth}{hull}{_where(numbers)}")
        if mesh.skipped:
            lines.append("   " + mesh.skipped_words())
    d = report.descent
    c = report.counts()
    lines.append(f"volume: {report.volume} ({report.volume_reason})")
    lines.append({"off": "hulls: not tested" + ("" if report.hull else " (--no-hull)"),
                  "too big": "hulls: not tested (their faces × corners exceed the early-out's budget; the trees are "
                             "quicker)",
                  "meet": "hulls: meet (tested first)",
                  "apart": "hulls: apart (tested first): no node visited"}[d.hull_test])
    if d.hull_test != "apart":
        refit = f"; {c['refitted']} AABB nodes refitted for the poses" if c["refitted"] else ""
        lines.append(f"search: {c['visited']} node pairs visited: {c['split']} with meeting volumes (split), "
                     f"{c['apart']} apart (culled), "
                     f"{c['leaf_pairs']} leaf pairs tested ({len(d.pairs)} meet){refit}")
    if d.meet:
        shown = ", ".join(f"{i}×{j}" for i, j in d.pairs[:12].tolist())
        more = f" and {len(d.pairs) - 12} more" if len(d.pairs) > 12 else ""
        lines.append(f"MEET: {len(d.pairs)} triangle pair(s) meet (triangle of A × triangle of B): {shown}{more}")
    else:
        lines.append("APART: no triangle of A meets a triangle of B")
    if d.hull_test != "apart":
        depth_a, depth_b = report.trees[0].nodes.depth, report.trees[1].nodes.depth
        lines.append("search tree (node of A × node of B: outcome):")
        rows = d.log if max_lines <= 0 else d.log[:max_lines]
        for i, j, outcome, _parent in rows.tolist():
            lines.append(f"{'  ' * (int(depth_a[i]) + int(depth_b[j]) + 1)}A{i}×B{j} {OUTCOME_NAMES[outcome]}")
        if len(rows) < len(d.log):
            lines.append(f"  … {len(d.log) - len(rows)} more node pairs (--max-lines 0 shows all)")
    return "\n".join(lines)


def search_depths(log) -> list[int]:
    """Each row's depth in the search tree (0 for the roots) from the descent log's parent
    column (rows come after their parents)."""
    depths: list[int] = []
    for parent in log[:, 3].tolist():
        depths.append(0 if parent < 0 else depths[parent] + 1)
    return depths
