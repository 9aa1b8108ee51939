"""The built-in ``rain`` scene as a pile forms: per-step cost, contacts and held-solve work.

    .venv/bin/python benchmarks/rain_pile.py [--count 500] [--steps 240] [--every 15]

``physdbg run rain -s generate.count=500`` (r = 0.03 m, dt = 1/120 s, 2 s) is a pile's
textbook case: 500 frictionless spheres with e = 0.8 rain into a 1 m box and, from
about 1.5 s, form a dense, still-moving pile. Prints every ``--every`` steps (and every
step slower than a second): the step's wall time, contacts resolved, swept tests, held
contacts, the held-contact solve's work (updates, ``world.held.count[2]``), the largest
overlap and any warning — then the whole run's time.
"""

from __future__ import annotations

import argparse
import time

from physdbg.engine.warm import warm_up
from physdbg.api import load_scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=500)
    parser.add_argument("--steps", type=int, default=240)
    parser.add_argument("--every", type=int, default=15)
    args = parser.parse_args()
    scene = load_scene("rain", [f"generate.count={args.count}"])
    world = scene.build_world()
    warm_up(world.broad_phase.name, sleeping=world.sleepers is not None)
    started = time.perf_counter()
    print("step  ms/step  contacts  swept-tests  held  solve-work  overlap(m)  warnings")
    for index, dt in enumerate(scene.step_lengths(None)):
        if index >= args.steps:
            break
        t0 = time.perf_counter()
        stats = world.step(dt)
        seconds = time.perf_counter() - t0
        if (index + 1) % args.every == 0 or seconds > 1.0:
            print(f"{index + 1:4d} {seconds * 1000:8.0f} {stats.counts.contacts:9d} {stats.counts.swept_tests:12d} {stats.counts.held:5d} "
                  f"{int(world.held.count[2]):11d} {stats.max_overlap:11.2g}  "
                  f"{','.join(sorted({w.code for w in stats.warnings})) or '-'}", flush=True)
    print(f"{min(args.steps, scene.steps)} steps in {time.perf_counter() - started:.1f} s")


if __name__ == "__main__":
    main()
