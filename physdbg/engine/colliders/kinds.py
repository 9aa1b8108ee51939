"""The table of collider kinds: what a contact's partner is, one row per kind of the
registry (events.COLLIDER_KINDS), and the records a kind module declares with.

A contact, a swept test and a held contact are (kind, a, other): sphere ``a`` against a
partner of kind ``kind`` (events.KIND_*), whose index is ``other``. Whatever the engine
asks about a kind *in general* is a column of this table; what it asks about the
geometry is the kind's own module (sphere.py, plane.py), reached through the switch
(``colliders/switch.py``). A leaf (events' codes, numpy and numba only), so the
held-contact store (resting/) reads it too.
"""

from __future__ import annotations

import numpy as np
from typing import NamedTuple

from numba import njit

from ...events import KIND_MESH, KIND_NAMES, KIND_PAIR, KIND_WALL, PARTNER_IS_SPHERE

# the rows themselves are events' (readers ask them too): indexed by the kind's code
KINDS = len(KIND_NAMES)

assert KIND_NAMES[KIND_PAIR] == "sphere" and KIND_NAMES[KIND_WALL] == "wall" and KIND_NAMES[KIND_MESH] == "mesh"


@njit(cache=True, inline="always")
def partner_sphere(kind, other):
    """The partner's sphere index, or -1 when the partner is immovable (PARTNER_IS_SPHERE)."""
    return other if PARTNER_IS_SPHERE[kind] else -1


def every_sphere_with(count: int, partners: int) -> tuple[np.ndarray, np.ndarray]:
    """Every sphere of ``count`` with every one of ``partners`` immovable partners of a kind,
    (a (count·partners,), other) int64, sphere by sphere: the slow reference's candidates
    of a kind whose partners are not spheres."""
    return (np.repeat(np.arange(count, dtype=np.int64), partners),
            np.tile(np.arange(partners, dtype=np.int64), count))


class Field(NamedTuple):
    """A field of a kind's partners in a scene and a recording (a module's FIELDS): its
    name, the shape of one partner's value (() a number, (3,) a vector [x, y, z]), its
    default (None: required), what it means, with its unit (the scene's error messages
    quote it), and a number's bounds (lo, hi; lo_open: lo itself is refused)."""

    name: str
    shape: tuple
    default: object
    meaning: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False


class Drawing(NamedTuple):
    """What a view draws of a kind's partners (a module's ``drawing``): spheres (centres
    (S, 3) m, radii (S,) m) and triangles (corners (T, 3, 3) m), either may be empty."""

    centres: np.ndarray
    radii: np.ndarray
    triangles: np.ndarray
