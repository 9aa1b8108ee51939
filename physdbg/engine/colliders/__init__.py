"""Collider kinds: what a sphere can hit, as one table, one geometry and one switch.

A contact is sphere ``a`` against a partner of some kind (events.KIND_*): another sphere
(sphere.py), a wall (plane.py) or a fixed mesh's triangle (mesh.py). The engine never branches on a kind itself; it asks

* the table (kinds.py, events' rows) what a kind is in general: its name, and whether the
  partner is a sphere that moves (``partner_sphere``) or immovable;
* the switch below about its geometry: the swept test, the contact normal, the gap of a
  held contact, the partner's restitution, which partners a re-predicted sphere can meet,
  the narrow phase's candidates and the deepest overlap.

What the kinds read besides the particles is the *geometry*: one group per kind, in the
order of their codes (``geometry_of``: ``geometry[KIND_PAIR]`` is sphere.SphereGeometry,
``geometry[KIND_WALL]`` plane.PlaneGeometry, ``geometry[KIND_MESH]`` mesh.MeshGeometry),
each built and unpacked by its own module and handed down whole to every kernel that
reaches a kind. Adding a kind is one module beside sphere.py, plane.py and mesh.py (its
functions and its group), its row
in the table (events.KIND_NAMES, PARTNER_IS_SPHERE), its module in KIND_MODULES, and one
branch in each function of the switch (docs/colliders.md, "Adding an integrator or a collider kind"):
every function names each kind it handles and raises UNKNOWN_KIND for any other.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...events import KIND_MESH, KIND_PAIR, KIND_WALL
from ..jit import borrowing
from . import mesh, plane, sphere
from .kinds import KIND_NAMES, KINDS, PARTNER_IS_SPHERE, partner_sphere

__all__ = ["KIND_NAMES", "KINDS", "KIND_MODULES", "PARTNER_IS_SPHERE", "partner_sphere", "geometry_of",
           "check_kind_modules", "time_of_impact", "contact_normal", "contact_feature", "partner_surface",
           "partner_normal_motion", "partner_moves", "surface_gap", "contact_gap", "partner_restitution",
           "partners_of", "max_overlap", "deepest_overlap", "deepest_of_kind", "narrow_candidates", "every_candidate",
           "most_partners", "partners_bound",
           "searches_meshes", "mesh_search", "CALENDAR_TAKES", "partner_count", "immovable_partners_in"]

# each kind's module, in the order of the kinds' codes: its geometry group is ``module.GEOMETRY``
KIND_MODULES = (sphere, plane, mesh)
# whether the event calendar (engine/calendar.py) predicts each kind's contacts, from each
# kind module's CALENDAR: the calendar tests every kind it takes through this switch, and
# World refuses the calendar for a scene with partners of a kind it does not take
CALENDAR_TAKES = tuple(bool(module.CALENDAR) for module in KIND_MODULES)
# what every function of the switch raises for a kind it has no branch for (a kind added to
# the table but not to the switch fails at its first use, never runs another kind's code)
UNKNOWN_KIND = ("engine/colliders: a collider kind with no branch in this function of the switch (docs/colliders.md, "
                "\"Adding an integrator or a collider kind\")")


def check_kind_modules(names=KIND_NAMES, modules=KIND_MODULES) -> None:
    """Raise ValueError when the table of kinds and the kinds' modules disagree (a kind
    added to the table without its module, or the other way round). Run at import."""
    if len(names) != len(modules):
        missing = ", ".join(f"{code} {name}" for code, name in enumerate(names) if code >= len(modules))
        raise ValueError(f"engine/colliders: {len(names)} collider kinds in the table ({', '.join(names)}) but "
                         f"{len(modules)} modules in KIND_MODULES" + (f"; no module for {missing}" if missing else "")
                         + ": a kind is one module, its table row and one branch per switch function "
                           "(docs/colliders.md, \"Adding an integrator or a collider kind\")")


check_kind_modules()


def geometry_of(walls) -> tuple:
    """The geometry the kernels read (a plain tuple of each kind's group, as plain tuples,
    in kind order) from a scene's walls and box (state.Walls)."""
    return tuple(tuple(module.GEOMETRY.of(walls)) for module in KIND_MODULES)


