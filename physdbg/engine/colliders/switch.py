"""The collider switch: each function takes a collider kind and calls that kind's own.

WRITTEN BY physdbg/write_switch.py from the registry of kinds
(events.COLLIDER_KINDS) and each kind module's SWITCH: do not edit it; after adding or
changing a kind, run ``python physdbg/write_switch.py``
(docs/colliders.md, "Adding an integrator or a collider kind"). A test holds this
file equal to what that script writes. Every function names each kind it handles and
raises UNKNOWN_KIND for any other, so a kind missing here fails at its first use and
never runs another kind's code."""

from __future__ import annotations

from numba import njit

from ..jit import borrowing
from . import sphere, plane, mesh

# the kinds' modules this switch was written for, in the order of their codes
WRITTEN_FOR = ("sphere", "plane", "mesh")
KIND_MODULES = (sphere, plane, mesh)
# the registry and the kinds' SWITCH tables it was written from (switch_fingerprint): colliders/
# __init__ refuses to load a switch whose tables have changed since
WRITTEN_FROM = "6628f43366f2fc4d"
# what every function raises for a kind it has no branch for
UNKNOWN_KIND = ("engine/colliders: a collider kind with no branch in this function of the switch (docs/colliders.md, "
                "\"Adding an integrator or a collider kind\")")


@njit(cache=True, inline="always")
def time_of_impact(kind, ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, tolerance, geometry):
    """Swept test of (kind, ia, other) on the paths (x, v, a: (N, 3)) from their anchors
    sigma (s): (start, t, work), the test's start in the step, the time of impact after it
    (s; inf or beyond step_end: none) and the work it counts against the swept-test budget
    (1, or a moving triangle's passes: mesh.time_of_impact). tolerance (m): the sphere
    pairs' root tolerance."""
    if kind == 0:  # sphere
        return sphere.time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, tolerance, geometry[0])
    if kind == 1:  # wall
        return plane.time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, geometry[1])
    if kind == 2:  # mesh
        return mesh.time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, tolerance, geometry[2])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def contact_normal(kind, x, sigma, ia, other, geometry):
    """Unit normal (3 floats) from the partner to sphere ia at the anchors (times sigma (N,)
    s in the step: where a moving partner is then)."""
    if kind == 0:  # sphere
        return sphere.normal(x, ia, other, geometry[0])
    if kind == 1:  # wall
        return plane.normal(x, ia, other, geometry[1])
    if kind == 2:  # mesh
        return mesh.normal(x, sigma, ia, other, geometry[2])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def contact_feature(kind, x, sigma, ia, other, geometry):
    """Where sphere ia touches the partner, for the contact's row: 1 + the feature of a
    mesh's triangle (events.FEATURE_NAMES: face, edge, corner), 0 for a kind without
    features."""
    if kind == 0:  # sphere
        return 0
    if kind == 1:  # wall
        return 0
    if kind == 2:  # mesh
        return 1 + mesh.feature(x, sigma, ia, other, geometry[2])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partner_surface(kind, x, sigma, radius, ia, other, n0, n1, n2, geometry):
    """(u0, u1, u2, moving): the velocity (m/s) of an immovable partner's surface where
    sphere ia touches it along the normal n (a kinematic mesh's); (0, 0, 0, False) for a
    partner that stands still (and for a sphere, whose velocity the resolver reads itself)."""
    if kind == 0:  # sphere
        return (0.0, 0.0, 0.0, False)
    if kind == 1:  # wall
        return (0.0, 0.0, 0.0, False)
    if kind == 2:  # mesh
        return mesh.surface(x, sigma, radius, ia, other, n0, n1, n2, geometry[2])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partner_normal_motion(kind, x, v, sigma, radius, ia, other, n0, n1, n2, geometry):
    """(velocity m/s, acceleration m/s²) of the partner's surface along the normal n where
    sphere ia touches it, at ia's anchor time: what a held contact's relative normal
    velocity and acceleration are measured from (resting.HeldContacts.surface). (0, 0)
    for a partner that stands still; a sphere's own motion is the solve's, not this."""
    if kind == 0:  # sphere
        return (0.0, 0.0)
    if kind == 1:  # wall
        return (0.0, 0.0)
    if kind == 2:  # mesh
        return mesh.normal_motion(x, v, sigma, radius, ia, other, n0, n1, n2, geometry[2])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partner_moves(kind, other, geometry):
    """Whether the immovable partner ``other`` moves by a prescribed motion (a kinematic
    mesh's triangle); False for a partner that stands still and for a sphere."""
    if kind == 0:  # sphere
        return False
    if kind == 1:  # wall
        return False
    if kind == 2:  # mesh
        return mesh.moves(other, geometry[2])
    raise ValueError(UNKNOWN_KIND)


@borrowing
def surface_gap(kind, x, v, a, radius, ia, other, geometry):
    """(gap m, n0, n1, n2, on_face): sphere ia's gap to the partner's whole surface where it is
    nearest, the normal there and whether that point is inside a face (a mesh: any
    triangle of ``other``'s mesh, ``mesh.surface_gap``; a wall is one face; a sphere has
    no face)."""
    if kind == 0:  # sphere
        return sphere.surface_gap(x, radius, ia, other, geometry[0])
    if kind == 1:  # wall
        return plane.gap(x, v, a, radius, ia, other, geometry[1])
    if kind == 2:  # mesh
        return mesh.surface_gap(x, radius, ia, other, geometry[2])
    raise ValueError(UNKNOWN_KIND)


