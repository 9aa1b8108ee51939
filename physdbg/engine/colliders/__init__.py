"""Collider kinds: what a sphere can hit, as one registry, one geometry and one switch.

A contact is sphere ``a`` against a partner of some kind (events.KIND_*): another sphere
(sphere.py), a wall (plane.py) or a fixed mesh's triangle (mesh.py). The engine never
branches on a kind itself; it asks

* the registry (events.COLLIDER_KINDS, read through kinds.py) what a kind is in general:
  its name, and whether the partner is a sphere that moves (``partner_sphere``) or
  immovable;
* the switch (switch.py, written by physdbg/write_switch.py from the registry and each kind
  module's ``SWITCH``) about its geometry: the swept test, the contact normal, the gap of
  a held contact, the partner's restitution, which partners a re-predicted sphere can
  meet, the narrow phase's candidates and the deepest overlap;
* the kind's module for the rest of its declaration: ``GEOMETRY`` (its group), whether
  the event calendar takes it (``CALENDAR``) and, for a kind beyond the wall and the
  mesh, its scene fields and how it is drawn (``FIELDS``, ``drawing``: docs/colliders.md).

What the kinds read besides the particles is the *geometry*: one group per kind, in the
order of their codes (``geometry_of``: ``geometry[KIND_PAIR]`` is sphere.SphereGeometry,
``geometry[KIND_WALL]`` plane.PlaneGeometry, ``geometry[KIND_MESH]`` mesh.MeshGeometry),
each built and unpacked by its own module and handed down whole to every kernel that
reaches a kind. Adding a kind is one module beside sphere.py, plane.py and mesh.py and
its row in the registry, then the switch written again (docs/colliders.md, "Adding an
integrator or a collider kind").
"""

from __future__ import annotations

import hashlib

import numpy as np
from numba import njit

from ...errors import KindRegistryError
from ...events import COLLIDER_KINDS, KIND_MESH
from ..jit import borrowing
from ..state import Partners
from . import mesh
from .kinds import KIND_NAMES, KINDS, PARTNER_IS_SPHERE, partner_sphere
from .switch import (KIND_MODULES, UNKNOWN_KIND, WRITTEN_FOR, WRITTEN_FROM, contact_feature, contact_gap, contact_normal, deepest_of_kind,
                     every_candidate, immovable_partners_in, narrow_candidates, partner_count, partner_moves,
                     partner_normal_motion, partner_restitution, partner_surface, partners_of, surface_gap,
                     time_of_impact)

__all__ = ["KIND_NAMES", "KINDS", "KIND_MODULES", "PARTNER_IS_SPHERE", "UNKNOWN_KIND", "partner_sphere",
           "geometry_of", "check_kind_modules", "time_of_impact", "contact_normal", "contact_feature",
           "partner_surface", "partner_normal_motion", "partner_moves", "surface_gap", "contact_gap",
           "partner_restitution", "partners_of", "max_overlap", "deepest_overlap", "deepest_of_kind",
           "narrow_candidates", "every_candidate", "most_partners", "partners_bound", "searches_meshes",
           "mesh_search", "CALENDAR_TAKES", "partner_count", "immovable_partners_in", "extra_kinds"]

# KIND_MODULES (from the switch, which imports them): each kind's module, in the order of
# the kinds' codes (the registry's, as check_kind_modules holds): its geometry group is
# ``module.GEOMETRY``
# whether the event calendar (engine/calendar.py) predicts each kind's contacts, from each
# kind module's CALENDAR: the calendar tests every kind it takes through this switch, and
# World refuses the calendar for a scene with partners of a kind it does not take
CALENDAR_TAKES = tuple(bool(module.CALENDAR) for module in KIND_MODULES)
HOW_TO_ADD = ("a kind is one module, its row in the registry (events.COLLIDER_KINDS) and the switch written again "
              "(python physdbg/write_switch.py; docs/colliders.md, \"Adding an integrator or a "
              "collider kind\")")


def check_kind_modules(names=KIND_NAMES, modules=KIND_MODULES,
                       written_for=WRITTEN_FOR, registered=tuple(row.module for row in COLLIDER_KINDS)) -> None:
    """Raise KindRegistryError (a ValueError) when the registry of kinds, the kinds' modules
    and the switch disagree (a switch written for other kinds than the registry's, or a
    kind in the table without its module). Run at import."""
    if tuple(written_for) != tuple(registered):
        raise KindRegistryError(f"engine/colliders: the switch (switch.py) was written for the kinds' modules "
                                f"{', '.join(written_for)} but the registry lists {', '.join(registered)}: "
                                f"{HOW_TO_ADD}")
    if len(names) == len(modules) and modules is KIND_MODULES and WRITTEN_FROM != switch_fingerprint():
        raise KindRegistryError("engine/colliders: the switch (switch.py) was written from other SWITCH tables than "
                                f"the kinds' modules hold now: {HOW_TO_ADD}")
    if len(names) != len(modules):
        missing = ", ".join(f"{code} {name}" for code, name in enumerate(names) if code >= len(modules))
        raise KindRegistryError(f"engine/colliders: {len(names)} collider kinds in the table ({', '.join(names)}) "
                                f"but {len(modules)} modules in KIND_MODULES"
                                + (f"; no module for {missing}" if missing else "") + f": {HOW_TO_ADD}")


