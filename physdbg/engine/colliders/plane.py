"""Plane partners: the seed's walls, one collider kind (events.KIND_WALL).

A wall is the plane n·x = d (normals (W, 3) unit, offsets (W,) m), one-sided (it keeps
spheres on the side n points to) or two-sided (a thin slab of half-thickness h that
pushes a sphere back to whichever side its anchor is on). What the engine asks about
sphere i against wall w, each function reached through the switch in
``colliders/switch.py``: its swept test, its contact normal and gap, which walls a
sphere's box reaches, and the deepest overlap. Immovable: the partner takes no impulse
(colliders.kinds.PARTNER_IS_SPHERE). What a wall reads is this kind's group,
``PlaneGeometry``, unpacked by ``_unpack`` alone.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..jit import borrowing, kernel
from ..toi import DISCRETE, SWEPT, wall_toi_sampled, wall_toi_swept
from .kinds import every_sphere_with  # noqa: F401 (the switch calls it: SWITCH["every_candidate"])


class PlaneGeometry(NamedTuple):
    """This kind's group of the geometry (colliders.geometry_of), the planes n·x = d (W
    rows): normals (W, 3) unit, offsets (W,) m, half_thickness (W,) m, two_sided (W,)
    bool, restitution (W,)."""

    normals: np.ndarray
    offsets: np.ndarray
    half_thickness: np.ndarray
    two_sided: np.ndarray
    restitution: np.ndarray

    @classmethod
    def of(cls, walls) -> PlaneGeometry:
        """The group of a scene's walls (state.Walls), as contiguous float64 (two_sided:
        bool) arrays."""
        def floats(values) -> np.ndarray:
            return np.ascontiguousarray(values, dtype=np.float64)
        return cls(floats(walls.normals).reshape(-1, 3), floats(walls.offsets), floats(walls.thickness * 0.5),
                   np.ascontiguousarray(walls.two_sided, dtype=np.bool_), floats(walls.restitution))


GEOMETRY = PlaneGeometry  # this kind's group (colliders.geometry_of)
# the event calendar (engine/calendar.py) predicts this kind's contacts from the anchors
# (colliders.CALENDAR_TAKES): each sphere lists the walls its shell's box reaches
CALENDAR = True
# what the collider switch (colliders/switch.py, written by physdbg/write_switch.py) answers for
# this kind: one expression per function of the switch, in its parameters' names,
# ``group`` this kind's geometry (PlaneGeometry)
SWITCH = {
    "time_of_impact": "time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, "
                      "group)",
    "contact_normal": "normal(x, ia, other, group)",
    "contact_feature": "0",
    "partner_surface": "(0.0, 0.0, 0.0, False)",
    "partner_normal_motion": "(0.0, 0.0)",
    "partner_moves": "False",
    "surface_gap": "gap(x, v, a, radius, ia, other, group)",
    "contact_gap": "gap(x, v, a, radius, ia, other, group)",
    "partner_restitution": "restitution(other, group)",
    "partners_of": "partners_of(p, path_lo, path_hi, group, out)",
    "immovable_partners_in": "partners_of(p, lo, hi, group, out)",
    "partner_count": "count(group)",
    "deepest_of_kind": "deepest_where(x, radius, group, ignore_tunnelled)",
    "narrow_candidates": "reachable(lo, hi, group)",
    "every_candidate": "every_sphere_with(count, count(group))",
}


@njit(cache=True, inline="always")
def _unpack(planes):
    """The group's fields (PlaneGeometry's order), the one place a kernel reads them."""
    return planes[0], planes[1], planes[2], planes[3], planes[4]


@njit(cache=True, inline="always")
def side_of(h, two_sided) -> float:
    """The side of a wall a centre at signed distance h = n·x - d (m) is pushed back to:
    +1, the side n points to, or -1 behind a two-sided wall (a thin slab pushes a sphere
    back to whichever side its centre is on). The one place a two-sided wall turns round."""
    return -1.0 if two_sided and h < 0.0 else 1.0


def sides(h: np.ndarray, two_sided: np.ndarray) -> np.ndarray:
    """side_of over arrays (readers of recordings): h (..., W) m, two_sided (W,) bool."""
    return np.where(np.asarray(two_sided, dtype=bool) & (np.asarray(h) < 0.0), -1.0, 1.0)


def gaps(x: np.ndarray, radius: np.ndarray, walls) -> np.ndarray:
    """(N, W) m: the gap between each sphere (centres x (N, 3), radius (N,)) and each wall
    of ``walls`` (state.Walls), on the side its centre is on (< 0: overlap), as the
    engine's wall_gap_terms measures it: for the readers of recordings (the audit,
    check-run), so that the rule is written once."""
    h = x @ walls.normals.T - walls.offsets[None, :]
    two_sided = np.asarray(walls.two_sided, dtype=bool)[None, :]
    return h * sides(h, two_sided) - 0.5 * walls.thickness[None, :] * two_sided - radius[:, None]


@borrowing
def wall_gap_terms(x, v, a, radius, i, normal, offset, half_thickness, two_sided):
    """(g0, p, q, side) of particle i's anchor against a wall n·x = d: the gap between the
    surfaces (m), its rate (m/s) and its path acceleration (m/s²) on i's side of the wall,
    and that side (side_of)."""
    h = normal[0] * x[i, 0] + normal[1] * x[i, 1] + normal[2] * x[i, 2] - offset
    side = side_of(h, two_sided)
    g0 = side * h - half_thickness - radius[i]
    p = side * (normal[0] * v[i, 0] + normal[1] * v[i, 1] + normal[2] * v[i, 2])
    q = side * (normal[0] * a[i, 0] + normal[1] * a[i, 1] + normal[2] * a[i, 2])
    return g0, p, q, side


@njit(cache=True, inline="always")
def count(planes) -> int:
    """How many walls."""
    return planes[0].shape[0]


@njit(cache=True, inline="always")
def restitution(w, planes) -> float:
    """Wall w's restitution coefficient."""
    return planes[4][w]


