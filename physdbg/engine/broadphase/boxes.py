"""Axis-aligned box tests every broad phase shares: the leaf of the broad-phase package.

Nothing here imports the rest of the package, so the grid, the BVHs and the interface
(``__init__``) all depend on this module and never on each other. Boxes are (lo, hi):
(N, 3) arrays of corners, in m.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..jit import borrowing, kernel

NO_LIMIT = 2**62  # a pair budget that is no budget (broad phases take ``limit``)


@kernel
def boxes_overlap(lo, hi, i, j):
    """Do boxes i and j of (lo, hi) (N, 3) overlap (touching counts)?"""
    for c in range(3):
        if lo[i, c] > hi[j, c] or lo[j, c] > hi[i, c]:
            return False
    return True


@borrowing
def box_misses(box, lo, hi, q, period) -> bool:
    """Does the box ``box`` (2, 3: its lo and hi rows) miss box q of (lo, hi) (N, 3)
    (touching meets)? Only non-periodic axes (period (3,) m, 0 = not periodic) can tell:
    on a periodic one the minimum image decides, so it never counts as a miss."""
    for c in range(3):
        if period[c] == 0.0 and (box[1, c] < lo[q, c] or box[0, c] > hi[q, c]):
            return True
    return False


@njit(cache=True, inline="always")
def box_meets(lo0, lo1, lo2, hi0, hi1, hi2, lo, hi, j) -> bool:
    """Does the box (lo0, lo1, lo2)-(hi0, hi1, hi2) meet box j of (lo, hi) (N, 3)?
    Touching counts; a NaN bound meets nothing (a query's rule: overlapping, and the
    contact loop's own re-query)."""
    return (lo0 <= hi[j, 0] and lo[j, 0] <= hi0 and lo1 <= hi[j, 1] and lo[j, 1] <= hi1
            and lo2 <= hi[j, 2] and lo[j, 2] <= hi2)


@kernel
def overlapping(lo, hi, box_lo, box_hi):
    """Indices (sorted, int64) of the boxes lo, hi (N, 3) that overlap one box box_lo,
    box_hi (3,) (touching counts; a NaN bound overlaps nothing): a linear scan, compiled
    (a mid-step re-query; numpy's four passes took ~0.3 ms at 10 000 boxes)."""
    n = lo.shape[0]
    out = np.empty(n, dtype=np.int64)
    found = 0
    for i in range(n):
        if box_meets(box_lo[0], box_lo[1], box_lo[2], box_hi[0], box_hi[1], box_hi[2], lo, hi, i):
            out[found] = i
            found += 1
    return out[:found]


def boxes_meet(lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray,
               period: np.ndarray) -> np.ndarray:
    """(N,) bool: does each box lo, hi (N, 3) overlap one box, on periodic axes (period (3,)
    m, 0 = not periodic) through any whole-period shift? Boxes narrower than half a period
    need only the shifts -L, 0 and +L."""
    meet = np.ones(lo.shape[0], dtype=bool)
    for c in range(3):
        axis = (box_lo[c] <= hi[:, c]) & (lo[:, c] <= box_hi[c])
        length = period[c]
        if length > 0:
            for shift in (-length, length):
                axis |= (box_lo[c] + shift <= hi[:, c]) & (lo[:, c] <= box_hi[c] + shift)
        meet &= axis
    return meet
