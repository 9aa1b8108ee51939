"""Any broad phase in a periodic box: the boxes that cross a periodic face get images.

Positions are wrapped into [origin, origin + L) on each periodic axis, and every swept
box is narrower than L/2 (World refuses a step otherwise), so a box can reach past at
most one face per axis. Each box that reaches past the face at origin + L gets an image
shifted by -L on that axis, and each that reaches below origin one shifted by +L; images
of images give the edges and corners. If boxes A and B overlap through some shift s, then
on every axis either A's image by -s or B's image by +s is among the boxes (the box that
reaches past the face has one), so the wrapped broad phase finds the pair among the
boxes and their images; the pairs are mapped back to the particles and deduplicated.
The narrow phase then meets each pair through the minimum image (periodic.py).
"""

from __future__ import annotations

import numpy as np

from .boxes import NO_LIMIT, boxes_meet


def images(lo: np.ndarray, hi: np.ndarray, origin: np.ndarray, period: np.ndarray):
    """(lo, hi, owner): the boxes lo, hi (N, 3) then their images across periodic faces;
    owner (M,) int64 is the particle each of the M >= N boxes belongs to."""
    owner = np.arange(lo.shape[0], dtype=np.int64)
    for c in range(3):
        length = float(period[c])
        if length <= 0:
            continue
        low = lo[:, c] < origin[c]
        high = hi[:, c] > origin[c] + length
        if not (low.any() or high.any()):
            continue
        shift = np.where(low, length, -length)
        crossing = np.nonzero(low | high)[0]
        moved_lo = lo[crossing].copy()
        moved_hi = hi[crossing].copy()
        moved_lo[:, c] += shift[crossing]
        moved_hi[:, c] += shift[crossing]
        lo = np.concatenate((lo, moved_lo))
        hi = np.concatenate((hi, moved_hi))
        owner = np.concatenate((owner, owner[crossing]))
    return lo, hi, owner


class PeriodicBroadPhase:
    """Wraps a broad phase (``inner``) for a box periodic on the axes where period > 0.

    The inner structure sees the boxes and their images (its stats and tree are of those);
    ``pairs`` gives particle pairs i < j, sorted, as every broad phase does.
    """

    def __init__(self, inner, origin: np.ndarray, period: np.ndarray):
        self.inner = inner
        self.name = inner.name
        self.query_scans_boxes = False  # through images: the loop's scan has none
        self.origin = np.asarray(origin, dtype=np.float64)
        self.period = np.asarray(period, dtype=np.float64)

    def renumbered(self) -> None:
        self.inner.renumbered()

    @property
    def stats(self) -> dict:
        return self.inner.stats

    @property
    def nodes(self):
        return self.inner.nodes

    def pairs(self, lo: np.ndarray, hi: np.ndarray, limit: int = NO_LIMIT) -> np.ndarray:
        n = lo.shape[0]
        all_lo, all_hi, owner = images(lo, hi, self.origin, self.period)
        found = self.inner.pairs(np.ascontiguousarray(all_lo), np.ascontiguousarray(all_hi), limit)
        self.inner.stats["images"] = len(owner) - n
        if len(found) > limit:
            return found
        a, b = owner[found[:, 0]], owner[found[:, 1]]
        keep = a != b
        first, second = np.minimum(a[keep], b[keep]), np.maximum(a[keep], b[keep])
        keys = np.sort(first * n + second)  # a pair found through several images comes once
        keys = keys[np.concatenate(([True], keys[1:] != keys[:-1]))] if len(keys) else keys
        out = np.empty((len(keys), 2), dtype=np.int64)
        np.floor_divide(keys, n, out=out[:, 0])
        np.remainder(keys, n, out=out[:, 1])
        return out

    def query(self, lo: np.ndarray, hi: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray) -> np.ndarray:
        """Boxes that overlap one box through any shift: a linear scan (re-queries are rare)."""
        return np.nonzero(boxes_meet(lo, hi, box_lo, box_hi, self.period))[0].astype(np.int64)
