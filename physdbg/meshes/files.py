"""Mesh files (OBJ, STL) read through trimesh, after a streaming pre-scan of physdbg's own.

trimesh parses (OBJ polygons, negative and slashed indices, groups; ASCII and binary STL),
but its errors name no line ("string or file could not be read to its end due to unmatched
data"). So a file is first scanned line by line, which holds one line in memory at a time:
it counts the triangles (the memory budget is checked before anything is loaded) and
names the first line it cannot read, with the problem, and which line each triangle comes
from (a degenerate triangle is reported by its line).
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import MeshError

FORMATS = ("obj", "stl")
OBJ_IGNORED = {"vt", "vn", "vp", "l", "p", "o", "g", "s", "usemtl", "mtllib", "cstype", "deg", "curv", "surf",
               "parm", "end"}


@dataclass
class Scan:
    """What the pre-scan found: counts, and each triangle's line (1-based; 0 for binary STL)."""

    vertices: int = 0
    triangles: int = 0
    lines: list[int] = field(default_factory=list)
    binary: bool = False


def _number(path: Path, line: int, token: str, what: str) -> float:
    try:
        value = float(token)
    except ValueError:
        raise MeshError(f"{path}: line {line}: {what} {token!r} is not a number") from None
    if not np.isfinite(value):
        raise MeshError(f"{path}: line {line}: {what} {token!r} is not finite")
    return value


def _scan_obj(path: Path) -> Scan:
    scan = Scan()
    with open(path, "rb") as handle:
        for number, raw in enumerate(handle, start=1):
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError:
                raise MeshError(f"{path}: line {number}: not text (is this an OBJ file?)") from None
            words = text.split("#", 1)[0].split()
            if not words:
                continue
            key = words[0]
            if key == "v":
                if len(words) not in (4, 5, 7):
                    raise MeshError(f"{path}: line {number}: a vertex takes x y z (and optionally w or r g b), "
                                    f"not {len(words) - 1} numbers")
                for token, axis in zip(words[1:4], "xyz"):
                    _number(path, number, token, f"vertex {axis}")
                scan.vertices += 1
            elif key == "f":
                corners = words[1:]
                if len(corners) < 3:
                    raise MeshError(f"{path}: line {number}: a face needs at least 3 corners, not {len(corners)}")
                for corner in corners:
                    token = corner.split("/", 1)[0]
                    try:
                        index = int(token)
                    except ValueError:
                        raise MeshError(f"{path}: line {number}: face corner {corner!r} does not start with a "
                                        f"vertex number") from None
                    position = index if index > 0 else scan.vertices + index + 1
                    if index == 0 or not 1 <= position <= scan.vertices:
                        raise MeshError(f"{path}: line {number}: face corner {index} names no vertex "
                                        f"({scan.vertices} defined so far)")
                scan.triangles += len(corners) - 2
                scan.lines += [number] * (len(corners) - 2)
            elif key not in OBJ_IGNORED:
                raise MeshError(f"{path}: line {number}: unknown OBJ statement {key!r} (physdbg reads v and f; "
                                f"{', '.join(sorted(OBJ_IGNORED))} are skipped)")
    return scan


def _scan_stl(path: Path) -> Scan:
    size = path.stat().st_size
    with open(path, "rb") as handle:
        head = handle.read(84)
    if len(head) == 84:
        (count,) = struct.unpack("<I", head[80:84])
        if size == 84 + 50 * count:
            return Scan(vertices=3 * count, triangles=count, lines=[0] * count, binary=True)
    if not head.lstrip().lower().startswith(b"solid"):
        raise MeshError(f"{path}: neither a binary STL ({size} bytes, which is not 84 + 50 × its triangle count) "
                        f"nor an ASCII STL (which begins with 'solid')")
    scan = Scan()
    expect = "solid"
    corners = 0
    facet_line = 0
    with open(path, "rb") as handle:
        for number, raw in enumerate(handle, start=1):
            words = raw.decode("utf-8", "replace").split()
            if not words:
                continue
            key = words[0].lower()
            if key == "solid" and expect == "solid":
                expect = "facet"
            elif key == "facet" and expect in ("facet", "endsolid"):
                facet_line = number
                if len(words) != 5 or words[1].lower() != "normal":
                    raise MeshError(f"{path}: line {number}: expected 'facet normal nx ny nz'")
                for token in words[2:]:
                    _number(path, number, token, "normal component")
                expect = "outer"
            elif key == "outer" and expect == "outer":
                expect, corners = "vertex", 0
            elif key == "vertex" and expect == "vertex":
                if len(words) != 4:
                    raise MeshError(f"{path}: line {number}: a vertex takes x y z, not {len(words) - 1} numbers")
                for token, axis in zip(words[1:], "xyz"):
                    _number(path, number, token, f"vertex {axis}")
                corners += 1
                if corners == 3:
                    expect = "endloop"
            elif key == "endloop" and expect == "endloop":
                expect = "endfacet"
            elif key == "endfacet" and expect == "endfacet":
                scan.triangles += 1
                scan.vertices += 3
                scan.lines.append(facet_line)
                expect = "endsolid"
            elif key == "endsolid" and expect in ("endsolid", "facet"):
                expect = "solid"
            else:
                raise MeshError(f"{path}: line {number}: expected {expect!r}, found {words[0]!r}")
    if expect not in ("solid", "endsolid", "facet"):
        raise MeshError(f"{path}: ends inside a facet (expected {expect!r})")
    return scan


def scan(path: Path) -> Scan:
    """Count a mesh file's triangles and name the first line it cannot read (MeshError)."""
    kind = path.suffix.lower().lstrip(".")
    if kind not in FORMATS:
        raise MeshError(f"{path}: a mesh file is .obj or .stl, not {path.suffix or 'a file without a suffix'!r}")
    if not path.is_file():
        raise MeshError(f"{path}: no such file")
    return _scan_obj(path) if kind == "obj" else _scan_stl(path)


def read(path: Path, expected: Scan) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3), faces (F, 3)) of a scanned file, parsed by trimesh, as it is in the
    file (no merging, no reordering: triangle k is the k-th of the scan)."""
    import trimesh  # a mesh file is rare; keep physdbg's start quick

    try:
        loaded = trimesh.load(os.fspath(path), force="mesh", process=False, validate=False)
    except Exception as err:  # noqa: BLE001  (trimesh raises many kinds; the scan passed, so say so)
        raise MeshError(f"{path}: trimesh could not read it ({type(err).__name__}: {err})") from None
    vertices = np.ascontiguousarray(loaded.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(loaded.faces, dtype=np.int64)
    if faces.shape[0] != expected.triangles:
        raise MeshError(f"{path}: trimesh read {faces.shape[0]} triangles where the file has {expected.triangles}")
    return vertices, faces
