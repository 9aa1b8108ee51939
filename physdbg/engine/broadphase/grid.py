"""Uniform grid broad phase (numba).

Cells are cubes of side ``cell`` no smaller than the largest box (for swept boxes: twice
the largest radius plus the longest motion of the step). Each box is filed under the
cell of its centre (a counting sort), so two overlapping boxes have centres at most one
cell apart on every axis: each box needs testing only against the boxes filed in its own
and the 26 neighbouring cells. Boxes are walked in cell order, each against the *half
shell* of cells after its own (so each pair comes out once); in cell order the three
cells z-1, z, z+1 of one (x, y) row are contiguous, so the half shell is five runs of
boxes: the rest of its own row, (x, y+1), and (x+1, y-1 .. y+1). The pairs are then
sorted (a counting sort on the first index).
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import borrowing, kernel
from .boxes import NO_LIMIT, overlapping

@borrowing
def _cell_of(value, origin, cell, dim):
    k = int(math.floor((value - origin) / cell))
    if k < 0:
        return 0
    if k >= dim:
        return dim - 1
    return k


@borrowing
def grid_frame(points, cell, origin, dims):
    """The uniform grid of side ``cell`` (m) over points (N, 3), N >= 1: origin (3,) <- the
    points' lowest corner (m), dims (3,) <- the cells on each axis; returns the points'
    largest extent on any axis (m). NaN coordinates are passed over (and cell_key clamps
    them into the grid); an axis with no number gives a negative extent. dims mean
    something only where 0 <= extent and extent / cell is moderate: a caller that cannot
    promise it checks."""
    extent = 0.0
    for c in range(3):
        low = np.inf
        high = -np.inf
        for i in range(points.shape[0]):
            low = min(low, points[i, c])
            high = max(high, points[i, c])
        origin[c] = low
        dims[c] = int(math.floor((high - low) / cell)) + 1
        extent = extent if high - low <= extent else high - low
    return extent


@borrowing
def cell_key(points, i, origin, cell, dims):
    """The cell of point i of points (N, 3) in grid_frame's grid, as (x·dy + y)·dz + z."""
    cx = _cell_of(points[i, 0], origin[0], cell, dims[0])
    cy = _cell_of(points[i, 1], origin[1], cell, dims[1])
    cz = _cell_of(points[i, 2], origin[2], cell, dims[2])
    return (cx * dims[1] + cy) * dims[2] + cz


@kernel
def grid_pairs(lo, hi, cell, limit):
    """(M, 2) int64 pairs i < j of overlapping boxes, sorted; the number of cells used; and
    the cell side (m).

    lo, hi: (N, 3) box corners (m); cell: cell side (m) >= the largest box extent, or 0 for
    the one auto_cell gives; limit: stop after limit + 1 pairs (over the budget).
    """
    n = lo.shape[0]
    if cell <= 0.0:
        cell = auto_cell(lo, hi)
    if n < 2:
        return np.empty((0, 2), dtype=np.int64), 0, cell
    centres = np.empty((n, 3))
    for i in range(n):
        for c in range(3):
            centres[i, c] = 0.5 * (lo[i, c] + hi[i, c])
    origin = np.empty(3)
    dims = np.empty(3, dtype=np.int64)
    grid_frame(centres, cell, origin, dims)
    cells = dims[0] * dims[1] * dims[2]
    key = np.empty(n, dtype=np.int64)
    for i in range(n):
        key[i] = cell_key(centres, i, origin, cell, dims)
    dense = cells <= 8 * n + 4096
    if dense:
        # counting sort: cell_start[k] .. cell_start[k+1] are the boxes filed in cell k
        cell_start = bucket_starts(key, cells)
        fill = cell_start[:-1].copy()
        filed = np.empty(n, dtype=np.int64)
        for i in range(n):
            filed[fill[key[i]]] = i
            fill[key[i]] += 1
        sorted_keys = key[filed]
    else:
        filed = np.argsort(key, kind="mergesort")
        sorted_keys = key[filed]
        cell_start = np.empty(0, dtype=np.int64)
    used = 0
    for k in range(n):
        if k == 0 or sorted_keys[k] != sorted_keys[k - 1]:
            used += 1
    # cell-ordered copies of the bounds, one row of six per box (memory locality)
    boxes = np.empty((n, 6))
    for k in range(n):
        for c in range(3):
            boxes[k, c] = lo[filed[k], c]
            boxes[k, 3 + c] = hi[filed[k], c]
    out_i = np.empty(max(16, 8 * n), dtype=np.int64)
    out_j = np.empty(max(16, 8 * n), dtype=np.int64)
    found = 0
    k = 0
    while True:
        k, found = _collect_pairs(k, found, filed, sorted_keys, cell_start, dense, dims, boxes, limit, out_i, out_j)
        if k >= n:
            break
        bigger_i = np.empty(2 * out_i.shape[0] + 64, dtype=np.int64)
        bigger_j = np.empty(2 * out_j.shape[0] + 64, dtype=np.int64)
        for t in range(found):  # a loop, not a slice copy: that compiles numba's shape-error
            bigger_i[t] = out_i[t]  # formatting, 2 s of the cold compile
            bigger_j[t] = out_j[t]
        out_i = bigger_i
        out_j = bigger_j
    return sort_pairs(out_i[:found], out_j[:found], n), used, cell


