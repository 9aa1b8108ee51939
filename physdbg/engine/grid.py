"""Uniform grid broad phase (numba).

Cells are cubes of side ``cell`` no smaller than the largest box (for swept boxes: twice
the largest radius plus the longest motion of the step), so a box overlaps at most
2 × 2 × 2 cells. Each box is listed in every cell it overlaps; the list is sorted by cell
key, and within each cell every pair of boxes is tested. A pair overlapping in several
cells is reported only by its *owner* cell, the one holding the lower corner of the two
boxes' intersection — so each pair comes out exactly once, with no hash set.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _boxes_overlap(lo, hi, i, j):
    for c in range(3):
        if lo[i, c] > hi[j, c] or lo[j, c] > hi[i, c]:
            return False
    return True


@njit(cache=True)
def _cell_of(value, origin, cell, dim):
    k = int(math.floor((value - origin) / cell))
    if k < 0:
        return 0
    if k >= dim:
        return dim - 1
    return k


@njit(cache=True)
def grid_pairs(lo, hi, cell):
    """(M, 2) int64 pairs i < j of overlapping boxes, sorted; and the number of cells used.

    lo, hi: (N, 3) box corners (m); cell: cell side (m) >= the largest box extent.
    """
    n = lo.shape[0]
    if n < 2:
        return np.empty((0, 2), dtype=np.int64), 0
    origin = np.empty(3)
    dims = np.empty(3, dtype=np.int64)
    for c in range(3):
        mn = lo[0, c]
        mx = hi[0, c]
        for i in range(1, n):
            mn = min(mn, lo[i, c])
            mx = max(mx, hi[i, c])
        origin[c] = mn
        dims[c] = int(math.floor((mx - mn) / cell)) + 1
    cell_lo = np.empty((n, 3), dtype=np.int64)
    cell_hi = np.empty((n, 3), dtype=np.int64)
    total = 0
    for i in range(n):
        k = 1
        for c in range(3):
            cell_lo[i, c] = _cell_of(lo[i, c], origin[c], cell, dims[c])
            cell_hi[i, c] = _cell_of(hi[i, c], origin[c], cell, dims[c])
            k *= cell_hi[i, c] - cell_lo[i, c] + 1
        total += k
    keys = np.empty(total, dtype=np.int64)
    ids = np.empty(total, dtype=np.int64)
    m = 0
    for i in range(n):
        for x in range(cell_lo[i, 0], cell_hi[i, 0] + 1):
            for y in range(cell_lo[i, 1], cell_hi[i, 1] + 1):
                for z in range(cell_lo[i, 2], cell_hi[i, 2] + 1):
                    keys[m] = (x * dims[1] + y) * dims[2] + z
                    ids[m] = i
                    m += 1
    order = np.argsort(keys, kind="mergesort")
    keys = keys[order]
    ids = ids[order]
    out = np.empty((max(16, 4 * n), 2), dtype=np.int64)
    count = 0
    cells_used = 0
    start = 0
    while start < total:
        end = start + 1
        while end < total and keys[end] == keys[start]:
            end += 1
        cells_used += 1
        key = keys[start]
        cz = key % dims[2]
        cy = (key // dims[2]) % dims[1]
        cx = key // (dims[2] * dims[1])
        for a in range(start, end):
            i = ids[a]
            for b in range(a + 1, end):
                j = ids[b]
                if not _boxes_overlap(lo, hi, i, j):
                    continue
                # owner cell: the cell of the intersection's lower corner
                if (_cell_of(max(lo[i, 0], lo[j, 0]), origin[0], cell, dims[0]) != cx
                        or _cell_of(max(lo[i, 1], lo[j, 1]), origin[1], cell, dims[1]) != cy
                        or _cell_of(max(lo[i, 2], lo[j, 2]), origin[2], cell, dims[2]) != cz):
                    continue
                if count == out.shape[0]:
                    bigger = np.empty((2 * count, 2), dtype=np.int64)
                    bigger[:count] = out[:count]
                    out = bigger
                out[count, 0] = min(i, j)
                out[count, 1] = max(i, j)
                count += 1
        start = end
    pairs = out[:count]
    if count > 1:
        rank = np.argsort(pairs[:, 0] * n + pairs[:, 1])
        pairs = pairs[rank]
    return pairs, cells_used


class UniformGrid:
    """Broad phase on a uniform grid; best when boxes are of similar size.

    cell: fixed cell side (m), or None to use the largest box extent of each call.
    """

    name = "grid"

    def __init__(self, cell: float | None = None):
        self.cell = cell
        self.stats: dict[str, float] = {}

    def _cell_size(self, lo: np.ndarray, hi: np.ndarray) -> float:
        if self.cell is not None:
            return self.cell
        extent = float(np.max(hi - lo)) if lo.size else 1.0
        # keep the key space bounded even if one box flies far away
        span = float(np.max(np.max(hi, axis=0) - np.min(lo, axis=0))) if lo.size else 1.0
        return max(extent, span / 2.0**20, 1e-12)

    def pairs(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        cell = self._cell_size(lo, hi)
        pairs, cells = grid_pairs(np.ascontiguousarray(lo), np.ascontiguousarray(hi), cell)
        self.stats = {"cell": cell, "cells_used": cells, "pairs": len(pairs)}
        return pairs

    def query(self, lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray) -> np.ndarray:
        overlap = np.all((box_lo <= hi) & (lo <= box_hi), axis=1)
        return np.nonzero(overlap)[0].astype(np.int64)
