"""Broad phase: which pairs of swept boxes overlap, so the narrow phase tests only those.

A broad phase answers two questions about axis-aligned boxes (lo, hi: (N, 3), m):

* ``pairs(lo, hi)`` -> (M, 2) int64 array of every i < j whose boxes overlap, sorted;
* ``query(lo, hi, box_lo, box_hi)`` -> (K,) int64 indices whose boxes overlap one box.

:class:`BruteForce` compares every pair. It is the reference the faster structures
(grid and BVHs, next) must match exactly, and stays the judge in their tests.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np


class BroadPhase(Protocol):
    name: str

    def pairs(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray: ...

    def query(self, lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray,
              box_hi: np.ndarray) -> np.ndarray: ...


class BruteForce:
    """All N(N-1)/2 box tests, vectorised a block of rows at a time (O(N²) time).

    block: rows compared at once (memory ~ block·N booleans per axis).
    """

    name = "brute-force"

    def __init__(self, block: int = 512):
        self.block = block

    def pairs(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        n = lo.shape[0]
        chunks = []
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
                chunks.append(np.column_stack((i + start, j)))
        if not chunks:
            return np.empty((0, 2), dtype=np.int64)
        return np.concatenate(chunks).astype(np.int64)

    def query(self, lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray,
              box_hi: np.ndarray) -> np.ndarray:
        overlap = np.all((box_lo <= hi) & (lo <= box_hi), axis=1)
        return np.nonzero(overlap)[0].astype(np.int64)


BROAD_PHASES = {"brute-force": BruteForce}


def make_broad_phase(name: str) -> BroadPhase:
    """The broad phase called ``name`` (see BROAD_PHASES)."""
    return BROAD_PHASES[name]()
