"""Posts: fixed spheres a moving sphere bounces off, a collider kind for tests alone.

tests/test_extending.py copies this module into a copy of physdbg beside sphere.py,
plane.py and mesh.py, adds its row to the registry (events.COLLIDER_KINDS) and writes the
switch again: nothing else of physdbg changes, and the engine, the audit, the recording
and the view take posts from a scene's [[post]] tables. Everything a kind declares is
here: its group (``GEOMETRY``), whether the event calendar takes it (``CALENDAR``), its
scene and recording fields (``FIELDS``), the room its partners fill for the advisor
(``reach``), how the views draw it (``drawing``) and what the switch calls for it
(``SWITCH``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..jit import borrowing, kernel
from ..motion import path_acceleration_weight, path_coefficients
from ..toi import DISCRETE, SWEPT, pair_toi_sampled_scalar, pair_toi_swept_scalar
from .kinds import Drawing, Field, every_sphere_with  # noqa: F401 (every_sphere_with: the switch calls it)


class PostGeometry(NamedTuple):
    """This kind's group: centres (P, 3) m, radii (P,) m, restitution (P,)."""

    centres: np.ndarray
    radii: np.ndarray
    restitution: np.ndarray

    @classmethod
    def of(cls, partners) -> PostGeometry:
        """The group of a scene's posts (state.Partners of this kind)."""
        def floats(name):
            return np.ascontiguousarray(partners.fields[name], dtype=np.float64)
        return cls(floats("centre").reshape(-1, 3), floats("radius"), floats("restitution"))


GEOMETRY = PostGeometry
CALENDAR = True
FIELDS = (Field("centre", (3,), None, "[x, y, z] in m"),
          Field("radius", (), None, "metres > 0", lo=0.0, lo_open=True),
          Field("restitution", (), 1.0, "0 <= e <= 1 (default 1)", lo=0.0, hi=1.0))
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
    "partner_restitution": "restitution(other, group)",
    "partners_of": "partners_of(p, path_lo, path_hi, group, out)",
    "immovable_partners_in": "partners_of(p, lo, hi, group, out)",
    "partner_count": "count(group)",
    "deepest_of_kind": "deepest_where(x, radius, group)",
    "narrow_candidates": "reachable(lo, hi, group)",
    "every_candidate": "every_sphere_with(count, count(group))",
}


def reach(partners) -> tuple[np.ndarray, np.ndarray]:
    """The boxes (lo, hi (P, 3) m) the posts fill: a sphere that cannot reach them cannot
    touch a post (the advisor's question)."""
    centres, radii = partners.fields["centre"].reshape(-1, 3), partners.fields["radius"]
    return centres - radii[:, None], centres + radii[:, None]


def drawing(partners) -> Drawing:
    """Each post as a sphere."""
    return Drawing(partners.fields["centre"].reshape(-1, 3), partners.fields["radius"], np.zeros((0, 3, 3)))


@njit(cache=True, inline="always")
def count(posts) -> int:
    return posts[0].shape[0]


@njit(cache=True, inline="always")
def restitution(q, posts) -> float:
    return posts[2][q]


@njit(cache=True, inline="always")
def time_of_impact(i, q, x, v, a, radius, sigma, step_end, integrator, k, detection, samples, tolerance, posts):
    """Swept test of sphere i against post q from i's anchor: (start, t, 1), as a sphere
    pair whose second sphere stands still."""
    centres, radii = posts[0], posts[1]
    start = sigma[i]
    p1, _p2, dp = path_coefficients(integrator, k, 0.0)
    w = path_acceleration_weight(integrator, p1)
    dx0, dx1, dx2 = x[i, 0] - centres[q, 0], x[i, 1] - centres[q, 1], x[i, 2] - centres[q, 2]
    dv0, dv1, dv2 = v[i, 0] * dp + a[i, 0] * w, v[i, 1] * dp + a[i, 1] * w, v[i, 2] * dp + a[i, 2] * w
    horizon = step_end - start
    if detection == SWEPT:
        t = pair_toi_swept_scalar(dx0, dx1, dx2, dv0, dv1, dv2, a[i, 0], a[i, 1], a[i, 2], radius[i] + radii[q],
                                  integrator, k, horizon, tolerance)
    else:
        t = pair_toi_sampled_scalar(dx0, dx1, dx2, dv0, dv1, dv2, a[i, 0], a[i, 1], a[i, 2], radius[i] + radii[q],
                                    integrator, k, horizon, 1 if detection == DISCRETE else samples)
    return start, t, 1


@njit(cache=True, inline="always")
def normal(x, ia, q, posts):
    """Unit normal from post q's centre to sphere ia's (coincident: +x)."""
    centres = posts[0]
    d0, d1, d2 = x[ia, 0] - centres[q, 0], x[ia, 1] - centres[q, 1], x[ia, 2] - centres[q, 2]
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if length == 0.0:
        return 1.0, 0.0, 0.0
    return d0 / length, d1 / length, d2 / length


@borrowing
def gap(x, radius, ia, q, posts):
    """(gap m, n0, n1, n2, renewed): as a sphere pair's, the normal turning as ia rolls."""
    centres, radii = posts[0], posts[1]
    d0, d1, d2 = x[ia, 0] - centres[q, 0], x[ia, 1] - centres[q, 1], x[ia, 2] - centres[q, 2]
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    g = length - radius[ia] - radii[q]
    if length > 0.0:
        return g, d0 / length, d1 / length, d2 / length, True
    return g, 0.0, 0.0, 0.0, False


@borrowing
def surface_gap(x, radius, ia, q, posts):
    g, n0, n1, n2, _renewed = gap(x, radius, ia, q, posts)
    return g, n0, n1, n2, False


@njit(cache=True, inline="always")
def _reaches(lo, hi, i, centres, radii, q) -> bool:
    for c in range(3):
        if lo[i, c] > centres[q, c] + radii[q] or hi[i, c] < centres[q, c] - radii[q]:
            return False
    return True


@njit(cache=True, inline="always")
def partners_of(p, lo, hi, posts, out) -> int:
    """The posts whose boxes meet row p of lo, hi (N, 3), as rows (p, q) of out."""
    centres, radii = posts[0], posts[1]
    m = 0
    for q in range(centres.shape[0]):
        if _reaches(lo, hi, p, centres, radii, q):
            out[m, 0] = p
            out[m, 1] = q
            m += 1
    return m


@kernel
def reachable(lo, hi, posts):
    """(spheres (K,), posts (K,)) whose boxes meet."""
    centres, radii = posts[0], posts[1]
    n, count_ = lo.shape[0], centres.shape[0]
    ip = np.empty(n * count_, dtype=np.int64)
    iq = np.empty(n * count_, dtype=np.int64)
    m = 0
    for i in range(n):
        for q in range(count_):
            if _reaches(lo, hi, i, centres, radii, q):
                ip[m] = i
                iq[m] = q
                m += 1
    return ip[:m], iq[:m]


@borrowing
def deepest_where(x, radius, posts):
    """(depth m >= 0, sphere, post) of the deepest overlap ((0, -1, -1) when none)."""
    centres, radii = posts[0], posts[1]
    worst, who, which = 0.0, -1, -1
    for i in range(x.shape[0]):
        for q in range(centres.shape[0]):
            d0, d1, d2 = x[i, 0] - centres[q, 0], x[i, 1] - centres[q, 1], x[i, 2] - centres[q, 2]
            pen = radius[i] + radii[q] - math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if pen > worst:
                worst, who, which = pen, i, q
    return worst, who, which
