"""The crease: the `ramp` scene (two mesh ramps meeting in a V) beside the same V made of two
`[[planes]]`, counted step by step.

    .venv/bin/python benchmarks/crease.py [-s KEY=VALUE ...]

Sleeping is off (`sleep_speed=0`, extra overrides after it) so that the balls' contacts
in the valley are counted to the end: contacts, held contacts released, and both in the
run's second half, when the balls lie in the valley. The planes' V has the ramps' slopes
(y = |x| / 4), box, balls, drag and restitution.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

PLANES_V = """name = "ramp-as-planes"
dt = "1/240"
duration = 8.0
integrator = "exact"
detection = "swept"
ordering = "time"
gravity = [0.0, -9.81, 0.0]
drag = 0.5
[[planes]]
name = "left"
normal = [0.25, 1.0, 0.0]
offset = 0.0
restitution = 0.5
[[planes]]
name = "right"
normal = [-0.25, 1.0, 0.0]
offset = 0.0
restitution = 0.5
[box]
min = [-2.0, 0.0, -0.5]
max = [2.0, 3.0, 0.5]
restitution = 0.5
""" + "".join(f"[[particles]]\nposition = {p}\nradius = 0.1\nrestitution = 0.5\n"
              for p in ("[-1.5, 1.0, 0.0]", "[1.2, 1.2, 0.1]", "[0.6, 1.5, -0.2]"))


def counted(spec: str, overrides: list[str]) -> str:
    from physdbg.api import load_scene

    scene = load_scene(spec, overrides)
    world = scene.build_world()
    rows = np.array([(end.counts.contacts, end.counts.released, end.counts.held)
                     for end in (world.step(dt) for dt in scene.step_lengths())])
    late = rows[len(rows) // 2:]
    return (f"{scene.name:16s} contacts {rows[:, 0].sum():6d} (second half {late[:, 0].sum():6d}, "
            f"{late[:, 0].mean():5.1f} a step, at most {late[:, 0].max()}), released {rows[:, 1].sum():6d} "
            f"(second half {late[:, 1].sum():6d}), held at the end {rows[-1, 2]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-s", "--set", action="append", default=[], help="an override for both scenes")
    args = parser.parse_args()
    overrides = ["sleep_speed=0", *args.set]
    with tempfile.TemporaryDirectory() as folder:
        planes = Path(folder) / "ramp-as-planes.toml"
        planes.write_text(PLANES_V)
        print(counted("ramp", overrides))
        print(counted(str(planes), overrides))


if __name__ == "__main__":
    main()
