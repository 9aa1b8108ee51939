"""Meshes as a scene or a command names them: a file (OBJ, STL) or a built-in shape, checked,
with degenerate triangles reported and skipped, and its convex hull from qhull.

``load_mesh("part.obj")`` or ``load_mesh("funnel")`` gives a ``Mesh``; ``mesh_tree(mesh)``
its BVH with every bounding volume (``physdbg.engine.mesh``). The engine never reads a file:
this layer hands it arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..engine.mesh import MeshTree, build_mesh_tree
from ..errors import MeshError
from ..limits import MIN_AREA
from . import files
from .shapes import SHAPES

# a triangle with its share of the BVH and its volumes, at the peak of building them: 1.36 kB
# (tracemalloc around convex_hull and mesh_tree, an icosphere of 81,920 triangles)
BYTES_PER_TRIANGLE = 1400
DEFAULT_MAX_MEMORY = 4e9   # bytes, as the engine's default budget
DEGENERATE_AREA = 1e-14    # a triangle whose area is below this times the mesh's size² is degenerate


@dataclass
class Mesh:
    """A checked triangle mesh: ``vertices`` (V, 3) m and ``faces`` (F, 3) in its own frame.

    ``source``: the file or "shape NAME"; ``skipped``: degenerate triangles left out, each
    (its line in the file, or its number in the shape, and why); ``hull``: the convex
    hull's (normals (H, 3), offsets (H,), corners (K, 3)) or None for a flat mesh.
    """

    name: str
    source: str
    vertices: np.ndarray
    faces: np.ndarray
    skipped: list[tuple[int, str]] = field(default_factory=list)
    hull: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    numbered_by: str = "line"  # what a skipped triangle's number is: its "line" or its "triangle" number

    @property
    def triangles(self) -> int:
        return int(self.faces.shape[0])

    def skipped_words(self) -> str:
        """The skipped triangles in a sentence ("" when none)."""
        if not self.skipped:
            return ""
        shown = ", ".join(f"{self.numbered_by} {at} ({why})" for at, why in self.skipped[:5])
        more = f" and {len(self.skipped) - 5} more" if len(self.skipped) > 5 else ""
        return f"{self.source}: skipped {len(self.skipped)} degenerate triangle(s): {shown}{more}"


def _check_memory(source: str, triangles: int, max_memory: float) -> None:
    need = triangles * BYTES_PER_TRIANGLE
    if need > max_memory:
        raise MeshError(f"{source}: {triangles:,} triangles need about {need / 1e9:.2g} GB with their BVH, over the "
                        f"memory budget of {max_memory / 1e9:.2g} GB (max_memory): simplify the mesh or raise it")


def degenerate(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """(F,) bool: which triangles are degenerate, and why, in the order found: a corner
    repeated, an area below DEGENERATE_AREA of the mesh's size squared, or below
    limits.MIN_AREA (1e-24 m²: too small for a normal, whatever the mesh's size).
    vertices (V, 3) m, coordinates within limits.MAX_MAGNITUDE (so no square overflows)."""
    corners = vertices[faces]
    size = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 0.0
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    flat = (area <= DEGENERATE_AREA * size * size) | (area < MIN_AREA)
    why = ["a corner repeated" if r else "zero area" if a == 0 else f"area {a:.3g} m²"
           for r, a in zip(repeated[repeated | flat], area[repeated | flat])]
    return repeated | flat, why


def convex_hull(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The convex hull by qhull (scipy.spatial.ConvexHull): (normals (H, 3), offsets (H,),
    corners (K, 3)) with n·x ≤ offset inside; None for a flat (or lower-dimensional) mesh."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(vertices)
    except QhullError:
        return None
    return (np.ascontiguousarray(hull.equations[:, :3]), np.ascontiguousarray(-hull.equations[:, 3]),
            np.ascontiguousarray(vertices[hull.vertices]))


def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except OSError:  # a name the system refuses: the reader says so
        return True


def load_mesh(spec: str | Path, name: str | None = None, max_memory: float = DEFAULT_MAX_MEMORY,
              hull: bool = True) -> Mesh:
    """A mesh from a file path (.obj, .stl) or a built-in shape name (``SHAPES``): checked,
    degenerate triangles skipped (and listed), its hull computed unless ``hull`` is False.
    Bad input is a MeshError naming the file, the line and the problem."""
    text = str(spec)
    if text in SHAPES and not Path(text).exists():
        vertices, faces = SHAPES[text]()
        source, lines, numbered_by = f"shape {text}", list(range(len(faces))), "triangle"
        _check_memory(source, len(faces), max_memory)
    else:
        path = Path(text)
        if path.suffix.lower().lstrip(".") not in files.FORMATS and not _exists(path):
            raise MeshError(f"{text}: neither a mesh file (.obj, .stl) nor a built-in shape "
                            f"({', '.join(SHAPES)})")
        read = files.read(path, max_memory, BYTES_PER_TRIANGLE)
        if read.triangles == 0:
            raise MeshError(f"{path}: holds no triangles")
        vertices, faces = read.vertices, read.faces
        source, lines, numbered_by = str(path), read.lines, "triangle" if read.binary else "line"
    bad, why = degenerate(vertices, faces)
    skipped = [(lines[k], reason) for k, reason in zip(np.nonzero(bad)[0].tolist(), why)]
    faces = np.ascontiguousarray(faces[~bad])
    if len(faces) == 0:
        raise MeshError(f"{source}: every triangle is degenerate ({len(skipped)} skipped)")
    mesh = Mesh(name or Path(text).stem, source, vertices, faces, skipped, numbered_by=numbered_by)
    if hull:
        mesh.hull = convex_hull(vertices[np.unique(faces)])
    return mesh


def mesh_tree(mesh: Mesh, builder: str = "sah") -> MeshTree:
    """The mesh's BVH (``builder``: median, mean, sah or lbvh) with every volume and its hull."""
    return build_mesh_tree(mesh.vertices, mesh.faces, builder, mesh.hull)


__all__ = ["SHAPES", "Mesh", "convex_hull", "load_mesh", "mesh_tree"]
