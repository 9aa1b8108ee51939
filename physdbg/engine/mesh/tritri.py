"""Triangle against triangle: Möller's interval test (numba), the seed's narrow phase for meshes.

T. Möller, "A Fast Triangle-Triangle Intersection Test", J. Graphics Tools 2(2), 1997, in
its division-free form: reject when one triangle lies strictly on one side of the other's
plane; otherwise both triangles cut the line where the planes meet in an interval each,
and they intersect exactly when the intervals overlap. Coplanar triangles are tested in
2D (edge against edge, then one corner inside the other). Touching counts as meeting.

Signed distances to a plane are snapped to zero below ``PLANE_TOLERANCE`` times the size
of the two triangles (Möller uses a fixed 1e-6, which depends on the units), so a corner
lying on the other plane counts as on it, as the test's touching rule wants.
"""

from __future__ import annotations

import numpy as np

from ..jit import borrowing, kernel

PLANE_TOLERANCE = 1e-12  # relative to (triangle size)², the scale of the signed distances


@borrowing
def _sub(a, b, out):
    for c in range(3):
        out[c] = a[c] - b[c]


@borrowing
def _cross_into(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@borrowing
def _plane_distances(p0, p1, p2, q0, q1, q2, normal, scratch, eps):
    """Normal (3,) of plane (p0, p1, p2), unnormalised, and the signed distances (times
    its length) of q0, q1, q2, snapped to 0 within ``eps`` (returned as a tuple)."""
    _sub(p1, p0, scratch[0])
    _sub(p2, p0, scratch[1])
    _cross_into(scratch[0], scratch[1], normal)
    d = -(normal[0] * p0[0] + normal[1] * p0[1] + normal[2] * p0[2])
    d0 = normal[0] * q0[0] + normal[1] * q0[1] + normal[2] * q0[2] + d
    d1 = normal[0] * q1[0] + normal[1] * q1[1] + normal[2] * q1[2] + d
    d2 = normal[0] * q2[0] + normal[1] * q2[1] + normal[2] * q2[2] + d
    if abs(d0) <= eps:
        d0 = 0.0
    if abs(d1) <= eps:
        d1 = 0.0
    if abs(d2) <= eps:
        d2 = 0.0
    return d0, d1, d2


@borrowing
def _interval(v0, v1, v2, d0, d1, d2):
    """(a, b, c, x0, x1, coplanar): the triangle's interval on the planes' line is
    [a + b/x0, a + c/x1]·..., kept division-free as Möller's NEWCOMPUTE_INTERVALS."""
    if d0 * d1 > 0.0:
        return v2, (v0 - v2) * d2, (v1 - v2) * d2, d2 - d0, d2 - d1, False
    if d0 * d2 > 0.0:
        return v1, (v0 - v1) * d1, (v2 - v1) * d1, d1 - d0, d1 - d2, False
    if d1 * d2 > 0.0 or d0 != 0.0:
        return v0, (v1 - v0) * d0, (v2 - v0) * d0, d0 - d1, d0 - d2, False
    if d1 != 0.0:
        return v1, (v0 - v1) * d1, (v2 - v1) * d1, d1 - d0, d1 - d2, False
    if d2 != 0.0:
        return v2, (v0 - v2) * d2, (v1 - v2) * d2, d2 - d0, d2 - d1, False
    return 0.0, 0.0, 0.0, 0.0, 0.0, True


@borrowing
def _edges_cross_2d(ax, ay, bx, by, cx, cy, dx, dy):
    """Do segments ab and cd (2D) meet (touching counts)?"""
    d1 = (dx - cx) * (ay - cy) - (dy - cy) * (ax - cx)
    d2 = (dx - cx) * (by - cy) - (dy - cy) * (bx - cx)
    d3 = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    d4 = (bx - ax) * (dy - ay) - (by - ay) * (dx - ax)
    if ((d1 > 0.0 and d2 < 0.0) or (d1 < 0.0 and d2 > 0.0)) and ((d3 > 0.0 and d4 < 0.0) or (d3 < 0.0 and d4 > 0.0)):
        return True
    if d1 == 0.0 and min(cx, dx) <= ax <= max(cx, dx) and min(cy, dy) <= ay <= max(cy, dy):
        return True
    if d2 == 0.0 and min(cx, dx) <= bx <= max(cx, dx) and min(cy, dy) <= by <= max(cy, dy):
        return True
    if d3 == 0.0 and min(ax, bx) <= cx <= max(ax, bx) and min(ay, by) <= cy <= max(ay, by):
        return True
    if d4 == 0.0 and min(ax, bx) <= dx <= max(ax, bx) and min(ay, by) <= dy <= max(ay, by):
        return True
    return False


@borrowing
def _inside_2d(px, py, ax, ay, bx, by, cx, cy):
    """Is point p inside (or on) triangle abc (2D)?"""
    s0 = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
    s1 = (cx - bx) * (py - by) - (cy - by) * (px - bx)
    s2 = (ax - cx) * (py - cy) - (ay - cy) * (px - cx)
    return (s0 >= 0.0 and s1 >= 0.0 and s2 >= 0.0) or (s0 <= 0.0 and s1 <= 0.0 and s2 <= 0.0)


@borrowing
def _coplanar(normal, v0, v1, v2, u0, u1, u2):
    """Coplanar triangles: drop the normal's largest axis and test in 2D."""
    ax = abs(normal[0])
    ay = abs(normal[1])
    az = abs(normal[2])
    i = 1
    j = 2
    if ax < ay or ax < az:
        if ay >= az:
            i = 0
            j = 2
        else:
            i = 0
            j = 1
    v = ((v0[i], v0[j]), (v1[i], v1[j]), (v2[i], v2[j]))
    u = ((u0[i], u0[j]), (u1[i], u1[j]), (u2[i], u2[j]))
    for a in range(3):
        b = (a + 1) % 3
        for c in range(3):
            d = (c + 1) % 3
            if _edges_cross_2d(v[a][0], v[a][1], v[b][0], v[b][1], u[c][0], u[c][1], u[d][0], u[d][1]):
                return True
    if _inside_2d(v[0][0], v[0][1], u[0][0], u[0][1], u[1][0], u[1][1], u[2][0], u[2][1]):
        return True
    return _inside_2d(u[0][0], u[0][1], v[0][0], v[0][1], v[1][0], v[1][1], v[2][0], v[2][1])


@borrowing
def triangles_meet(v0, v1, v2, u0, u1, u2, scratch):
    """Do triangles (v0, v1, v2) and (u0, u1, u2) (each corner (3,), m) meet?

    ``scratch`` is a (4, 3) work array. Touching (a shared corner, an edge on a face)
    counts as meeting.
    """
    size = 0.0
    for c in range(3):
        size = max(size, abs(v1[c] - v0[c]), abs(v2[c] - v0[c]), abs(u1[c] - u0[c]), abs(u2[c] - u0[c]))
    eps = PLANE_TOLERANCE * size * size * size  # |normal| ~ size², a distance ~ size
    n1 = scratch[2]
    du0, du1, du2 = _plane_distances(v0, v1, v2, u0, u1, u2, n1, scratch, eps)
    if du0 * du1 > 0.0 and du0 * du2 > 0.0:
        return False
    n1x = n1[0]
    n1y = n1[1]
    n1z = n1[2]
    n2 = scratch[3]
    dv0, dv1, dv2 = _plane_distances(u0, u1, u2, v0, v1, v2, n2, scratch, eps)
    if dv0 * dv1 > 0.0 and dv0 * dv2 > 0.0:
        return False
    # direction of the planes' line; project on its largest axis
    lx = n1y * n2[2] - n1z * n2[1]
    ly = n1z * n2[0] - n1x * n2[2]
    lz = n1x * n2[1] - n1y * n2[0]
    axis = 0
    big = abs(lx)
    if abs(ly) > big:
        axis = 1
        big = abs(ly)
    if abs(lz) > big:
        axis = 2
    a, b, c, x0, x1, flat = _interval(v0[axis], v1[axis], v2[axis], dv0, dv1, dv2)
    if flat:
        scratch[2, 0] = n1x
        scratch[2, 1] = n1y
        scratch[2, 2] = n1z
        return _coplanar(scratch[2], v0, v1, v2, u0, u1, u2)
    d, e, f, y0, y1, flat = _interval(u0[axis], u1[axis], u2[axis], du0, du1, du2)
    if flat:
        scratch[2, 0] = n1x
        scratch[2, 1] = n1y
        scratch[2, 2] = n1z
        return _coplanar(scratch[2], v0, v1, v2, u0, u1, u2)
    xx = x0 * x1
    yy = y0 * y1
    xxyy = xx * yy
    t = a * xxyy
    i0 = t + b * x1 * yy
    i1 = t + c * x0 * yy
    t = d * xxyy
    j0 = t + e * xx * y1
    j1 = t + f * xx * y0
    if i0 > i1:
        i0, i1 = i1, i0
    if j0 > j1:
        j0, j1 = j1, j0
    return not (i1 < j0 or j1 < i0)


def brute_force_pairs(vertices_a: np.ndarray, faces_a: np.ndarray, vertices_b: np.ndarray,
                      faces_b: np.ndarray) -> np.ndarray:
    """Every meeting triangle pair (K, 2) (a's triangle, b's triangle), sorted: the
    reference the BVH descent is tested against (all F_a × F_b pairs)."""
    return _all_pairs(np.ascontiguousarray(vertices_a, dtype=np.float64), np.ascontiguousarray(faces_a, dtype=np.int64),
                      np.ascontiguousarray(vertices_b, dtype=np.float64), np.ascontiguousarray(faces_b, dtype=np.int64))


@kernel
def _all_pairs(va, fa, vb, fb):
    out = np.empty((max(fa.shape[0] * fb.shape[0], 1), 2), dtype=np.int64)
    found = 0
    scratch = np.empty((4, 3))
    for i in range(fa.shape[0]):
        for j in range(fb.shape[0]):
            if triangles_meet(va[fa[i, 0]], va[fa[i, 1]], va[fa[i, 2]], vb[fb[j, 0]], vb[fb[j, 1]], vb[fb[j, 2]],
                              scratch):
                out[found, 0] = i
                out[found, 1] = j
                found += 1
    return out[:found]
