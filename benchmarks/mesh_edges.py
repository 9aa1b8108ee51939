"""Mesh scenes at the edges: a discrete run among mesh walls, a soup of triangles, check at 100k.

    .venv/bin/python benchmarks/mesh_edges.py [--quick]

Each case runs as a user runs it, ``physdbg run`` (or ``check``) in its own process, one
after another in this one run, and prints the engine's ms/step from the run summary, the
wall time and the process's own peak resident memory (``ru_maxrss`` of that child, os.wait4):

* ``highspeed`` swept and with ``-s detection=discrete`` (the whole 10 s; ``--quick``: 1 s):
  the discrete run among mesh walls should cost about what the swept one does;
* a soup: 7,191 random triangles, corners uniform in a 2 m cube (``soup.obj``, seeded),
  with 8 spheres of r = 0.3 m starting inside it (each overlapping hundreds of triangles)
  and the same 8 dropped into it from above, 3 steps of 1/60 s and 30 steps;
* ``check`` and 3 steps of ``run`` of a 100,000-sphere rain (r = 4 mm).
"""

from __future__ import annotations

import argparse
import os
import random
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SOUP_TRIANGLES = 7191


def write_soup(folder: Path) -> dict[str, Path]:
    """soup.obj (seeded random triangles) and its two scenes: spheres inside, spheres above."""
    rng = random.Random(1)
    corners = [f"v {rng.uniform(-1, 1):f} {rng.uniform(-1, 1):f} {rng.uniform(-1, 1):f}"
               for _ in range(3 * SOUP_TRIANGLES)]
    faces = [f"f {3 * t + 1} {3 * t + 2} {3 * t + 3}" for t in range(SOUP_TRIANGLES)]
    (folder / "soup.obj").write_text("\n".join(corners + faces) + "\n")
    head = 'dt = "1/60"\ngravity = [0.0, -9.81, 0.0]\n[[meshes]]\nname = "soup"\nfile = "soup.obj"\n'
    scenes = {}
    for name, place in (("inside", lambda i, r: [r.uniform(-0.8, 0.8), r.uniform(-0.8, 0.8), r.uniform(-0.8, 0.8)]),
                        ("above", lambda i, r: [r.uniform(-0.8, 0.8), 1.5 + 0.7 * i, r.uniform(-0.8, 0.8)])):
        r = random.Random(2)
        body = "".join(f"[[particles]]\nposition = {place(i, r)!r}\nradius = 0.3\n"
                       f"velocity = [0.0, {0.0 if name == 'inside' else -5.0}, 0.0]\n" for i in range(8))
        path = folder / f"soup-{name}.toml"
        path.write_text(f'name = "soup-{name}"\n' + head + body)
        scenes[name] = path
    return scenes


def measure(args: list[str]) -> tuple[str, float, float]:
    """(the engine's ms/step from the summary or "", wall s, the child's own peak RSS MB)."""
    with tempfile.TemporaryFile("w+") as out:
        start = time.perf_counter()
        child = subprocess.Popen([sys.executable, "-m", "physdbg", *args], stdout=out, stderr=subprocess.STDOUT,
                                 text=True)
        _pid, status, usage = os.wait4(child.pid, 0)  # this child's own rusage
        child.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - start
        out.seek(0)
        text = out.read()
    found = re.search(r"^speed\s+([\d.]+) ms/step in the engine", text, re.M)
    if child.returncode not in (0, 1):
        print(text[-2000:])
    return (found.group(1) if found else ""), wall, usage.ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="highspeed for 1 s instead of 10")
    quick = parser.parse_args().quick
    cases = [("highspeed, swept", ["run", "highspeed"] + (["-s", "duration=1"] if quick else [])),
             ("highspeed, discrete", ["run", "highspeed", "-s", "detection=discrete"]
              + (["-s", "duration=1"] if quick else []))]
    with tempfile.TemporaryDirectory() as folder:
        soup = write_soup(Path(folder))
        for name in ("inside", "above"):
            for steps in (3, 30):
                cases.append((f"soup, spheres {name}, {steps} steps", ["run", str(soup[name]), "-s", f"steps={steps}"]))
        rain = ["rain", "-s", "generate.count=100000", "-s", "generate.radius=0.004"]
        cases += [("rain 100k, check", ["check", *rain]), ("rain 100k, run 3 steps", ["run", *rain, "-s", "steps=3"])]
        print(f"{'case':34} {'engine ms/step':>15} {'wall s':>8} {'peak MB':>8}")
        for label, args in cases:
            ms, wall, peak = measure(args)
            print(f"{label:34} {ms:>15} {wall:8.1f} {peak:8.0f}", flush=True)


if __name__ == "__main__":
    main()
