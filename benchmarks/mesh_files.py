"""physdbg's mesh file reader timed beside trimesh's OBJ loader, on one generated file.

    .venv/bin/pip install trimesh && .venv/bin/python benchmarks/mesh_files.py [--n 300]

Writes an OBJ height field of 2·n² triangles to a temporary folder, reads it with
``physdbg.meshes.files.read`` (which also checks every number and the memory budget) and
with ``trimesh.load`` (its import timed apart), and checks that both give the same
vertices and faces, number for number.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def write_plate(path: Path, n: int) -> None:
    xs = np.linspace(-1.0, 1.0, n + 1)
    with open(path, "w") as f:
        for x in xs:
            for z in xs:
                f.write(f"v {float(x)!r} {float(np.sin(x * z))!r} {float(z)!r}\n")
        for i in range(n):
            for j in range(n):
                a = i * (n + 1) + j + 1
                f.write(f"f {a} {a + 1} {a + n + 2}\nf {a} {a + n + 2} {a + n + 1}\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=300, help="the plate is n × n squares (2·n² triangles)")
    args = parser.parse_args()
    from physdbg.meshes import BYTES_PER_TRIANGLE, files

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "plate.obj"
        write_plate(path, args.n)
        started = time.perf_counter()
        mine = files.read(path, 4e9, BYTES_PER_TRIANGLE)
        physdbg_s = time.perf_counter() - started
        started = time.perf_counter()
        import trimesh

        import_s = time.perf_counter() - started
        started = time.perf_counter()
        theirs = trimesh.load(str(path), force="mesh", process=False, validate=False)
        trimesh_s = time.perf_counter() - started
    same = np.array_equal(mine.vertices, theirs.vertices) and np.array_equal(mine.faces, theirs.faces)
    print(f"{mine.triangles:,} triangles: physdbg {physdbg_s:.2f} s; trimesh {trimesh_s:.2f} s (+ {import_s:.2f} s "
          f"to import it); the same arrays: {same}")


if __name__ == "__main__":
    main()
