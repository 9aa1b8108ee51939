"""Mesh files (OBJ, STL), read by physdbg's own streaming reader.

One pass over the file, one line in memory at a time: every number is parsed and checked
(finite, within ±MAX_MAGNITUDE m: limits.py), every face corner names a vertex defined
before it, and the first line that cannot be read is named with the problem. What the
reader accepts is what the run uses: there is no second parser to disagree with it (a
library parser refused OBJ files whose fields are separated by tabs, which the format
allows). The memory the mesh will need (its arrays, then its BVH and volumes) is checked
against the budget as the file is read, so a huge file is refused before it is held.

OBJ: ``v x y z [w | r g b]`` and ``f a b c ...`` (a polygon is split into a fan from its
first corner; ``a/b/c`` keeps the vertex; negative numbers count back from the last
vertex); fields separated by any white space; the statements in OBJ_IGNORED are skipped.
STL: binary (84 + 50 bytes a triangle) or ASCII (``solid`` ... ``endsolid``).
"""

from __future__ import annotations

import struct
from array import array
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import MeshError, os_error_words
from ..limits import MAX_MAGNITUDE

FORMATS = ("obj", "stl")
OBJ_IGNORED = {"vt", "vn", "vp", "l", "p", "o", "g", "s", "usemtl", "mtllib", "cstype", "deg", "curv", "surf",
               "parm", "end"}
_COMMAS = " (fields are separated by spaces or tabs, not commas)"
BYTES_PER_VERTEX = 24  # three float64 while the file is read
BYTES_PER_FACE_READ = 32  # three int64 and the line number


@dataclass
class MeshFile:
    """What a mesh file holds: ``vertices`` (V, 3) float64 m, ``faces`` (F, 3) int64 (0-based,
    in file order), ``lines`` (F,): each triangle's line in the file (1-based; for a binary
    STL its triangle number, 1-based), ``binary``: a binary STL."""

    vertices: np.ndarray
    faces: np.ndarray
    lines: list[int]
    binary: bool = False

    @property
    def triangles(self) -> int:
        return int(self.faces.shape[0])


class _Budget:
    """Raises MeshError once what is read would need more than ``max_memory`` bytes with
    ``bytes_per_triangle`` for each triangle's BVH share (checked as the file grows)."""

    def __init__(self, path: Path, max_memory: float, bytes_per_triangle: float):
        self.path, self.max_memory, self.per_triangle = path, max_memory, bytes_per_triangle

    def check(self, vertices: int, triangles: int) -> None:
        need = vertices * BYTES_PER_VERTEX + triangles * (self.per_triangle + BYTES_PER_FACE_READ)
        if need > self.max_memory:
            raise MeshError(f"{self.path}: {triangles:,} triangles and {vertices:,} vertices (and counting) need "
                            f"about {need / 1e9:.2g} GB with their BVH, over the memory budget of "
                            f"{self.max_memory / 1e9:.2g} GB (max_memory): simplify the mesh or raise it")


def _number(path: Path, where: str, token: str, what: str) -> float:
    try:
        value = float(token)
    except ValueError:
        hint = _COMMAS if "," in token else ""
        raise MeshError(f"{path}: {where}: {what} {token!r} is not a number{hint}") from None
    if not np.isfinite(value):
        raise MeshError(f"{path}: {where}: {what} {token!r} is not finite")
    if abs(value) > MAX_MAGNITUDE:
        raise MeshError(f"{path}: {where}: {what} {token!r} is beyond ±{MAX_MAGNITUDE:g} m, the largest coordinate "
                        f"physdbg takes (give the mesh in other units, or scale it in the scene)")
    return value


def _text_lines(path: Path):
    """(line number, words before any '#') of each line of a text file, one line held at a time."""
    with open(path, "rb") as handle:
        for number, raw in enumerate(handle, start=1):
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError:
                raise MeshError(f"{path}: line {number}: not text (is this an {path.suffix.lstrip('.').upper()} "
                                f"file?)") from None
            yield number, text.split("#", 1)[0].split()


def _read_obj(path: Path, budget: _Budget) -> MeshFile:
    coordinates, faces, lines = array("d"), array("q"), []
    vertices = 0
    for number, words in _text_lines(path):
        if not words:
            continue
        key, where = words[0], f"line {number}"
        if key == "v":
            if len(words) not in (4, 5, 7):
                raise MeshError(f"{path}: {where}: a vertex takes x y z (and optionally w or r g b), "
                                f"not {len(words) - 1} numbers{_COMMAS if ',' in ''.join(words) else ''}")
            coordinates.extend(_number(path, where, token, f"vertex {axis}") for token, axis in
                               zip(words[1:4], "xyz"))
            vertices += 1
        elif key == "f":
            corners = words[1:]
            if len(corners) < 3:
                raise MeshError(f"{path}: {where}: a face needs at least 3 corners, not {len(corners)}")
            numbers = []
            for corner in corners:
                token = corner.split("/", 1)[0]
                try:
                    index = int(token)
                except ValueError:
                    raise MeshError(f"{path}: {where}: face corner {corner!r} does not start with a "
                                    f"vertex number") from None
                position = index if index > 0 else vertices + index + 1
                if index == 0 or not 1 <= position <= vertices:
                    counted = " (OBJ counts vertices from 1)" if index == 0 else ""
                    raise MeshError(f"{path}: {where}: face corner {index} names no vertex "
                                    f"({vertices} defined so far){counted}")
                numbers.append(position - 1)
            for k in range(1, len(numbers) - 1):  # a fan from the first corner
                faces.extend((numbers[0], numbers[k], numbers[k + 1]))
                lines.append(number)
        elif key not in OBJ_IGNORED:
            raise MeshError(f"{path}: {where}: unknown OBJ statement {key!r} (physdbg reads v and f; "
                            f"{', '.join(sorted(OBJ_IGNORED))} are skipped)")
        if number % 1024 == 0:
            budget.check(vertices, len(lines))
    budget.check(vertices, len(lines))
    return MeshFile(np.frombuffer(coordinates, dtype=np.float64).reshape(-1, 3).copy(),
                    np.frombuffer(faces, dtype=np.int64).reshape(-1, 3).copy(), lines)


