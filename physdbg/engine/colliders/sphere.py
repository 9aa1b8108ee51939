"""Sphere partners: the seed's sphere–sphere contact, one collider kind (events.KIND_PAIR).

What the engine asks about a pair of spheres i < j, each function reached through the
switch (``colliders/switch.py``): its swept test, its contact normal and gap, which
partners a re-predicted sphere can meet, and the deepest overlap. Positions are (N, 3) m.
What a pair reads besides the particles is this kind's group, ``SphereGeometry``: the
period (3,) m of the periodic axes (0 = not periodic), where the minimum image counts.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..broadphase.boxes import box_misses
from ..jit import borrowing, kernel
from ..motion import path_acceleration_weight, path_coefficients
from ..periodic import image
from ..toi import DISCRETE, SWEPT, pair_toi_sampled_scalar, pair_toi_swept_scalar


class SphereGeometry(NamedTuple):
    """This kind's group of the geometry (colliders.geometry_of): period (3,) m, each
    periodic axis's length (0 = not periodic)."""

    period: np.ndarray

    @classmethod
    def of(cls, walls) -> SphereGeometry:
        """The group of a scene's walls and box (state.Walls)."""
        return cls(np.ascontiguousarray(walls.period, dtype=np.float64).reshape(3))


GEOMETRY = SphereGeometry  # this kind's group (colliders.geometry_of)
# the event calendar (engine/calendar.py) predicts this kind's contacts from the anchors
# (colliders.CALENDAR_TAKES): a pair is a neighbour on both spheres' lists
CALENDAR = True
# what the collider switch (colliders/switch.py, written by physdbg/write_switch.py) answers for
# this kind: one expression per function of the switch, in its parameters' names,
# ``group`` this kind's geometry (SphereGeometry)
SWITCH = {
    "time_of_impact": "time_of_impact(ia, other, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, "
                      "tolerance, group)",
    "contact_normal": "normal(x, ia, other, group)",
    "contact_feature": "0",
    "partner_surface": "(0.0, 0.0, 0.0, False)",
    "partner_normal_motion": "(0.0, 0.0)",
    "partner_moves": "False",
    "surface_gap": "surface_gap(x, radius, ia, other, group)",
    "contact_gap": "gap(x, radius, ia, other, group)",
    "partner_restitution": "restitution[other]",
    "partners_of": "partners_of(p, box, path_lo, path_hi, adj_start, adj, batch_mark, batch, group, out, scan)",
    "immovable_partners_in": "0",
    "partner_count": "0",
    "deepest_of_kind": "deepest_where(x, radius, pairs, group)",
    "narrow_candidates": "candidates(pairs, lo, hi, group)",
    "every_candidate": "every_pair(count)",
}


@njit(cache=True, inline="always")
def _unpack(spheres):
    """The group's fields (SphereGeometry's order), the one place a kernel reads them."""
    return spheres[0]


@njit(cache=True, inline="always")
def separation(x, ia, ib, period):
    """Centre of a minus centre of b (3 floats, m) at the anchors, through the minimum
    image on periodic axes, and its length."""
    d0 = image(x[ia, 0] - x[ib, 0], period[0])
    d1 = image(x[ia, 1] - x[ib, 1], period[1])
    d2 = image(x[ia, 2] - x[ib, 2], period[2])
    return d0, d1, d2, math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@njit(cache=True, inline="always")
def time_of_impact(i, j, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, tolerance, spheres):
    """Swept test of spheres i < j from the later of their anchors: (start, t), the test's
    start in the step (s) and the time of impact after it (s; inf or beyond the step: none)."""
    period = _unpack(spheres)
    start = max(sigma[i], sigma[j])
    pi1, pi2, dpi = path_coefficients(integrator, k, start - sigma[i])
    pj1, pj2, dpj = path_coefficients(integrator, k, start - sigma[j])
    wi = path_acceleration_weight(integrator, pi1)
    wj = path_acceleration_weight(integrator, pj1)
    # relative position (the minimum image on periodic axes) and path velocity at the
    # common start (see motion.path_state)
    dx0 = image((x[i, 0] + v[i, 0] * pi1 + a[i, 0] * pi2) - (x[j, 0] + v[j, 0] * pj1 + a[j, 0] * pj2), period[0])
    dx1 = image((x[i, 1] + v[i, 1] * pi1 + a[i, 1] * pi2) - (x[j, 1] + v[j, 1] * pj1 + a[j, 1] * pj2), period[1])
    dx2 = image((x[i, 2] + v[i, 2] * pi1 + a[i, 2] * pi2) - (x[j, 2] + v[j, 2] * pj1 + a[j, 2] * pj2), period[2])
    dv0 = (v[i, 0] * dpi + a[i, 0] * wi) - (v[j, 0] * dpj + a[j, 0] * wj)
    dv1 = (v[i, 1] * dpi + a[i, 1] * wi) - (v[j, 1] * dpj + a[j, 1] * wj)
    dv2 = (v[i, 2] * dpi + a[i, 2] * wi) - (v[j, 2] * dpj + a[j, 2] * wj)
    horizon = step_end - start
    if detection == SWEPT:
        t = pair_toi_swept_scalar(dx0, dx1, dx2, dv0, dv1, dv2, a[i, 0] - a[j, 0], a[i, 1] - a[j, 1],
                                  a[i, 2] - a[j, 2], radius[i] + radius[j], integrator, k, horizon, tolerance)
    else:
        t = pair_toi_sampled_scalar(dx0, dx1, dx2, dv0, dv1, dv2, a[i, 0] - a[j, 0], a[i, 1] - a[j, 1],
                                    a[i, 2] - a[j, 2], radius[i] + radius[j], integrator, k, horizon,
                                    1 if detection == DISCRETE else samples)
    return start, t, 1


