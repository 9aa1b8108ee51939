"""Broad phase: which pairs of swept boxes overlap, so the narrow phase tests only those.

A broad phase answers two questions about axis-aligned boxes (lo, hi: (N, 3), m):

* ``pairs(lo, hi, limit)`` -> (M, 2) int64 array of every i < j whose boxes overlap,
  sorted; a structure stops looking once it has found ``limit + 1`` pairs, so more than
  ``limit`` rows means "over the budget" (memory stays bounded whatever the boxes);
* ``query(lo, hi, box_lo, box_hi)`` -> (K,) int64 indices whose boxes overlap one box.

:class:`BruteForce` compares every pair. It is the reference the faster structures
(grid and BVHs, next) must match exactly, and stays the judge in their tests.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from .boxes import NO_LIMIT, overlapping


class BroadPhase(Protocol):
    """What World uses of a broad phase. stats: what the last ``pairs`` call measured
    (numbers by name, shown in BroadPhaseInfo); nodes: the tree it built (BVHs:
    bvh.BVHNodes) or None; query_scans_boxes: whether ``query`` tests every box it is
    given as it is now (a linear scan), so that the contact loop may run the same scan
    itself (timeline: a re-query that finds nothing new need not pause the loop)."""

    name: str
    stats: dict
    nodes: object | None
    query_scans_boxes: bool

    def pairs(self, lo: np.ndarray, hi: np.ndarray, limit: int = ...) -> np.ndarray: ...

    def query(self, lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray,
              box_hi: np.ndarray) -> np.ndarray: ...

    def renumbered(self) -> None:
        """The boxes will come in another order from now on (space_order.py): forget
        anything kept by index from one call to the next."""


class BruteForce:
    """All N(N-1)/2 box tests, vectorised a block of rows at a time (O(N²) time).

    block: rows compared at once (memory ~ block·N booleans per axis).
    """

    name = "brute-force"
    nodes = None
    query_scans_boxes = True

    def __init__(self, block: int = 512):
        self.block = block
        self.stats: dict = {}

    def renumbered(self) -> None:
        """Nothing is kept between calls."""

    def pairs(self, lo: np.ndarray, hi: np.ndarray, limit: int = NO_LIMIT) -> np.ndarray:
        n = lo.shape[0]
        chunks = []
        found = 0
        for start in range(0, max(n - 1, 0), self.block):
            rows = slice(start, min(start + self.block, n))
            overlap = np.ones((rows.stop - start, n), dtype=bool)
            for axis in range(3):
                overlap &= lo[rows, axis, None] <= hi[None, :, axis]
                overlap &= lo[None, :, axis] <= hi[rows, axis, None]
            # keep j > i only: each unordered pair once
            overlap &= np.arange(n)[None, :] > np.arange(start, rows.stop)[:, None]
            i, j = np.nonzero(overlap)
            if i.size:
                chunks.append(np.column_stack((i + start, j))[: limit + 1 - found])
                found += len(chunks[-1])
                if found > limit:
                    break
        if not chunks:
            return np.empty((0, 2), dtype=np.int64)
        return np.concatenate(chunks).astype(np.int64)

    def query(self, lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray,
              box_hi: np.ndarray) -> np.ndarray:
        return overlapping(lo, hi, box_lo, box_hi)


BROAD_PHASE_NAMES = ("auto", "brute-force", "grid", "bvh-sah", "bvh-median", "bvh-mean", "bvh-lbvh")

# The auto rule (docs/broadphase.md): brute force below this many particles...
AUTO_BRUTE_FORCE_BELOW = 64
# ...a grid when the largest radius is at most this many times the smallest...
AUTO_GRID_MAX_RADIUS_RATIO = 4.0


def make_broad_phase(name: str) -> BroadPhase:
    """The broad phase called ``name`` (one of BROAD_PHASE_NAMES except ``auto``)."""
    from .bvh import BVH
    from .grid import UniformGrid

    if name == "brute-force":
        return BruteForce()
    if name == "grid":
        return UniformGrid()
    if name.startswith("bvh-") and name[4:] in ("sah", "median", "mean", "lbvh"):
        return BVH(method=name[4:])
    raise ValueError(f"unknown broad phase {name!r}; one of {', '.join(BROAD_PHASE_NAMES)}")


def choose_broad_phase(name: str, radius: np.ndarray) -> tuple[str, str]:
    """(broad phase, reason): resolve ``auto`` for particles of these radii (m).

    A scene is modelled with no more machinery than it needs: brute force for a handful
    of particles, a uniform grid for similar sizes, an LBVH when sizes differ widely.
    """
    n = int(radius.size)
    if name != "auto":
        return name, "chosen in the scene"
    if n < AUTO_BRUTE_FORCE_BELOW:
        return "brute-force", (f"auto: {n} particle{'' if n == 1 else 's'} (< {AUTO_BRUTE_FORCE_BELOW}): "
                               f"{n * (n - 1) // 2} box tests cost less than building a structure")
    ratio = float(radius.max() / radius.min()) if radius.min() > 0 else float("inf")
    if ratio <= AUTO_GRID_MAX_RADIUS_RATIO:
        return "grid", (f"auto: {n} particles with similar radii (largest/smallest = {ratio:.3g} "
                        f"<= {AUTO_GRID_MAX_RADIUS_RATIO:g}): a uniform grid")
    # LBVH: in benchmarks/broadphase.py it builds and pairs fastest of the BVHs for mixed radii
    return "bvh-lbvh", (f"auto: {n} particles with radii spanning {ratio:.3g}x (> {AUTO_GRID_MAX_RADIUS_RATIO:g}): "
                        f"a grid would be sized for the largest, so a BVH (LBVH: the fastest to rebuild)")
