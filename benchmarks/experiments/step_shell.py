"""Neighbour lists with a shell kept across the engine's steps, without the rest of the
event-driven design: how often they would be made again, and how many pairs they hold.

    .venv/bin/python benchmarks/experiments/step_shell.py [--scene gas|box-rain] [--count N]
        [--steps S] [--skins 0.1 0.25 0.5]

Each step, the engine's broad phase pairs the boxes each sphere could reach in that step
(its path over the step grown to the reach of a contact: World._add_reach). A list kept
across steps would pair boxes grown by a skin on every side, and be made again once any
sphere's box of a later step leaves the box it was listed with (Verlet's rule, the whole
list at once). This script runs the engine, reads each step's boxes and pairs
(``world.last_step``), and counts, for each skin (in σ, on each side), how often the list
is made again and its pairs against the step's own.

What it measured is in docs/benchmarks.md, "Measured and not kept": the reach boxes move
with the spheres, so a skin thin enough to keep the pairs few is left within a step or
two, and one thick enough to last holds several times the pairs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

if str(Path(__file__).resolve().parents[2]) not in sys.path:  # run as a script: benchmarks/ importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def scene_of(name: str, count: int, steps: int):
    """The exact gas of benchmarks/gas.py (packing 0.3, walls), or box-rain."""
    if name == "gas":
        from physdbg.api import load_scene

        return load_scene("gas", [f"generate.count={count}", "generate.packing_fraction=0.3", f"steps={steps}"])
    from physdbg.analysis.engines import box_rain_scene

    return box_rain_scene(count, steps)


def measure(scene, skins: list[float]) -> dict:
    """Run ``scene`` and count, per skin (σ each side), the lists made and the pairs held:
    {"pairs": mean pairs a step of the broad phase, skin: (steps a list lasts, mean pairs a
    step of the list)}."""
    world = scene.build_world()
    sigma = 2.0 * float(world.state.radius.max())
    lists = {skin: None for skin in skins}
    made = dict.fromkeys(skins, 0)
    held = dict.fromkeys(skins, 0)
    step_pairs = 0
    for _ in range(scene.steps):
        world.step(scene.dt)
        ctx = world.last_step
        step_pairs += len(ctx.pairs)
        for skin in skins:
            listed = lists[skin]
            if listed is None or (ctx.lo < listed[0]).any() or (ctx.hi > listed[1]).any():
                lo, hi = ctx.lo - skin * sigma, ctx.hi + skin * sigma
                listed = lists[skin] = (lo, hi, len(world.broad_phase.pairs(lo, hi)))
                made[skin] += 1
            held[skin] += listed[2]
    steps = scene.steps
    return {"pairs": step_pairs / steps, **{skin: (steps / made[skin], held[skin] / steps) for skin in skins}}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", choices=("gas", "box-rain"), default="gas")
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--skins", type=float, nargs="+", default=[0.1, 0.25, 0.5], metavar="SIGMA")
    args = parser.parse_args(argv)
    if args.count < 2 or args.steps < 1 or any(not np.isfinite(s) or s <= 0 for s in args.skins):
        parser.error("--count >= 2, --steps >= 1 and every skin a positive number")
    from physdbg.engine.warm import warm_up

    warm_up()
    found = measure(scene_of(args.scene, args.count, args.steps), args.skins)
    print(f"{args.scene} N={args.count}, {args.steps} steps: the step's broad phase pairs {found['pairs']:.0f} a step")
    for skin in args.skins:
        lasts, pairs = found[skin]
        print(f"  skin {skin:g} σ each side: a list lasts {lasts:.2f} steps, holds {pairs:.0f} pairs "
              f"({pairs / found['pairs']:.2f}× the step's)")


if __name__ == "__main__":
    main()
