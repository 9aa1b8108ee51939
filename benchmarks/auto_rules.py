"""The pile rules left to ``auto`` against the same rules set by hand, on piles.

    .venv/bin/python benchmarks/auto_rules.py [--rounds 3] [--with-exact]

rain with 500 spheres (its 2 s) and box-rain with 10 000 (240 steps of 1/240 s) run with no
rule on the command line (``rapid_contact_rule`` and ``sleep_speed`` default to ``auto``:
the advisor picks the TC rule and sleeping for a pile) and with ``-s rapid_contact_rule=tc
-s sleep_speed=0.1 -s sleep_time=0.1`` typed out, in turn, ``--rounds`` times; the best
ms/step of each and what ``auto`` said. ``--with-exact`` adds the exact rules (``hold``, no
sleeping), what a pile got before ``auto`` (rain 500 alone: minutes).
"""

from __future__ import annotations

import argparse
import time

from physdbg.analysis.engines import box_rain_scene
from physdbg.engine.warm import warm_up
from physdbg.api import load_scene

HAND = ("rapid_contact_rule=tc", "sleep_speed=0.1", "sleep_time=0.1")
EXACT = ("rapid_contact_rule=hold", "sleep_speed=0")


def scenes(with_exact: bool):
    """(label, rules, builder) for each scene and set of rules."""
    sets = [("auto (nothing given)", ()), ("by hand", HAND)] + ([("exact (hold, no sleeping)", EXACT)]
                                                                 if with_exact else [])
    for name, build in (("rain 500", lambda rules: load_scene("rain", ["generate.count=500", *rules])),
                        ("box-rain 10k", lambda rules: box_rain_scene(10000, 240, rules))):
        for label, rules in sets:
            yield name, label, rules, build


def ms_per_step(scene) -> float:
    world = scene.build_world()
    warm_up(world.broad_phase.name, sleeping=world.sleepers is not None)
    started = time.perf_counter()
    for dt in scene.step_lengths():
        world.step(dt)
    return 1000.0 * (time.perf_counter() - started) / scene.steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--with-exact", action="store_true", help="also the exact rules (slow on a pile)")
    args = parser.parse_args()
    best: dict[tuple[str, str], float] = {}
    said: dict[tuple[str, str], str] = {}
    for _ in range(args.rounds):  # in turn, so the machine's drift falls on every set alike
        for name, label, rules, build in scenes(args.with_exact):
            scene = build(rules)
            said[(name, label)] = "; ".join(f"{k}={v.value}" for k, v in scene.auto.items()
                                            if k in ("rapid_contact_rule", "sleep_speed", "sleep_time")) or "—"
            ms = ms_per_step(scene)
            best[(name, label)] = min(best.get((name, label), float("inf")), ms)
    print("\n| scene | rules | auto said | ms/step (best of %d) | against by hand |" % args.rounds)
    print("|---|---|---|---|---|")
    for (name, label), ms in best.items():
        hand = best[(name, "by hand")]
        print(f"| {name} | {label} | {said[(name, label)]} | {ms:.1f} | {ms / hand:.2f}x |")


if __name__ == "__main__":
    main()
