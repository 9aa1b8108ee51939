"""Built-in mesh shapes, each (vertices (V, 3) m, faces (F, 3)) in its local frame, origin at
its centre of interest, triangles wound counter-clockwise seen from outside."""

from __future__ import annotations

import numpy as np


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], dtype=np.float64)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                  [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], dtype=np.int64)
    return v, f


def box(size: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A closed cube of side ``size`` centred on the origin (12 triangles); scaled per axis
    in a scene, a thin wall or a room."""
    s = 0.5 * size
    return _box((-s, -s, -s), (s, s, s))


def ramp(length: float = 2.0, width: float = 1.0, height: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """A wedge (a triangular prism): the slope rises along +x from z = 0 to ``height``."""
    h = 0.5 * width
    v = np.array([[0, -h, 0], [length, -h, 0], [length, -h, height],
                  [0, h, 0], [length, h, 0], [length, h, height]], dtype=np.float64)
    v[:, 0] -= 0.5 * length
    f = np.array([[0, 2, 1], [3, 4, 5], [0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [0, 3, 5], [0, 5, 2]],
                 dtype=np.int64)
    return v, f


def funnel(top_radius: float = 1.0, bottom_radius: float = 0.25, height: float = 1.0,
           segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """An open truncated cone about +z (a surface, no lid): the wide ring at z = ``height``."""
    angles = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.c_[np.cos(angles), np.sin(angles), np.zeros(segments)]
    bottom = ring * [bottom_radius, bottom_radius, 0.0]
    top = ring * [top_radius, top_radius, 0.0] + [0.0, 0.0, height]
    v = np.vstack([bottom, top])
    f = []
    for k in range(segments):
        n = (k + 1) % segments
        f += [[k, n, segments + n], [k, segments + n, segments + k]]
    return v, np.array(f, dtype=np.int64)


def box_with_hole(size: float = 1.0, hole: float = 0.4) -> tuple[np.ndarray, np.ndarray]:
    """A box of side ``size`` (a closed shell) whose top face has a square hole of side ``hole``."""
    s, q = 0.5 * size, 0.5 * hole
    v, f = _box((-s, -s, -s), (s, s, s))
    faces = [tri for tri in f.tolist() if not all(v[i, 2] == s for i in tri)]  # drop the top
    verts = v.tolist()
    outer = [4, 5, 6, 7]  # the top's corners (z = s)
    inner = []
    for x, y in ((-q, -q), (q, -q), (q, q), (-q, q)):
        inner.append(len(verts))
        verts.append([x, y, s])
    for k in range(4):
        n = (k + 1) % 4
        faces += [[outer[k], outer[n], inner[n]], [outer[k], inner[n], inner[k]]]
    return np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64)


def paddle(length: float = 1.0, width: float = 0.2, thickness: float = 0.05,
           segments: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A flat box, long along x, centred on the origin (its pivot), its four long sides
    cut into ``segments`` pieces along x (8·segments + 4 triangles),
    so that its BVH splits along the length as a blade's would."""
    xs = np.linspace(-0.5 * length, 0.5 * length, segments + 1)
    h, t = 0.5 * width, 0.5 * thickness
    # ring k: the four corners of the cross-section at xs[k] (y, z) = (-,-), (+,-), (+,+), (-,+)
    v = np.array([[x, y, z] for x in xs for y, z in ((-h, -t), (h, -t), (h, t), (-h, t))], dtype=np.float64)
    f = []
    for k in range(segments):
        a, b = 4 * k, 4 * (k + 1)
        for side in range(4):
            n = (side + 1) % 4
            f += [[a + side, b + n, b + side], [a + side, a + n, b + n]]
    last = 4 * segments
    f += [[0, 2, 1], [0, 3, 2], [last, last + 1, last + 2], [last, last + 2, last + 3]]  # the two ends
    return v, np.array(f, dtype=np.int64)


def icosphere(radius: float = 0.5, subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """An icosahedron subdivided ``subdivisions`` times, corners on the sphere (20·4^s triangles)."""
    t = (1.0 + 5.0 ** 0.5) / 2.0
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
         [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    verts = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in v]
    for _ in range(subdivisions):
        middle: dict[tuple[int, int], int] = {}

        def mid(i: int, j: int) -> int:
            key = (min(i, j), max(i, j))
            if key not in middle:
                p = verts[i] + verts[j]
                verts.append(p / np.linalg.norm(p))
                middle[key] = len(verts) - 1
            return middle[key]

        f = [tri for a, b, c in f for tri in ([a, mid(a, b), mid(c, a)], [b, mid(b, c), mid(a, b)],
                                               [c, mid(c, a), mid(b, c)], [mid(a, b), mid(b, c), mid(c, a)])]
    return np.array(verts) * radius, np.array(f, dtype=np.int64)


SHAPES = {"box": box, "ramp": ramp, "funnel": funnel, "box-with-hole": box_with_hole, "paddle": paddle, "icosphere": icosphere}