@borrowing
def auto_cell(lo, hi):
    """The cell side (m) for boxes lo, hi (N, 3): the largest box extent, but at least
    1/2^20 of the span of all boxes (the key space stays bounded even if one box flies far
    away) and 1e-12 m; 1 m for no boxes."""
    n = lo.shape[0]
    if n == 0:
        return 1.0
    extent = 0.0
    span = 0.0
    for c in range(3):
        low = np.inf
        high = -np.inf
        for i in range(n):
            extent = max(extent, hi[i, c] - lo[i, c])
            low = min(low, lo[i, c])
            high = max(high, hi[i, c])
        span = max(span, high - low)
    return max(extent, span / 2.0**20, 1e-12)


# the half shell's (x, y) rows after a box's own, as offsets (the own row comes first)
_ROW_DX = (0, 0, 1, 1, 1)
_ROW_DY = (0, 1, -1, 0, 1)


@borrowing
def _collect_pairs(first_box, found, filed, sorted_keys, cell_start, dense, dims, boxes, limit, out_i, out_j):
    """The pairs of boxes ``first_box`` onwards (in cell order) into out_i, out_j from
    ``found`` on; returns (the box to go on from, pairs found): n when done (or past
    ``limit``), else the box whose pairs did not fit, whose pairs are dropped, to be
    collected again into larger arrays. (Growing the arrays inside this loop made the
    whole loop about twice as slow: an array variable reassigned in a loop is reloaded,
    and reference-counted, on every pass.)

    boxes: (N, 6) lo then hi of each box, in cell order. Each run of candidates is
    tested without branches: every candidate is written and the count moves on by
    whether the boxes meet (a mispredicted branch per candidate cost more than the test).
    """
    n = filed.shape[0]
    plane = dims[1] * dims[2]
    for k in range(first_box, n):
        if found > limit:
            return n, found
        box_start = found
        i = filed[k]
        own = sorted_keys[k]
        own_x = own // plane
        own_y = (own // dims[2]) % dims[1]
        own_z = own % dims[2]
        z_first = max(own_z - 1, 0)
        z_end = min(own_z + 2, dims[2])
        lo0, lo1, lo2 = boxes[k, 0], boxes[k, 1], boxes[k, 2]
        hi0, hi1, hi2 = boxes[k, 3], boxes[k, 4], boxes[k, 5]
        for r in range(5):
            x = own_x + _ROW_DX[r]
            y = own_y + _ROW_DY[r]
            if x >= dims[0] or y < 0 or y >= dims[1]:
                continue
            row = (x * dims[1] + y) * dims[2]
            if dense:
                first = cell_start[row + z_first]
                last = cell_start[row + z_end]
            else:
                first = np.searchsorted(sorted_keys, row + z_first)
                last = np.searchsorted(sorted_keys, row + z_end)
            if r == 0:
                first = k + 1  # own row: only the boxes after this one
            if found + (last - first) > out_i.shape[0]:
                return k, box_start
            for t in range(first, last):
                # "not apart" rather than "overlap", so that a NaN bound pairs as before
                apart = ((lo0 > boxes[t, 3]) | (boxes[t, 0] > hi0) | (lo1 > boxes[t, 4]) | (boxes[t, 1] > hi1)
                         | (lo2 > boxes[t, 5]) | (boxes[t, 2] > hi2))
                j = filed[t]
                out_i[found] = min(i, j)
                out_j[found] = max(i, j)
                found += 1 - apart
    return n, found


@kernel
def bucket_starts(keys, buckets):
    """Counting-sort offsets: items with key k go to [start[k], start[k+1]); (buckets + 1,)."""
    start = np.zeros(buckets + 1, dtype=np.int64)
    for t in range(keys.shape[0]):
        start[keys[t] + 1] += 1
    for k in range(buckets):
        start[k + 1] += start[k]
    return start


@kernel
def sort_pairs(first, second, n):
    """(M, 2) pairs in lexicographic order: counting sort on the first index (O(M + N)),
    then an insertion sort of each row's few second indices."""
    m = first.shape[0]
    start = bucket_starts(first, n)
    fill = start[:-1].copy()
    out = np.empty((m, 2), dtype=np.int64)
    for t in range(m):
        row = fill[first[t]]
        out[row, 0] = first[t]
        out[row, 1] = second[t]
        fill[first[t]] += 1
    for i in range(n):
        for a in range(start[i] + 1, start[i + 1]):
            value = out[a, 1]
            b = a - 1
            while b >= start[i] and out[b, 1] > value:
                out[b + 1, 1] = out[b, 1]
                b -= 1
            out[b + 1, 1] = value
    return out


class UniformGrid:
    """Broad phase on a uniform grid; best when boxes are of similar size.

    cell: fixed cell side (m), or None to use the largest box extent of each call.
    """

    name = "grid"
    nodes = None  # no tree
    query_scans_boxes = True

    def __init__(self, cell: float | None = None):
        self.cell = cell
        self.stats: dict[str, float] = {}

    def renumbered(self) -> None:
        """Nothing is kept between calls."""

    def pairs(self, lo: np.ndarray, hi: np.ndarray, limit: int = NO_LIMIT) -> np.ndarray:
        pairs, cells, cell = grid_pairs(np.ascontiguousarray(lo), np.ascontiguousarray(hi),
                                        0.0 if self.cell is None else float(self.cell), limit)
        self.stats = {"cell": cell, "cells_used": cells, "pairs": len(pairs)}
        return pairs

    def query(self, lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray) -> np.ndarray:
        """Boxes overlapping one box: a linear scan (mid-step re-queries are rare)."""
        return overlapping(lo, hi, box_lo, box_hi)