def switch_fingerprint() -> str:
    """The digest of the registry and the loaded kinds' SWITCH tables, as write_switch.py
    computes it from their text (switch.WRITTEN_FROM holds the one it wrote from)."""
    text = repr([(row.name, row.module, sorted(module.SWITCH.items()))
                 for row, module in zip(COLLIDER_KINDS, KIND_MODULES)])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


check_kind_modules()


def extra_kinds() -> tuple:
    """(code, name, module) of each kind whose partners a scene lists in a table of its own
    (a kind beyond the sphere, the wall and the mesh: its module declares ``FIELDS``)."""
    return tuple((code, row.name, module) for code, (row, module) in enumerate(zip(COLLIDER_KINDS, KIND_MODULES))
                 if _declares_fields(module))


def geometry_of(walls) -> tuple:
    """The geometry the kernels read (a plain tuple of each kind's group, as plain tuples,
    in kind order) from a scene's walls and box (state.Walls)."""
    return tuple(tuple(module.GEOMETRY.of(_partners(walls, row.name, module) if _declares_fields(module) else walls))
                 for row, module in zip(COLLIDER_KINDS, KIND_MODULES))


def _declares_fields(module) -> bool:
    return getattr(module, "FIELDS", None) is not None


def _partners(walls, name: str, module):
    """The scene's partners of the kind ``name`` (state.Partners; none: empty, each field
    an empty array), what the geometry of a kind declaring FIELDS is built from."""
    partners = getattr(walls, "partners", {}).get(name)
    return partners if partners is not None else Partners.empty(module.FIELDS)


@njit(cache=True, inline="always")
def searches_meshes(geometry) -> bool:
    """Whether a re-predicted sphere's path is asked of any mesh's tree (the scene has
    triangles): the contact loop then logs the box it asks with, in an observed step."""
    return mesh.count(geometry[KIND_MESH]) > 0


def mesh_search(lo: np.ndarray, hi: np.ndarray, geometry: tuple) -> tuple:
    """Every node of the meshes' trees the engine's walk visits for the boxes lo, hi (J, 3)
    (mesh.search_visits; the meshes placed as for the step): (query, node, outcome,
    parent) (V,) int64 each."""
    return mesh.search_visits(np.ascontiguousarray(lo, dtype=np.float64), np.ascontiguousarray(hi, dtype=np.float64),
                              geometry[KIND_MESH])


@njit(cache=True, inline="always")
def most_partners(geometry, max_degree) -> int:
    """The most candidates of one kind a re-predicted sphere can have (the size of
    partners_of's ``out``): its broad-phase partners (at most max_degree), or every
    immovable partner of a kind (every wall, every triangle). Every kind of the table is
    asked (partner_count: a kind with no branch there is refused, never left out)."""
    most = max_degree
    for kind in range(KINDS):
        most = max(most, partner_count(kind, geometry))
    return most


@njit(cache=True, inline="always")
def partners_bound(geometry, max_degree) -> int:
    """The most candidates of every kind together a re-predicted sphere can have."""
    bound = max_degree
    for kind in range(KINDS):
        bound += partner_count(kind, geometry)
    return bound


@borrowing
def max_overlap(x, radius, pairs, geometry, ignore_tunnelled):
    """Deepest overlap (m, >= 0) of the candidate sphere pairs (M, 2) and of every sphere
    with every wall and triangle (ignore_tunnelled: see plane.deepest, mesh.deepest)."""
    return deepest_overlap(x, radius, pairs, geometry, ignore_tunnelled)[0]


@borrowing
def deepest_overlap(x, radius, pairs, geometry, ignore_tunnelled):
    """max_overlap and who: (depth m >= 0, kind, sphere, partner) of the deepest overlap of
    every kind of the table, (0.0, -1, -1, -1) when none; a pair's partner is the other
    sphere, as in contacts."""
    best, best_kind, a, other = 0.0, -1, -1, -1
    for kind in range(KINDS):
        depth, i, j = deepest_of_kind(kind, x, radius, pairs, geometry, ignore_tunnelled)
        if depth > best:
            best, best_kind, a, other = depth, kind, i, j
    return best, best_kind, a, other