@njit(cache=True, inline="always")
def normal(x, ia, ib, spheres):
    """Unit normal (3 floats) from b to a at the anchors; coincident centres give +x."""
    d0, d1, d2, length = separation(x, ia, ib, _unpack(spheres))
    if length == 0.0:
        return 1.0, 0.0, 0.0
    return d0 / length, d1 / length, d2 / length


@borrowing
def gap(x, radius, ia, ib, spheres):
    """(gap (m, < 0: overlap), n0, n1, n2, renewed): the gap between the surfaces at the
    anchors and the normal from b to a (renewed False where the centres coincide)."""
    d0, d1, d2, length = separation(x, ia, ib, _unpack(spheres))
    g = length - radius[ia] - radius[ib]
    if length > 0.0:
        return g, d0 / length, d1 / length, d2 / length, True
    return g, 0.0, 0.0, 0.0, False


@borrowing
def surface_gap(x, radius, ia, ib, spheres):
    """(gap m, n0, n1, n2, False): gap's gap and normal; a sphere has no face."""
    g, n0, n1, n2, _renewed = gap(x, radius, ia, ib, spheres)
    return g, n0, n1, n2, False


@njit(cache=True, inline="always")
def partners_of(p, box, path_lo, path_hi, adj_start, adj, batch_mark, batch, spheres, out, scan) -> int:
    """The pairs (a < other, rows of out (K, 2)) sphere p's new path must be tested against;
    returns how many.

    A pair whose both spheres changed in this batch is listed once, from the larger index.
    A partner q that did not change in this batch is listed only where the new path's box
    ``box`` (2, 3) meets the box of q's current path (path_lo, path_hi (N, 3): each
    sphere's path over the rest of the step, renewed whenever it is re-predicted). A path
    whose box misses another path's box cannot touch that path, so what is skipped is a
    miss; if q's path changes later, q is re-predicted against p's then. (Everything used
    to be tested: in box-rain 10k's last steps 3–4.6 million tests a step, 95 % of them
    misses; judging by the swept boxes grown to each sphere's reach left 55 % of them.)

    scan: the partners are not listed (adj_start, adj unread): every other sphere is one,
    judged by the same rules in the order of their numbers (World._choose_partner_search:
    where the lists would hold more pairs than a scan of every path box per re-prediction
    costs). A partner the lists would have held is found by the scan too (its path box is
    inside its grown box), so the tests a pair of lists and a scan make differ only by the
    misses with batch-mates too far away to be listed.
    """
    period = _unpack(spheres)
    m = 0
    first = 0 if scan else adj_start[p]
    end = path_lo.shape[0] if scan else adj_start[p + 1]
    for s in range(first, end):
        q = s if scan else adj[s]
        if q == p:  # only a scan meets p itself: no list holds it
            continue
        if batch_mark[q] == batch:
            if q < p:
                continue
        elif box_misses(box, path_lo, path_hi, q, period):
            continue
        out[m, 0] = min(p, q)
        out[m, 1] = max(p, q)
        m += 1
    return m


@borrowing
def deepest(x, radius, pairs, spheres):
    """Deepest overlap (m, >= 0) among the pairs (M, 2)."""
    return deepest_where(x, radius, pairs, spheres)[0]


@borrowing
def deepest_where(x, radius, pairs, spheres):
    """(depth m >= 0, sphere, partner sphere) of the deepest overlap among the pairs (M, 2)
    ((0, -1, -1) when none)."""
    period = _unpack(spheres)
    worst = 0.0
    who = -1
    which = -1
    for m in range(pairs.shape[0]):
        i = pairs[m, 0]
        j = pairs[m, 1]
        d = separation(x, i, j, period)[3]
        pen = radius[i] + radius[j] - d
        if pen > worst:
            worst = pen
            who = i
            which = j
    return worst, who, which


@kernel
def candidates(pairs, lo, hi, spheres):
    """The narrow phase's pairs (a (K,), other (K,)): those of the broad phase's (M, 2),
    i < j, whose boxes lo, hi (N, 3) meet (box_misses: on a periodic axis the minimum
    image decides, so the axis never tells them apart); in their order."""
    period = _unpack(spheres)
    m = pairs.shape[0]
    a = np.empty(m, dtype=np.int64)
    other = np.empty(m, dtype=np.int64)
    box = np.empty((2, 3))
    k = 0
    for t in range(m):
        i = pairs[t, 0]
        for c in range(3):
            box[0, c] = lo[i, c]
            box[1, c] = hi[i, c]
        if box_misses(box, lo, hi, pairs[t, 1], period):
            continue
        a[k] = i
        other[k] = pairs[t, 1]
        k += 1
    return a[:k], other[:k]


def every_pair(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pair i < j of ``count`` spheres, (a, other) int64 (the slow reference's)."""
    a, other = np.triu_indices(count, 1)
    return a.astype(np.int64), other.astype(np.int64)
