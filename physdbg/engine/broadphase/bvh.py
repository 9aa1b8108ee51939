"""Bounding volume hierarchies over axis-aligned boxes (numba): the seed's BVHs.

Top-down (the seed: "compute a bounding volume enclosing all of the geometry, split the
geometry into two groups, recurse") with the split on the **longest axis** of the node's
centroids, at

* ``median`` — the median centroid (a balanced tree: depth ceil(log2(leaves)));
* ``mean``   — the mean centroid (falls back to the median if one side would be empty);
* ``sah``    — the surface area heuristic, binned (16 bins): the split minimising
  A(left)·N(left) + A(right)·N(right);

and bottom-up (the seed: "bottom-up merging, which offers better parallelism"):

* ``lbvh`` — Karras (2012): sort the primitives by 30-bit Morton code of their centroid,
  then every internal node is found independently from the sorted codes (a binary radix
  tree), and bounds are merged from the leaves up.

All trees share one node layout (arrays of length M): ``lo, hi`` (M, 3) bounds; ``left,
right`` children (-1 at leaves); ``parent`` (-1 at the root); ``depth``; ``start,
count`` the leaf's range in ``order``, the permutation of primitive indices. With
one-primitive leaves a tree has exactly 2·N − 1 nodes.

Pairs come from a **self-traversal** of the one scene tree: a simultaneous descent of
node pairs from (root, root) — "two primitives can overlap only if their volumes overlap"
(the seed) — so each overlapping leaf pair is found once.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from time import perf_counter

import numpy as np

from ..jit import kernel

from .boxes import NO_LIMIT, boxes_overlap

MEDIAN = 0
MEAN = 1
SAH = 2
LBVH = 3
BUILD_NAMES = ("median", "mean", "sah", "lbvh")
_SAH_BINS = 16


@kernel
def _area(lo0, lo1, lo2, hi0, hi1, hi2):
    dx = hi0 - lo0
    dy = hi1 - lo1
    dz = hi2 - lo2
    return 2.0 * (dx * dy + dy * dz + dz * dx)


@kernel
def _fit_leaf(lo, hi, order, s, cnt, node_lo, node_hi, node):
    for c in range(3):
        mn = np.inf
        mx = -np.inf
        for m in range(s, s + cnt):
            p = order[m]
            mn = min(mn, lo[p, c])
            mx = max(mx, hi[p, c])
        node_lo[node, c] = mn
        node_hi[node, c] = mx


@kernel
def _empty_nodes(cap):
    """Node arrays for up to ``cap`` nodes: lo, hi, left, right, parent, depth, start, count."""
    return (np.empty((cap, 3)), np.empty((cap, 3)), np.full(cap, -1, dtype=np.int64),
            np.full(cap, -1, dtype=np.int64), np.full(cap, -1, dtype=np.int64), np.zeros(cap, dtype=np.int64),
            np.zeros(cap, dtype=np.int64), np.zeros(cap, dtype=np.int64))


@kernel
def build_top_down(lo, hi, method, leaf_size):
    """Top-down build; returns (node_lo, node_hi, left, right, parent, depth, start, count, order)."""
    n = lo.shape[0]
    cap = max(2 * n - 1, 1)
    node_lo, node_hi, left, right, parent, depth, start, count = _empty_nodes(cap)
    order = np.arange(n)
    if n == 0:
        return (node_lo[:0], node_hi[:0], left[:0], right[:0], parent[:0], depth[:0], start[:0],
                count[:0], order)
    centroid = 0.5 * (lo + hi)
    count[0] = n
    used = 1
    stack = np.empty(cap, dtype=np.int64)
    top = 0
    stack[top] = 0
    top += 1
    bin_count = np.zeros(_SAH_BINS, dtype=np.int64)
    bin_lo = np.empty((_SAH_BINS, 3))
    bin_hi = np.empty((_SAH_BINS, 3))
    while top > 0:
        top -= 1
        node = stack[top]
        s = start[node]
        cnt = count[node]
        _fit_leaf(lo, hi, order, s, cnt, node_lo, node_hi, node)
        if cnt <= leaf_size:
            continue
        # longest axis of the centroids (the seed's rule)
        axis = 0
        best_extent = -1.0
        cmin = np.empty(3)
        cmax = np.empty(3)
        for c in range(3):
            mn = np.inf
            mx = -np.inf
            for m in range(s, s + cnt):
                v = centroid[order[m], c]
                mn = min(mn, v)
                mx = max(mx, v)
            cmin[c] = mn
            cmax[c] = mx
            if mx - mn > best_extent:
                best_extent = mx - mn
                axis = c
        sub = order[s:s + cnt].copy()
        keys = np.empty(cnt)
        for m in range(cnt):
            keys[m] = centroid[sub[m], axis]
        rank = np.argsort(keys, kind="mergesort")
        for m in range(cnt):
            order[s + m] = sub[rank[m]]
        mid = cnt // 2
        if best_extent > 0.0 and method == MEAN:
            mean = 0.0
            for m in range(cnt):
                mean += keys[m]
            mean /= cnt
            below = 0
            for m in range(cnt):
                if keys[m] < mean:
                    below += 1
            if 0 < below < cnt:
                mid = below
        elif best_extent > 0.0 and method == SAH:
            bin_count[:] = 0
            bin_lo[:, :] = np.inf
            bin_hi[:, :] = -np.inf
            scale = _SAH_BINS / best_extent
            for m in range(cnt):
                p = order[s + m]
                b = min(int((centroid[p, axis] - cmin[axis]) * scale), _SAH_BINS - 1)
                bin_count[b] += 1
                for c in range(3):
                    bin_lo[b, c] = min(bin_lo[b, c], lo[p, c])
                    bin_hi[b, c] = max(bin_hi[b, c], hi[p, c])
            best_cost = np.inf
            best_split = -1
            for split in range(1, _SAH_BINS):
                nl = 0
                nr = 0
                l0 = np.full(3, np.inf)
                l1 = np.full(3, -np.inf)
                r0 = np.full(3, np.inf)
                r1 = np.full(3, -np.inf)
                for b in range(_SAH_BINS):
                    if bin_count[b] == 0:
                        continue
                    if b < split:
                        nl += bin_count[b]
                        for c in range(3):
                            l0[c] = min(l0[c], bin_lo[b, c])
                            l1[c] = max(l1[c], bin_hi[b, c])
                    else:
                        nr += bin_count[b]
                        for c in range(3):
                            r0[c] = min(r0[c], bin_lo[b, c])
                            r1[c] = max(r1[c], bin_hi[b, c])
                if nl == 0 or nr == 0:
                    continue
                cost = (_area(l0[0], l0[1], l0[2], l1[0], l1[1], l1[2]) * nl
                        + _area(r0[0], r0[1], r0[2], r1[0], r1[1], r1[2]) * nr)
                if cost < best_cost:
                    best_cost = cost
                    best_split = split
            if best_split > 0:
                # centroids are sorted along the axis: the split is where the bin changes
                below = 0
                for m in range(cnt):
                    if min(int((keys[rank[m]] - cmin[axis]) * scale), _SAH_BINS - 1) < best_split:
                        below += 1
                if 0 < below < cnt:
                    mid = below
        a = used
        b = used + 1
        used += 2
        left[node] = a
        right[node] = b
        parent[a] = node
        parent[b] = node
        depth[a] = depth[node] + 1
        depth[b] = depth[node] + 1
        start[a] = s
        count[a] = mid
        start[b] = s + mid
        count[b] = cnt - mid
        stack[top] = b
        top += 1
        stack[top] = a
        top += 1
    return (node_lo[:used], node_hi[:used], left[:used], right[:used], parent[:used], depth[:used],
            start[:used], count[:used], order)


@kernel
def _expand_bits(v):
    v = (v * 0x00010001) & 0xFF0000FF
    v = (v * 0x00000101) & 0x0F00F00F
    v = (v * 0x00000011) & 0xC30C30C3
    v = (v * 0x00000005) & 0x49249249
    return v


@kernel
def _clz64(x):
    """Leading zero bits of a non-negative int64 (keys here stay below 2**62)."""
    if x == 0:
        return 64
    n = 63
    while x > 1:
        x >>= 1
        n -= 1
    return n


@kernel
def _delta(keys, i, j):
    if j < 0 or j >= keys.shape[0]:
        return -1
    return _clz64(keys[i] ^ keys[j])


@kernel
def build_lbvh(lo, hi):
    """Karras' binary radix tree over Morton codes; same layout as build_top_down.

    Internal nodes come first (0 .. N-2, root 0), leaves after (N-1 .. 2N-2).
    """
    n = lo.shape[0]
    cap = max(2 * n - 1, 1)
    node_lo, node_hi, left, right, parent, depth, start, count = _empty_nodes(cap)
    if n == 0:
        return (node_lo[:0], node_hi[:0], left[:0], right[:0], parent[:0], depth[:0], start[:0],
                count[:0], np.arange(0))
    centroid = 0.5 * (lo + hi)
    cmin = np.empty(3)
    span = np.empty(3)
    for c in range(3):
        cmin[c] = centroid[:, c].min()
        span[c] = centroid[:, c].max() - cmin[c]
    keys = np.empty(n, dtype=np.int64)
    for i in range(n):
        code = 0
        for c in range(3):
            q = 0
            if span[c] > 0.0:
                q = int((centroid[i, c] - cmin[c]) / span[c] * 1023.0)
            code |= _expand_bits(np.int64(q)) << (2 - c)
        # unique 64-bit keys: Morton code above, primitive index below (ties by index)
        keys[i] = (code << 32) | i
    order = np.argsort(keys, kind="mergesort")
    keys = keys[order]
    first_leaf = n - 1
    for k in range(n):
        leaf = first_leaf + k
        start[leaf] = k
        count[leaf] = 1
    for i in range(n - 1):
        d = 1 if _delta(keys, i, i + 1) - _delta(keys, i, i - 1) > 0 else -1
        delta_min = _delta(keys, i, i - d)
        l_max = 2
        while _delta(keys, i, i + l_max * d) > delta_min:
            l_max *= 2
        l_len = 0
        t = l_max // 2
        while t >= 1:
            if _delta(keys, i, i + (l_len + t) * d) > delta_min:
                l_len += t
            t //= 2
        j = i + l_len * d
        delta_node = _delta(keys, i, j)
        s = 0
        divisor = 2
        t = (l_len + divisor - 1) // divisor
        while True:
            if _delta(keys, i, i + (s + t) * d) > delta_node:
                s += t
            if t == 1:
                break
            divisor *= 2
            t = (l_len + divisor - 1) // divisor
        gamma = i + s * d + min(d, 0)
        lo_end = min(i, j)
        hi_end = max(i, j)
        a = first_leaf + gamma if lo_end == gamma else gamma
        b = first_leaf + gamma + 1 if hi_end == gamma + 1 else gamma + 1
        left[i] = a
        right[i] = b
        parent[a] = i
        parent[b] = i
    # depth top-down (pre-order from the root), then bounds bottom-up
    stack = np.empty(2 * n - 1, dtype=np.int64)
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        if left[node] >= 0:
            depth[left[node]] = depth[node] + 1
            depth[right[node]] = depth[node] + 1
            stack[top] = right[node]
            top += 1
            stack[top] = left[node]
            top += 1
    refit(lo, hi, node_lo, node_hi, left, right, parent, start, count, order)
    return node_lo, node_hi, left, right, parent, depth, start, count, order


@kernel
def refit(lo, hi, node_lo, node_hi, left, right, parent, start, count, order):
    """New bounds for the same topology (children are fitted before their parents)."""
    m = node_lo.shape[0]
    if m == 0:
        return
    pre = np.empty(m, dtype=np.int64)
    stack = np.empty(m, dtype=np.int64)
    root = 0
    for k in range(m):
        if parent[k] < 0:
            root = k
            break
    stack[0] = root
    top = 1
    used = 0
    while top > 0:
        top -= 1
        node = stack[top]
        pre[used] = node
        used += 1
        if left[node] >= 0:
            stack[top] = right[node]
            top += 1
            stack[top] = left[node]
            top += 1
    for idx in range(used - 1, -1, -1):
        node = pre[idx]
        if left[node] < 0:
            _fit_leaf(lo, hi, order, start[node], count[node], node_lo, node_hi, node)
        else:
            for c in range(3):
                node_lo[node, c] = min(node_lo[left[node], c], node_lo[right[node], c])
                node_hi[node, c] = max(node_hi[left[node], c], node_hi[right[node], c])


@kernel
def _emit(out, count, i, j):
    if count == out.shape[0]:
        bigger = np.empty((2 * count + 16, 2), dtype=np.int64)
        bigger[:count] = out[:count]
        out = bigger
    out[count, 0] = min(i, j)
    out[count, 1] = max(i, j)
    return out, count + 1


@kernel
def self_pairs(lo, hi, node_lo, node_hi, left, right, start, count, order, root, limit):
    """All overlapping primitive pairs by simultaneous descent; (pairs, nodes visited, box tests).

    Stops after limit + 1 pairs (over the budget)."""
    n = lo.shape[0]
    out = np.empty((max(16, 4 * n), 2), dtype=np.int64)
    found = 0
    visited = 0
    tests = 0
    if node_lo.shape[0] == 0:
        return out[:0], 0, 0
    stack = np.empty((64 + 4 * node_lo.shape[0], 2), dtype=np.int64)
    stack[0, 0] = root
    stack[0, 1] = root
    top = 1
    while top > 0 and found <= limit:
        top -= 1
        a = stack[top, 0]
        b = stack[top, 1]
        visited += 1
        if a == b:
            if left[a] < 0:
                s = start[a]
                for x in range(s, s + count[a]):
                    for y in range(x + 1, s + count[a]):
                        tests += 1
                        p = order[x]
                        q = order[y]
                        if boxes_overlap(lo, hi, p, q):
                            out, found = _emit(out, found, p, q)
            else:
                if top + 3 > stack.shape[0]:
                    grown = np.empty((2 * stack.shape[0], 2), dtype=np.int64)
                    grown[:top] = stack[:top]
                    stack = grown
                stack[top, 0] = left[a]
                stack[top, 1] = left[a]
                stack[top + 1, 0] = right[a]
                stack[top + 1, 1] = right[a]
                stack[top + 2, 0] = left[a]
                stack[top + 2, 1] = right[a]
                top += 3
            continue
        tests += 1
        if not boxes_overlap(node_lo, node_hi, a, b):
            continue
        a_leaf = left[a] < 0
        b_leaf = left[b] < 0
        if a_leaf and b_leaf:
            for x in range(start[a], start[a] + count[a]):
                for y in range(start[b], start[b] + count[b]):
                    tests += 1
                    p = order[x]
                    q = order[y]
                    if boxes_overlap(lo, hi, p, q):
                        out, found = _emit(out, found, p, q)
            continue
        if top + 2 > stack.shape[0]:
            grown = np.empty((2 * stack.shape[0], 2), dtype=np.int64)
            grown[:top] = stack[:top]
            stack = grown
        # descend into the larger node (or the one that is not a leaf)
        if b_leaf or (not a_leaf and _area(node_lo[a, 0], node_lo[a, 1], node_lo[a, 2], node_hi[a, 0],
                                            node_hi[a, 1], node_hi[a, 2])
                      >= _area(node_lo[b, 0], node_lo[b, 1], node_lo[b, 2], node_hi[b, 0], node_hi[b, 1],
                               node_hi[b, 2])):
            stack[top, 0] = left[a]
            stack[top, 1] = b
            stack[top + 1, 0] = right[a]
            stack[top + 1, 1] = b
        else:
            stack[top, 0] = a
            stack[top, 1] = left[b]
            stack[top + 1, 0] = a
            stack[top + 1, 1] = right[b]
        top += 2
    pairs = out[:found]
    if found > 1:
        rank = np.argsort(pairs[:, 0] * n + pairs[:, 1])
        pairs = pairs[rank]
    return pairs, visited, tests


@kernel
def query_box(node_lo, node_hi, left, right, start, count, order, lo, hi, box_lo, box_hi, root):
    """Primitives whose boxes overlap one box, sorted."""
    out = np.empty(16, dtype=np.int64)
    found = 0
    if node_lo.shape[0] == 0:
        return out[:0]
    stack = np.empty(node_lo.shape[0] + 1, dtype=np.int64)
    stack[0] = root
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        hit = True
        for c in range(3):
            if node_lo[node, c] > box_hi[c] or box_lo[c] > node_hi[node, c]:
                hit = False
        if not hit:
            continue
        if left[node] < 0:
            for x in range(start[node], start[node] + count[node]):
                p = order[x]
                inside = True
                for c in range(3):
                    if lo[p, c] > box_hi[c] or box_lo[c] > hi[p, c]:
                        inside = False
                if inside:
                    if found == out.shape[0]:
                        bigger = np.empty(2 * found, dtype=np.int64)
                        bigger[:found] = out[:found]
                        out = bigger
                    out[found] = p
                    found += 1
        else:
            stack[top] = left[node]
            top += 1
            stack[top] = right[node]
            top += 1
    return np.sort(out[:found])


@kernel
def sah_cost(node_lo, node_hi, left, count, root):
    """SAH cost with unit traversal and test costs: sum A(node)/A(root) · (1 or leaf count)."""
    if node_lo.shape[0] == 0:
        return 0.0
    root_area = _area(node_lo[root, 0], node_lo[root, 1], node_lo[root, 2], node_hi[root, 0],
                      node_hi[root, 1], node_hi[root, 2])
    if root_area <= 0.0:
        return float(node_lo.shape[0])
    total = 0.0
    for node in range(node_lo.shape[0]):
        a = _area(node_lo[node, 0], node_lo[node, 1], node_lo[node, 2], node_hi[node, 0], node_hi[node, 1],
                  node_hi[node, 2]) / root_area
        total += a * (count[node] if left[node] < 0 else 1.0)
    return total


@dataclass
class BVHNodes:
    """A tree's node arrays (length M) and leaf order; see the module doc."""

    lo: np.ndarray
    hi: np.ndarray
    left: np.ndarray
    right: np.ndarray
    parent: np.ndarray
    depth: np.ndarray
    start: np.ndarray
    count: np.ndarray
    order: np.ndarray
    root: int = 0

    @property
    def size(self) -> int:
        return int(self.lo.shape[0])

    @property
    def max_depth(self) -> int:
        return int(self.depth.max()) if self.size else 0

    @property
    def leaves(self) -> np.ndarray:
        return np.nonzero(self.left < 0)[0]

    def copy(self) -> "BVHNodes":
        return BVHNodes(*(getattr(self, f).copy() for f in
                          ("lo", "hi", "left", "right", "parent", "depth", "start", "count", "order")),
                        root=self.root)


