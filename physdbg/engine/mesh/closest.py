"""The point of a triangle closest to a point, and which feature it lies on (numba).

Ericson, Real-Time Collision Detection 5.1.5: the point's Voronoi region of the triangle
decides: a corner's, an edge's or the face's. The feature is the contact's (a sphere that
meets a triangle meets it on its face, an edge or a corner): FACE, EDGE_0 (corners 0–1),
EDGE_1 (1–2), EDGE_2 (2–0), CORNER_0, CORNER_1, CORNER_2.
"""

from __future__ import annotations

from ...events import FEATURE_NAMES  # noqa: F401 (the features' names, one table: events.py)
from ..jit import borrowing

FACE, EDGE_0, EDGE_1, EDGE_2, CORNER_0, CORNER_1, CORNER_2 = range(7)


@borrowing
def closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """(qx, qy, qz, feature): the point of triangle abc closest to p (all m), and its feature."""
    abx = bx - ax
    aby = by - ay
    abz = bz - az
    acx = cx - ax
    acy = cy - ay
    acz = cz - az
    apx = px - ax
    apy = py - ay
    apz = pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, CORNER_0
    bpx = px - bx
    bpy = py - by
    bpz = pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz, CORNER_1
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        # d1 - d3 = |ab|² > 0, but computed from a far point's dot products it can cancel to 0
        t = d1 / (d1 - d3) if d1 - d3 > 0.0 else 0.0
        return ax + t * abx, ay + t * aby, az + t * abz, EDGE_0
    cpx = px - cx
    cpy = py - cy
    cpz = pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz, CORNER_2
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6) if d2 - d6 > 0.0 else 0.0  # |ac|², as above
        return ax + t * acx, ay + t * acy, az + t * acz, EDGE_2
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6)) if (d4 - d3) + (d5 - d6) > 0.0 else 0.0  # |bc|², as above
        return bx + t * (cx - bx), by + t * (cy - by), bz + t * (cz - bz), EDGE_1
    if va + vb + vc <= 0.0:
        # |ab × ac|² cancelled to nothing (a point far from a small triangle): its
        # projection on the triangle's plane, from the normal, which does not cancel
        nx = aby * acz - abz * acy
        ny = abz * acx - abx * acz
        nz = abx * acy - aby * acx
        s = (nx * apx + ny * apy + nz * apz) / (nx * nx + ny * ny + nz * nz)
        return px - s * nx, py - s * ny, pz - s * nz, FACE
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w, FACE
