"""The exact gas: pair collisions per second of the time-ordered loop (docs/benchmarks.md's gas targets).

    .venv/bin/python benchmarks/gas.py [--count 1000] [--steps 200] [--packing 0.3] [--dt 0.01]
        [--periodic] [--event-loop step|calendar]

The built-in ``gas`` scene (e = 1, exact integrator, swept detection) with ``count``
spheres at the packing fraction; the kernels are loaded (or compiled) first and not
timed. Prints pair and wall contacts, swept tests, seconds and the rates: pair
collisions per second is what event-driven codes report (Smallenburg's EDMD: 6.6·10⁵
per CPU-second); the targets are 5·10⁵ at N = 1 000 and 3·10⁵ at N = 32 000. Last, the
milliseconds a step spends in each phase of ``World.step``: an event-driven code has no
steps, so what the once-a-step phases cost is what physdbg pays for its steps; ``--dt``
(with ``--steps`` for the same simulated time) shows how that cost trades against the
longer steps' larger swept boxes (more candidate pairs a contact). ``--periodic``: the
gas in a periodic box (the scene of benchmarks/edmd.py); ``--event-loop calendar``: the
event calendar that keeps predictions across steps (docs/space-order.md, "The event calendar").
"""

from __future__ import annotations

import argparse
import time

from physdbg.engine.warm import warm_up
from physdbg.events import KIND_PAIR
from physdbg.api import load_scene


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--packing", type=float, default=0.3)
    parser.add_argument("--dt", type=float, default=None, help="step length, s (default: the scene's, 0.01)")
    parser.add_argument("--periodic", action="store_true", help="a periodic box instead of walls")
    parser.add_argument("--event-loop", choices=("step", "calendar"), default="step")
    args = parser.parse_args()
    if args.dt is not None and not 0.0 < args.dt < float("inf"):
        parser.error(f"--dt must be a positive number of seconds, got {args.dt}")
    scene = load_scene("gas", [f"generate.count={args.count}", f"generate.packing_fraction={args.packing}",
                               f"steps={args.steps}", f"event_loop={args.event_loop}",
                               f"box.periodic={str(args.periodic).lower()}"]
                       + ([f"dt={args.dt}"] if args.dt is not None else []))
    world = scene.build_world()
    warm_up(world.broad_phase.name, calendar=world.settings.event_loop == "calendar")
    pairs = walls = tests = 0
    phases: dict[str, float] = {}
    started = time.perf_counter()
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
        for phase, seconds in stats.timings.items():
            phases[phase] = phases.get(phase, 0.0) + seconds
        # this step's contact rows (the Contacts event's payload, read without observing)
        kinds = world._buf.contacts["kind"][:stats.counts.contacts]
        pairs += int((kinds == KIND_PAIR).sum())
        walls += stats.counts.contacts - int((kinds == KIND_PAIR).sum())
        tests += stats.counts.swept_tests
    seconds = time.perf_counter() - started
    box = "periodic box" if args.periodic else "walls"
    print(f"gas N={args.count}, packing {args.packing}, {box}, event_loop = {args.event_loop}, {scene.steps} steps of "
          f"{scene.dt:g} s: {seconds:.2f} s")
    print(f"  pair collisions {pairs} ({pairs / seconds:.3g}/s), wall contacts {walls}, "
          f"all contacts {(pairs + walls) / seconds:.3g}/s, swept tests {tests} ({tests / max(pairs + walls, 1):.1f} per contact)")
    # where a step goes: the once-a-step phases against the contact loop (resolve)
    total = sum(phases.values()) or 1.0
    print("  ms/step by phase: " + ", ".join(f"{phase} {1000 * t / scene.steps:.3f} ({t / total:.0%})"
                                             for phase, t in phases.items()))


if __name__ == "__main__":
    main()