def build(lo: np.ndarray, hi: np.ndarray, method: str = "sah", leaf_size: int = 1) -> BVHNodes:
    """Build a BVH over boxes lo, hi (N, 3) with one of BUILD_NAMES."""
    lo = np.ascontiguousarray(lo, dtype=np.float64)
    hi = np.ascontiguousarray(hi, dtype=np.float64)
    code = BUILD_NAMES.index(method)
    if code == LBVH:
        arrays = build_lbvh(lo, hi)
    else:
        arrays = build_top_down(lo, hi, code, leaf_size)
    return BVHNodes(*arrays)


@dataclass
class BVH:
    """Broad phase on one scene BVH, rebuilt or refitted each call (policy below).

    Refit keeps the tree's shape and recomputes bounds (O(N)); rebuild makes a new tree
    (O(N log N)). Policy: rebuild when N changes, when ``rebuild_every`` calls have
    passed, or when refitting raised the SAH cost above ``max_cost_growth`` times its
    value at the last rebuild (the tree has become a poor fit for where things are).
    """

    method: str = "sah"
    leaf_size: int = 1
    rebuild_every: int = 30
    max_cost_growth: float = 1.3
    name: str = field(init=False)
    nodes: BVHNodes | None = field(default=None, init=False, repr=False)
    query_scans_boxes: bool = field(default=False, init=False, repr=False)  # the tree is of the old boxes
    stats: dict = field(default_factory=dict, init=False, repr=False)
    _cost_at_build: float = field(default=0.0, init=False, repr=False)
    _since_build: int = field(default=0, init=False, repr=False)
    _lo: np.ndarray | None = field(default=None, init=False, repr=False)
    _hi: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        self.name = f"bvh-{self.method}"

    def renumbered(self) -> None:
        """The tree's leaves name boxes by index: the next call builds a new one."""
        self.nodes = None
        self._lo = self._hi = None

    def _update_tree(self, lo: np.ndarray, hi: np.ndarray) -> bool:
        t0 = perf_counter()
        rebuilt = True
        tree = self.nodes
        if tree is not None and len(tree.order) == lo.shape[0] and self._since_build < self.rebuild_every:
            refit(lo, hi, tree.lo, tree.hi, tree.left, tree.right, tree.parent, tree.start, tree.count, tree.order)
            cost = sah_cost(tree.lo, tree.hi, tree.left, tree.count, tree.root)
            if cost <= self.max_cost_growth * self._cost_at_build:
                rebuilt = False
                self._since_build += 1
        if rebuilt:
            self.nodes = build(lo, hi, self.method, self.leaf_size)
            cost = sah_cost(self.nodes.lo, self.nodes.hi, self.nodes.left, self.nodes.count, self.nodes.root)
            self._cost_at_build = cost
            self._since_build = 0
        self.stats = {"rebuilt": rebuilt, "build_seconds": perf_counter() - t0, "sah_cost": cost,
                      "nodes": self.nodes.size, "depth": self.nodes.max_depth}
        return rebuilt

    def pairs(self, lo: np.ndarray, hi: np.ndarray, limit: int = NO_LIMIT) -> np.ndarray:
        lo = np.ascontiguousarray(lo, dtype=np.float64)
        hi = np.ascontiguousarray(hi, dtype=np.float64)
        self._lo, self._hi = lo, hi
        self._update_tree(lo, hi)
        t0 = perf_counter()
        tree = self.nodes
        pairs, visited, tests = self_pairs(lo, hi, tree.lo, tree.hi, tree.left, tree.right, tree.start,
                                           tree.count, tree.order, tree.root, limit)
        self.stats.update(query_seconds=perf_counter() - t0, nodes_visited=int(visited), box_tests=int(tests),
                          pairs=len(pairs))
        return pairs

    def query(self, lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray) -> np.ndarray:
        """Boxes (as given to the last ``pairs`` call) that overlap one box."""
        if self.nodes is None or self._lo is None or self._lo.shape[0] != lo.shape[0]:
            self.pairs(lo, hi)
        tree = self.nodes
        return query_box(tree.lo, tree.hi, tree.left, tree.right, tree.start, tree.count, tree.order,
                         self._lo, self._hi, np.ascontiguousarray(box_lo, dtype=np.float64),
                         np.ascontiguousarray(box_hi, dtype=np.float64), tree.root)