@borrowing
def contact_gap(kind, x, v, a, radius, ia, other, geometry):
    """(gap (m, < 0: overlap), n0, n1, n2, renewed) of a held contact at the anchors: where
    renewed, (n0, n1, n2) is the contact's normal now (a sphere pair turns as it rolls)."""
    if kind == 0:  # sphere
        return sphere.gap(x, radius, ia, other, geometry[0])
    if kind == 1:  # wall
        return plane.gap(x, v, a, radius, ia, other, geometry[1])
    if kind == 2:  # mesh
        return mesh.gap(x, radius, ia, other, geometry[2])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partner_restitution(kind, other, restitution, geometry):
    """The partner's restitution coefficient: restitution (N,) for spheres, each immovable
    partner's own."""
    if kind == 0:  # sphere
        return restitution[other]
    if kind == 1:  # wall
        return plane.restitution(other, geometry[1])
    if kind == 2:  # mesh
        return mesh.restitution(other, geometry[2])
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partners_of(kind, p, box, adj_start, adj, path_lo, path_hi, batch_mark, batch, geometry, out, scan):
    """The candidates of ``kind`` that sphere p's new path must be swept-tested against, as
    rows (a, other) of out (K, 2); returns how many. box (2, 3): the new path's box, also
    p's row of path_lo, path_hi (N, 3), the boxes of every sphere's current path;
    adj_start, adj: the broad phase's partners (CSR); batch_mark (N,): the batch that last
    changed each sphere (batch: this one); scan: no lists, every sphere a partner
    (sphere.partners_of)."""
    if kind == 0:  # sphere
        return sphere.partners_of(p, box, path_lo, path_hi, adj_start, adj, batch_mark, batch, geometry[0], out, scan)
    if kind == 1:  # wall
        return plane.partners_of(p, path_lo, path_hi, geometry[1], out)
    if kind == 2:  # mesh
        return mesh.partners_of(p, path_lo, path_hi, geometry[2], out)
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def immovable_partners_in(kind, p, lo, hi, geometry, out):
    """The immovable partners of ``kind`` (walls, triangles) the box of row p of lo, hi
    (N, 3) m reaches, as rows (p, other) of out (K, 2), in the order of their numbers;
    returns how many (out has rows for every partner of the kind: most_partners). A kind
    whose partners are spheres has none here (the caller lists those: the event
    calendar's neighbour lists)."""
    if kind == 0:  # sphere
        return 0
    if kind == 1:  # wall
        return plane.partners_of(p, lo, hi, geometry[1], out)
    if kind == 2:  # mesh
        return mesh.partners_of(p, lo, hi, geometry[2], out)
    raise ValueError(UNKNOWN_KIND)


@njit(cache=True, inline="always")
def partner_count(kind, geometry):
    """How many immovable partners of ``kind`` the scene has (every wall, every triangle):
    each is a candidate of every sphere where no broad phase stands between them (the
    event calendar's walls). A kind whose partners are spheres has none here."""
    if kind == 0:  # sphere
        return 0
    if kind == 1:  # wall
        return plane.count(geometry[1])
    if kind == 2:  # mesh
        return mesh.count(geometry[2])
    raise ValueError(UNKNOWN_KIND)


@borrowing
def deepest_of_kind(kind, x, radius, pairs, geometry, ignore_tunnelled):
    """(depth m >= 0, sphere, partner) of the deepest overlap with partners of ``kind``:
    the candidate sphere pairs (M, 2), every wall, every triangle ((0, -1, -1) when none).
    ignore_tunnelled: a sphere past the middle of a thin partner went through it and is
    not counted as overlapping it."""
    if kind == 0:  # sphere
        return sphere.deepest_where(x, radius, pairs, geometry[0])
    if kind == 1:  # wall
        return plane.deepest_where(x, radius, geometry[1], ignore_tunnelled)
    if kind == 2:  # mesh
        return mesh.deepest_where(x, radius, geometry[2], ignore_tunnelled)
    raise ValueError(UNKNOWN_KIND)


def narrow_candidates(kind, pairs, lo, hi, geometry, together=False):
    """The narrow phase's candidates of ``kind`` at step start, (a (M,), other (M,)) int64:
    the broad phase's sphere pairs (M, 2) whose path boxes lo, hi (N, 3) meet, or the walls
    and triangles each path box reaches (``together``: the triangles by the simultaneous
    descent, mesh.reachable_together; the same candidates)."""
    if kind == 0:  # sphere
        return sphere.candidates(pairs, lo, hi, geometry[0])
    if kind == 1:  # wall
        return plane.reachable(lo, hi, geometry[1])
    if kind == 2:  # mesh
        return mesh.reachable_together(lo, hi, geometry[2])[:2] if together else mesh.reachable(lo, hi, geometry[2])
    raise ValueError(f"{UNKNOWN_KIND}: {kind}")


def every_candidate(kind, count, geometry):
    """Every candidate of ``kind`` among ``count`` spheres, with no broad phase (the slow
    reference loop's): (a (M,), other (M,)) int64, every pair i < j, or every sphere with
    every immovable partner of the kind."""
    if kind == 0:  # sphere
        return sphere.every_pair(count)
    if kind == 1:  # wall
        return plane.every_sphere_with(count, plane.count(geometry[1]))
    if kind == 2:  # mesh
        return mesh.every_sphere_with(count, mesh.count(geometry[2]))
    raise ValueError(f"{UNKNOWN_KIND}: {kind}")
