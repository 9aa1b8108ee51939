"""The table of collider kinds: what a contact's partner is, one row per kind.

A contact, a swept test and a held contact are (kind, a, other): sphere ``a`` against a
partner of kind ``kind`` (events.KIND_*), whose index is ``other``. Whatever the engine
asks about a kind *in general* is a column of this table; what it asks about the
geometry is the kind's own module (sphere.py, plane.py), reached through the switch in
``colliders/__init__``. A leaf (events' codes and numba only), so the
held-contact store (resting/) reads it too.
"""

from __future__ import annotations

from numba import njit

from ...events import KIND_NAMES, KIND_PAIR, KIND_WALL, PARTNER_IS_SPHERE

# the rows themselves are events' (readers ask them too): indexed by the kind's code
KINDS = len(KIND_NAMES)

assert KIND_NAMES[KIND_PAIR] == "sphere" and KIND_NAMES[KIND_WALL] == "wall"


@njit(cache=True, inline="always")
def partner_sphere(kind, other):
    """The partner's sphere index, or -1 when the partner is immovable (PARTNER_IS_SPHERE)."""
    return other if PARTNER_IS_SPHERE[kind] else -1