@njit(cache=True, inline="always")
def time_of_impact(kind, ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, tolerance,
                   geometry):
    """Swept test of (kind, ia, other) on the paths (x, v, a: (N, 3)) from their anchors
    sigma (s): (start, t, work), the test's start in the step, the time of impact after it
    (s; inf or beyond step_end: none) and the work it counts against the swept-test budget
    (1, or a moving triangle's passes: mesh.time_of_impact). tolerance (m): the sphere
    pairs' root tolerance."""
    if kind == KIND_PAIR:
        return sphere.time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples,
                                     tolerance, geometry[KIND_PAIR])
    if kind == KIND_WALL:
        return plane.time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples,
                                    geometry[KIND_WALL])
    if kind == KIND_MESH:
        return mesh.time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples,
                                   tolerance, geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def contact_normal(kind, x, sigma, ia, other, geometry):
    """Unit normal (3 floats) from the partner to sphere ia at the anchors (times sigma (N,)
    s in the step: where a moving partner is then)."""
    if kind == KIND_PAIR:
        return sphere.normal(x, ia, other, geometry[KIND_PAIR])
    if kind == KIND_WALL:
        return plane.normal(x, ia, other, geometry[KIND_WALL])
    if kind == KIND_MESH:
        return mesh.normal(x, sigma, ia, other, geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def contact_feature(kind, x, sigma, ia, other, geometry) -> int:
    """Where sphere ia touches the partner, for the contact's row: 1 + the feature of a
    mesh's triangle (events.FEATURE_NAMES: face, edge, corner), 0 for other kinds."""
    if kind == KIND_PAIR or kind == KIND_WALL:
        return 0
    if kind == KIND_MESH:
        return 1 + mesh.feature(x, sigma, ia, other, geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partner_surface(kind, x, sigma, radius, ia, other, n0, n1, n2, geometry):
    """(u0, u1, u2, moving): the velocity (m/s) of an immovable partner's surface where
    sphere ia touches it along the normal n (a kinematic mesh's); (0, 0, 0, False) for a
    partner that stands still (and for a sphere, whose velocity the resolver reads itself)."""
    if kind == KIND_PAIR or kind == KIND_WALL:
        return 0.0, 0.0, 0.0, False
    if kind == KIND_MESH:
        return mesh.surface(x, sigma, radius, ia, other, n0, n1, n2, geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partner_normal_motion(kind, x, v, sigma, radius, ia, other, n0, n1, n2, geometry):
    """(velocity m/s, acceleration m/s²) of the partner's surface along the normal n where
    sphere ia touches it, at ia's anchor time: what a held contact's relative normal
    velocity and acceleration are measured from (resting.HeldContacts.surface). (0, 0)
    for a partner that stands still; a sphere's own motion is the solve's, not this."""
    if kind == KIND_PAIR or kind == KIND_WALL:
        return 0.0, 0.0
    if kind == KIND_MESH:
        return mesh.normal_motion(x, v, sigma, radius, ia, other, n0, n1, n2, geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partner_moves(kind, other, geometry) -> bool:
    """Whether the immovable partner ``other`` moves by a prescribed motion (a kinematic
    mesh's triangle); False for a partner that stands still and for a sphere."""
    if kind == KIND_PAIR or kind == KIND_WALL:
        return False
    if kind == KIND_MESH:
        return mesh.moves(other, geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


@borrowing
def surface_gap(kind, x, v, a, radius, ia, other, geometry):
    """(gap m, n0, n1, n2, on_face): sphere ia's gap to the partner's whole surface where it is
    nearest, the normal there and whether that point is inside a face (a mesh: any
    triangle of ``other``'s mesh, ``mesh.surface_gap``; a wall is one face; a sphere has
    no face)."""
    if kind == KIND_PAIR:
        gap, n0, n1, n2, _renewed = sphere.gap(x, radius, ia, other, geometry[KIND_PAIR])
        return gap, n0, n1, n2, False
    if kind == KIND_WALL:
        gap, n0, n1, n2, renewed = plane.gap(x, v, a, radius, ia, other, geometry[KIND_WALL])
        return gap, n0, n1, n2, renewed
    if kind == KIND_MESH:
        return mesh.surface_gap(x, radius, ia, other, geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


@borrowing
def contact_gap(kind, x, v, a, radius, ia, other, geometry):
    """(gap (m, < 0: overlap), n0, n1, n2, renewed) of a held contact at the anchors: where
    renewed, (n0, n1, n2) is the contact's normal now (a sphere pair turns as it rolls)."""
    if kind == KIND_PAIR:
        return sphere.gap(x, radius, ia, other, geometry[KIND_PAIR])
    if kind == KIND_WALL:
        return plane.gap(x, v, a, radius, ia, other, geometry[KIND_WALL])
    if kind == KIND_MESH:
        return mesh.gap(x, radius, ia, other, geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partner_restitution(kind, other, restitution, geometry):
    """The partner's restitution coefficient: restitution (N,) for spheres, the walls' own."""
    if kind == KIND_PAIR:
        return restitution[other]
    if kind == KIND_WALL:
        return plane.restitution(other, geometry[KIND_WALL])
    if kind == KIND_MESH:
        return mesh.restitution(other, geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partners_of(kind, p, box, adj_start, adj, path_lo, path_hi, batch_mark, batch, geometry, out, scan) -> int:
    """The candidates of ``kind`` that sphere p's new path must be swept-tested against, as
    rows (a, other) of out (K, 2); returns how many. box (2, 3): the new path's box, also
    p's row of path_lo, path_hi (N, 3), the boxes of every sphere's current path;
    adj_start, adj: the broad phase's partners (CSR); batch_mark (N,): the batch that last
    changed each sphere (batch: this one); scan: no lists, every sphere a partner
    (sphere.partners_of)."""
    if kind == KIND_PAIR:
        return sphere.partners_of(p, box, path_lo, path_hi, adj_start, adj, batch_mark, batch, geometry[KIND_PAIR],
                                  out, scan)
    if kind == KIND_WALL:
        return plane.partners_of(p, path_lo, path_hi, geometry[KIND_WALL], out)
    if kind == KIND_MESH:
        return mesh.partners_of(p, path_lo, path_hi, geometry[KIND_MESH], out)
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def immovable_partners_in(kind, p, lo, hi, geometry, out) -> int:
    """The immovable partners of ``kind`` (walls, triangles) the box of row p of lo, hi
    (N, 3) m reaches, as rows (p, other) of out (K, 2), in the order of their numbers;
    returns how many (out has rows for every partner of the kind: most_partners). A kind
    whose partners are spheres has none here (the caller lists those: the event
    calendar's neighbour lists)."""
    if kind == KIND_PAIR:
        return 0
    if kind == KIND_WALL:
        return plane.partners_of(p, lo, hi, geometry[KIND_WALL], out)
    if kind == KIND_MESH:
        return mesh.partners_of(p, lo, hi, geometry[KIND_MESH], out)
    raise ValueError(UNKNOWN_KIND)


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
def partner_count(kind, geometry) -> int:
    """How many immovable partners of ``kind`` the scene has (every wall, every triangle):
    each is a candidate of every sphere where no broad phase stands between them (the
    event calendar's walls). A kind whose partners are spheres has none here."""
    if kind == KIND_PAIR:
        return 0
    if kind == KIND_WALL:
        return plane.count(geometry[KIND_WALL])
    if kind == KIND_MESH:
        return mesh.count(geometry[KIND_MESH])
    raise ValueError(UNKNOWN_KIND)


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
def deepest_of_kind(kind, x, radius, pairs, geometry, ignore_tunnelled):
    """(depth m >= 0, sphere, partner) of the deepest overlap with partners of ``kind``:
    the candidate sphere pairs (M, 2), every wall, every triangle ((0, -1, -1) when none)."""
    if kind == KIND_PAIR:
        return sphere.deepest_where(x, radius, pairs, geometry[KIND_PAIR])
    if kind == KIND_WALL:
        return plane.deepest_where(x, radius, geometry[KIND_WALL], ignore_tunnelled)
    if kind == KIND_MESH:
        return mesh.deepest_where(x, radius, geometry[KIND_MESH], ignore_tunnelled)
    raise ValueError(UNKNOWN_KIND)


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


def narrow_candidates(kind: int, pairs: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                      geometry: tuple, together: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The narrow phase's candidates of ``kind`` at step start, (a (M,), other (M,)) int64:
    the broad phase's sphere pairs (M, 2) whose path boxes lo, hi (N, 3) meet, or the walls
    and triangles each path box reaches (``together``: the triangles by the simultaneous
    descent, mesh.reachable_together; the same candidates)."""
    if kind == KIND_PAIR:
        return sphere.candidates(pairs, lo, hi, geometry[KIND_PAIR])
    if kind == KIND_WALL:
        return plane.reachable(lo, hi, geometry[KIND_WALL])
    if kind == KIND_MESH:
        if together:
            return mesh.reachable_together(lo, hi, geometry[KIND_MESH])[:2]
        return mesh.reachable(lo, hi, geometry[KIND_MESH])
    raise ValueError(f"{UNKNOWN_KIND}: {kind}")


def every_candidate(kind: int, count: int, geometry: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Every candidate of ``kind`` among ``count`` spheres, with no broad phase (the slow
    reference loop's): (a (M,), other (M,)) int64, every pair i < j, every sphere–wall or every sphere–triangle."""
    if kind == KIND_PAIR:
        a, other = np.triu_indices(count, 1)
        return a.astype(np.int64), other.astype(np.int64)
    if kind == KIND_WALL:
        partners = plane.count(geometry[KIND_WALL])
    elif kind == KIND_MESH:
        partners = mesh.count(geometry[KIND_MESH])
    else:
        raise ValueError(f"{UNKNOWN_KIND}: {kind}")
    return (np.repeat(np.arange(count, dtype=np.int64), partners),
            np.tile(np.arange(partners, dtype=np.int64), count))
