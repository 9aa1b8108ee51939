"""The world's own numbering of the spheres: close in space, close in memory.

A contact's swept tests read a row of each partner's per-sphere arrays (positions,
velocities, path boxes, radius, anchors...). With the spheres numbered as a scene lists
them (a generated scene: at random), a partner's row is anywhere among N; past the cache
(about 5 000 spheres here) each read waits on memory. Numbering them along a Z-curve
(Morton order) of their places puts neighbours in space at neighbouring rows. Measured on
box-rain 100k, stepped in turn in one process with the same run numbered otherwise
(docs/benchmarks.md, "Space order"): 17 % off the whole second in Morton order of the
starting places, 32 % in Morton order of the landed pile; 16–21 % off the exact gas at
32 000; nothing at 1 000, where everything fits the cache. Kept up inside the world, 30 %
off box-rain 100k.

So a world of many spheres keeps an internal numbering (``Settings.space_order``):

- ``given``: the scene's numbering (no permutation).
- ``morton``: Morton order of the places when the world is built, renewed every
  :data:`RENUMBER_EVERY` steps from where the spheres then are (World._renumber).
- ``auto`` (the default): ``morton`` from :data:`SPACE_ORDER_MIN` spheres up under the
  time-ordered policy, else ``given`` (small worlds fit the cache; the index-ordered
  policy resolves contacts in the order the spheres are numbered, which a user reads as
  the scene's).

Whatever the numbering inside, everything that leaves the world is in the scene's:
``World.state``, every event, the stats and the state hash (computed over the arrays in
the scene's numbering). What it changes is the order in which the engine meets exactly
simultaneous contacts and sweeps a held cluster, so a pile's last bits (and its state
hashes) can differ between ``given`` and ``morton`` (box-rain 1k and 10k do not; rain with
300 spheres does from step 221: tests/test_space_order.py); a run is as deterministic in
either. :class:`Numbering` is the one place indices cross between the two.
"""

from __future__ import annotations

import numpy as np

from .colliders.kinds import PARTNER_IS_SPHERE

SPACE_ORDER_NAMES = ("auto", "given", "morton")

# auto numbers a world in Morton order from this many spheres up: box-rain in turn gained
# nothing at 1 000 and 2 000 spheres, 4 % at 5 000, 7 % at 10 000 and 30 % at 100 000
# (docs/benchmarks.md, "Space order")
SPACE_ORDER_MIN = 4096

MORTON_BITS = 10  # per axis: 1024 cells a side, 30-bit keys

# a world in Morton order renumbers its spheres by where they are every this many steps
# (World._renumber): spheres that move apart in space drift apart in memory
RENUMBER_EVERY = 16


def morton_keys(points: np.ndarray, bits: int = MORTON_BITS) -> np.ndarray:
    """(N,) int64 Z-curve keys of points (N, 3) m: each axis quantised to ``bits`` bits
    over the points' bounding cube, the bits interleaved x (lowest), y, z."""
    return interleaved(quantised(points, bits), 3, bits)


def quantised(points: np.ndarray, bits: int) -> np.ndarray:
    """(N, 3) int64: each axis of points (N, 3) quantised to ``bits`` bits over the points'
    bounding cube (all in one place: all 0)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if points.shape[0] == 0:
        return np.zeros((0, 3), dtype=np.int64)
    low = points.min(axis=0)
    span = float((points.max(axis=0) - low).max()) or 1.0
    top = 2**bits - 1
    return np.clip(((points - low) * (top / span)).astype(np.int64), 0, top)


def interleaved(q: np.ndarray, axes: int, bits: int) -> np.ndarray:
    """(N,) int64: the low ``bits`` bits of the first ``axes`` columns of q (N, >= axes)
    interleaved, column 0 the lowest: bit k of column c goes to bit axes·k + c."""
    keys = np.zeros(q.shape[0], dtype=np.int64)
    for bit in range(bits):
        for axis in range(axes):
            keys |= ((q[:, axis] >> bit) & 1) << (axes * bit + axis)
    return keys


def morton_order(points: np.ndarray) -> np.ndarray:
    """(N,) int64 permutation: the indices of points (N, 3) along the Z-curve (ties by index)."""
    return np.argsort(morton_keys(points), kind="stable").astype(np.int64, copy=False)


def inverse_permutation(permutation: np.ndarray) -> np.ndarray:
    """(N,) int64 q with q[permutation[i]] = i."""
    inverse = np.empty(permutation.shape[0], dtype=np.int64)
    inverse[permutation] = np.arange(permutation.shape[0], dtype=np.int64)
    return inverse


def chosen_order(name: str, spheres: int, ordering: str) -> str:
    """What ``Settings.space_order`` = name means for a world of ``spheres`` spheres under
    the contact policy ``ordering`` ("time" or "index"): "given" or "morton"."""
    if name not in SPACE_ORDER_NAMES:
        raise ValueError(f"space_order must be one of {', '.join(SPACE_ORDER_NAMES)}, not {name!r}")
    if name == "auto":
        return "morton" if spheres >= SPACE_ORDER_MIN and ordering == "time" else "given"
    return name


class Numbering:
    """The permutation between the scene's numbering and the world's.

    inner_to_scene: (N,) int64 — the world's sphere i is the scene's sphere
    inner_to_scene[i]; scene_to_inner: its inverse.
    """

    def __init__(self, inner_to_scene: np.ndarray):
        self.inner_to_scene = np.ascontiguousarray(inner_to_scene, dtype=np.int64)
        self.scene_to_inner = inverse_permutation(self.inner_to_scene)

    # np.take, not fancy indexing: 2-5 times faster on (N, 3) rows, and this runs twice a step
    def inward(self, scene_rows: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Per-sphere rows (N, ...) in the scene's numbering -> the world's: into ``out``
        in place if given, else a new array."""
        return np.take(scene_rows, self.inner_to_scene, axis=0, out=out)

    def outward(self, inner_rows: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Per-sphere rows (N, ...) in the world's numbering -> the scene's: into ``out``
        in place if given, else a new array."""
        return np.take(inner_rows, self.scene_to_inner, axis=0, out=out)

    def sphere(self, inner_index: int) -> int:
        """The scene's number of the world's sphere inner_index."""
        return int(self.inner_to_scene[inner_index])

    def spheres(self, inner_indices: np.ndarray) -> np.ndarray:
        """The scene's numbers of the world's spheres inner_indices (any int array)."""
        return self.inner_to_scene[inner_indices].astype(inner_indices.dtype, copy=False)

    def partners(self, kinds: np.ndarray, others: np.ndarray) -> np.ndarray:
        """Contacts' partners (kinds, others: (M,) ints, colliders' kind codes and partner
        indices) in the scene's numbering: a sphere's translated, a wall's index kept."""
        out = others.copy()
        sphere = np.asarray(PARTNER_IS_SPHERE)[kinds]
        out[sphere] = self.inner_to_scene[others[sphere]]
        return out