@njit(cache=True, inline="always")
def time_of_impact(i, w, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, planes):
    """Swept test of sphere i against wall w from i's anchor: (start, t), the test's start
    in the step (s) and the time of impact after it (s; inf or beyond the step: none)."""
    normals, offsets, half_thickness, two_sided, _restitution = _unpack(planes)
    g0, p, q, _ = wall_gap_terms(x, v, a, radius, i, normals[w], offsets[w], half_thickness[w], two_sided[w])
    start = sigma[i]
    horizon = step_end - start
    if detection == SWEPT:
        t = wall_toi_swept(g0, p, q, integrator, k, horizon)
    else:
        depth = 2.0 * (radius[i] + half_thickness[w]) if two_sided[w] else math.inf
        t = wall_toi_sampled(g0, p, q, integrator, k, horizon, 1 if detection == DISCRETE else samples, depth)
    return start, t, 1


@njit(cache=True, inline="always")
def normal(x, ia, w, planes):
    """Unit normal (3 floats) from wall w to sphere a: towards a's side of a two-sided wall."""
    normals, offsets, _half_thickness, two_sided, _restitution = _unpack(planes)
    nx = normals[w, 0]
    ny = normals[w, 1]
    nz = normals[w, 2]
    if side_of(nx * x[ia, 0] + ny * x[ia, 1] + nz * x[ia, 2] - offsets[w], two_sided[w]) < 0.0:
        return -nx, -ny, -nz
    return nx, ny, nz


@borrowing
def gap(x, v, a, radius, i, w, planes):
    """(gap (m, < 0: overlap), 0, 0, 0, False): a wall's normal never needs renewing."""
    normals, offsets, half_thickness, two_sided, _restitution = _unpack(planes)
    return wall_gap_terms(x, v, a, radius, i, normals[w], offsets[w], half_thickness[w], two_sided[w])[0], \
        0.0, 0.0, 0.0, False


@njit(cache=True, inline="always")
def reaches(lo, hi, i, normals, offsets, half_thickness, two_sided, w) -> bool:
    """Whether sphere i's box lo[i], hi[i] (m, radius included) reaches wall w: it is not
    entirely beyond the plane (or, for a two-sided wall, the slab)."""
    low = 0.0
    high = 0.0
    for c in range(3):
        a = normals[w, c] * lo[i, c]
        b = normals[w, c] * hi[i, c]
        low += min(a, b)
        high += max(a, b)
    low -= offsets[w]
    high -= offsets[w]
    h = half_thickness[w]
    return (two_sided[w] and low <= h and high >= -h) or (not two_sided[w] and low <= h)


@njit(cache=True, inline="always")
def partners_of(p, path_lo, path_hi, planes, out) -> int:
    """The walls (rows (p, w) of out (K, 2)) sphere p's new path must be tested against;
    returns how many: those the box of that path (row p of path_lo, path_hi) reaches (the
    step-start rule, :func:`reachable`)."""
    normals, offsets, half_thickness, two_sided, _restitution = _unpack(planes)
    m = 0
    for w in range(normals.shape[0]):
        if not reaches(path_lo, path_hi, p, normals, offsets, half_thickness, two_sided, w):
            continue
        out[m, 0] = p
        out[m, 1] = w
        m += 1
    return m


@kernel
def reachable(lo, hi, planes):
    """Sphere–wall candidates (spheres (K,), walls (K,)) whose swept box (lo, hi (N, 3), the
    radius included) reaches the wall: a box entirely beyond the plane (or slab) cannot
    touch it on its current path."""
    normals, offsets, half_thickness, two_sided, _restitution = _unpack(planes)
    n = lo.shape[0]
    nw = normals.shape[0]
    ip = np.empty(n * nw, dtype=np.int64)
    iw = np.empty(n * nw, dtype=np.int64)
    m = 0
    for i in range(n):
        for w in range(nw):
            if reaches(lo, hi, i, normals, offsets, half_thickness, two_sided, w):
                ip[m] = i
                iw[m] = w
                m += 1
    return ip[:m], iw[:m]


@borrowing
def deepest(x, radius, planes, ignore_tunnelled):
    """Deepest overlap (m, >= 0) of any sphere with any wall. ignore_tunnelled: a sphere
    past the middle of a thin wall went through it (discrete or sampled detection) and is
    not counted as overlapping it."""
    return deepest_where(x, radius, planes, ignore_tunnelled)[0]


@borrowing
def deepest_where(x, radius, planes, ignore_tunnelled):
    """(depth m >= 0, sphere, wall) of the deepest overlap of a sphere with a wall ((0, -1,
    -1) when none); ignore_tunnelled as in ``deepest``."""
    normals, offsets, half_thickness, two_sided, _restitution = _unpack(planes)
    worst = 0.0
    who = -1
    which = -1
    for i in range(x.shape[0]):
        for w in range(normals.shape[0]):
            h = normals[w, 0] * x[i, 0] + normals[w, 1] * x[i, 1] + normals[w, 2] * x[i, 2] - offsets[w]
            pen = half_thickness[w] + radius[i] - side_of(h, two_sided[w]) * h
            if ignore_tunnelled and two_sided[w] and pen > radius[i]:
                pen = 0.0
            if pen > worst:
                worst = pen
                who = i
                which = w
    return worst, who, which