_BINARY_TRIANGLE = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])


def _read_binary_stl(path: Path, count: int, budget: _Budget) -> MeshFile:
    budget.check(3 * count, count)  # the size is known before a triangle is read
    rows = np.fromfile(path, dtype=_BINARY_TRIANGLE, count=count, offset=84)
    corners = rows["corners"].astype(np.float64)  # (F, 3, 3)
    finite = np.isfinite(corners).all(axis=(1, 2))
    if not finite.all():
        k = int(np.argmin(finite))
        raise MeshError(f"{path}: triangle {k + 1} (of {count:,}): a corner is not finite "
                        f"({corners[k].tolist()})")
    inside = (np.abs(corners) <= MAX_MAGNITUDE).all(axis=(1, 2))
    if not inside.all():
        k = int(np.argmin(inside))
        raise MeshError(f"{path}: triangle {k + 1} (of {count:,}): a corner is beyond ±{MAX_MAGNITUDE:g} m, the "
                        f"largest coordinate physdbg takes ({corners[k].tolist()})")
    return MeshFile(corners.reshape(-1, 3), np.arange(3 * count, dtype=np.int64).reshape(-1, 3),
                    list(range(1, count + 1)), binary=True)


def _read_ascii_stl(path: Path, budget: _Budget) -> MeshFile:
    coordinates, lines = array("d"), []
    expect = "solid"
    corners = 0
    facet_line = 0
    for number, words in _text_lines(path):
        if not words:
            continue
        key, where = words[0].lower(), f"line {number}"
        if key == "solid" and expect == "solid":
            expect = "facet"
        elif key == "facet" and expect in ("facet", "endsolid"):
            facet_line = number
            if len(words) != 5 or words[1].lower() != "normal":
                raise MeshError(f"{path}: {where}: expected 'facet normal nx ny nz'")
            for token in words[2:]:
                _number(path, where, token, "normal component")
            expect = "outer"
        elif key == "outer" and expect == "outer":
            expect, corners = "vertex", 0
        elif key == "vertex" and expect == "vertex":
            if len(words) != 4:
                raise MeshError(f"{path}: {where}: a vertex takes x y z, not {len(words) - 1} numbers")
            coordinates.extend(_number(path, where, token, f"vertex {axis}") for token, axis in zip(words[1:], "xyz"))
            corners += 1
            if corners == 3:
                expect = "endloop"
        elif key == "endloop" and expect == "endloop":
            expect = "endfacet"
        elif key == "endfacet" and expect == "endfacet":
            lines.append(facet_line)
            expect = "endsolid"
            if len(lines) % 1024 == 0:
                budget.check(3 * len(lines), len(lines))
        elif key == "endsolid" and expect in ("endsolid", "facet"):
            expect = "solid"
        else:
            raise MeshError(f"{path}: {where}: expected {expect!r}, found {words[0]!r}")
    if expect not in ("solid", "endsolid", "facet"):
        raise MeshError(f"{path}: ends inside a facet (expected {expect!r})")
    budget.check(3 * len(lines), len(lines))
    count = len(lines)
    return MeshFile(np.frombuffer(coordinates, dtype=np.float64)[: 9 * count].reshape(-1, 3).copy(),
                    np.arange(3 * count, dtype=np.int64).reshape(-1, 3), lines)


def _read_stl(path: Path, budget: _Budget) -> MeshFile:
    size = path.stat().st_size
    with open(path, "rb") as handle:
        head = handle.read(84)
    if len(head) == 84:
        (count,) = struct.unpack("<I", head[80:84])
        if size == 84 + 50 * count:
            return _read_binary_stl(path, count, budget)
    if not head.lstrip().lower().startswith(b"solid"):
        raise MeshError(f"{path}: neither a binary STL ({size} bytes, which is not 84 + 50 × its triangle count) "
                        f"nor an ASCII STL (which begins with 'solid')")
    return _read_ascii_stl(path, budget)


def read(path: Path, max_memory: float, bytes_per_triangle: float) -> MeshFile:
    """Read a mesh file (.obj or .stl): MeshError naming the file, and the line (OBJ, ASCII
    STL) or triangle (binary STL), for anything it cannot take; refused as soon as the mesh
    would need more than ``max_memory`` bytes (``bytes_per_triangle`` for each triangle's
    BVH and volumes)."""
    kind = path.suffix.lower().lstrip(".")
    if kind not in FORMATS:
        raise MeshError(f"{path}: a mesh file is .obj or .stl, not {path.suffix or 'a file without a suffix'!r}")
    try:
        if not path.exists():
            raise MeshError(f"{path}: no such file")
        if not path.is_file():  # a FIFO would block the read, a device never end
            raise MeshError(f"{path}: not a regular file (a mesh is an .obj or .stl file)")
        budget = _Budget(path, max_memory, bytes_per_triangle)
        return _read_obj(path, budget) if kind == "obj" else _read_stl(path, budget)
    except OSError as err:  # a name the system refuses (too long), a folder without read access, ...
        raise MeshError(os_error_words(err) or f"{path}: cannot read it ({err})") from None
