"""Where a step's time goes, call by call, measured inside the step; and what renumbering does.

    .venv/bin/python benchmarks/step_parts.py [--scene rain|gas] [--count 1000] [--steps S]
        [--order as-generated|random|morton|columns|landed|inside [--landed-step K]]
    .venv/bin/python benchmarks/step_parts.py --count 100000 --in-turn as-generated,morton,landed

Runs box-rain (``rain``: benchmarks/box_rain.py's scene, 240 steps) or the exact gas
(``gas``: packing 0.3, 200 steps at 1 000, 10 at 32 000 and more) and prints ms/step, each
phase of ``World.step``, and each compiled call the phases make, timed where it runs (a
call costs more there than alone in a loop: the step's other passes leave cold caches
and untrained branches), with the Python between them as the remainder. Also the pauses
of the contact loop for a broad-phase re-query (``REQUERY``) a step, and the Python time
they cost (``World._refresh_box``).

``--order`` renumbers the spheres before the run: as generated, in a random order, or in
Morton (Z-curve) order of their starting places, which puts spheres close in space close
in index (memory locality); ``columns``: Morton order of (x, y),
then height (rain falls nearly straight down, so a column stays a column); ``landed``:
Morton order of where each sphere is after ``--landed-step`` steps (default: nine tenths
of the run), found by a first, untimed run: what an order kept up as the spheres move
would give near that step (box-rain 100k's landing: docs/benchmarks.md, "Space
order"); ``inside``: as generated, numbered by the world itself (``space_order = "morton"``,
which ``auto`` picks from 4 096 spheres up; every other order here runs with
``space_order = "given"``, so the world keeps the order it is given). The contacts have
come out the same in every order measured (box-rain 1k, 10k and 100k, the gas at 32k),
though the held-contact solves sweep in index order, so a pile could differ in its last
bits: the time is the point. The mean index distance of the last
step's candidate pairs shows how local the order is. Whole runs one after another are no
way to compare orders on this machine (the same run has taken 544 and 916 ms/step an
hour apart); ``--in-turn`` steps the orders' worlds in turn in one process and prints each
one's ms/step.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

from physdbg.engine import world as world_module
from physdbg.engine.space_order import interleaved, morton_keys, quantised
from physdbg.engine.state import STATE_FIELDS
from physdbg.engine.timeline import REQUERY
from physdbg.engine.warm import warm_up
from physdbg.api import load_scene

sys.path.insert(0, str(Path(__file__).resolve().parent))  # run as a script or imported as benchmarks.step_parts
from box_rain import box_rain  # noqa: E402

# the compiled calls the step's phases make, by the name world.py imports them under
CALLS = ("settle_held", "swept_boxes", "grow_to_reach", "split_sleeping", "adjacency_from_pairs",
         "narrow_candidates", "predict_into", "run_time_order", "advance_particles", "deepest_overlap",
         "first_non_finite", "energies", "state_hash")
ORDERS = ("as-generated", "random", "morton", "columns", "landed", "inside")


def scene_for(name: str, count: int, steps: int | None):
    """The benchmark scene: box-rain or the exact gas at packing 0.3."""
    if name == "rain":
        return box_rain(count, steps or 240)
    steps = steps or (200 if count < 5000 else 10)
    return load_scene("gas", [f"generate.count={count}", "generate.packing_fraction=0.3", f"steps={steps}"])


def column_keys(points: np.ndarray, bits: int = 10) -> np.ndarray:
    """(N,) keys of points (N, 3) by column: the Z-curve of (x, y) quantised as in
    morton_keys, then the height z as the lowest ``bits`` bits."""
    q = quantised(points, bits)
    return (interleaved(q, 2, bits) << bits) | q[:, 2]


def landing_step(run_steps: int, landed_step: int | None) -> int:
    """The step whose places order the spheres for ``--order landed``: landed_step, or nine
    tenths of the run."""
    return (9 * run_steps) // 10 if landed_step is None else landed_step


def landed_places(scene, steps: int) -> np.ndarray:
    """(N, 3) where each sphere is after ``steps`` steps of the scene (a run of its own,
    untimed; the scene is left as it was)."""
    world = scene.build_world()
    warm_up(world.broad_phase.name, sleeping=world.sleepers is not None)
    for _ in range(steps):
        world.step(scene.dt)
    return world.state.positions.copy()


def renumber(scene, order: str, landed_step: int | None = None) -> None:
    """Permute the scene's particles in place into ``order`` (one of ORDERS), the world
    keeping that numbering (``space_order = "given"``); "inside": as generated, the world
    numbering them itself (``space_order = "morton"``, physdbg/engine/space_order.py);
    landed_step: for "landed", the step whose places give the order (default: nine tenths
    of the run)."""
    scene.settings = dataclasses.replace(scene.settings, space_order="morton" if order == "inside" else "given")
    state = scene.state
    if order in ("as-generated", "inside"):
        return
    if order == "random":
        permutation = np.random.default_rng(0).permutation(state.count)
    elif order == "columns":
        permutation = np.argsort(column_keys(state.positions), kind="stable")
    elif order == "landed":
        places = landed_places(scene, landing_step(scene.steps, landed_step))
        permutation = np.argsort(morton_keys(places), kind="stable")
    else:
        permutation = np.argsort(morton_keys(state.positions), kind="stable")
    for name in STATE_FIELDS:
        setattr(state, name, np.ascontiguousarray(getattr(state, name)[permutation]))


@contextlib.contextmanager
def timed_calls(world, seconds: Counter, counts: Counter):
    """While inside, every compiled call of CALLS that world.py makes, the broad phase's
    ``pairs``, the sleep rules and the re-query's Python are timed into ``seconds`` (by
    name); the loop's returns are counted into ``counts``."""
    def wrap(name, function, count_returns=False):
        def timed(*args, **kwargs):
            started = time.perf_counter()
            result = function(*args, **kwargs)
            seconds[name] += time.perf_counter() - started
            if count_returns:
                counts[result] += 1
            return result
        return timed

    saved = {name: getattr(world_module, name) for name in CALLS}
    try:
        for name, function in saved.items():
            setattr(world_module, name, wrap(name, function, name == "run_time_order"))
        world.broad_phase.pairs = wrap("broad phase pairs", world.broad_phase.pairs)
        if world.sleepers is not None:
            world.sleepers.end_of_step = wrap("sleep rules", world.sleepers.end_of_step)
        world._refresh_box = wrap("re-query (Python)", world._refresh_box)  # (its new pairs' tests: predict_into)
        yield
    finally:
        for name, function in saved.items():
            setattr(world_module, name, function)


def in_turn(name: str, count: int, steps: int | None, orders: list[str], landed_step: int | None = None
            ) -> tuple[int, dict]:
    """The scene in each of ``orders``, stepped in turn in one process: step k of every
    order back to back (the orders' sequence reversed every other step), so that this
    machine's drift (whole runs of the same engine have differed by 30 % within minutes)
    falls on every order alike. Returns the steps run and {order: (seconds stepping,
    contacts, the last step's state hash)}."""
    worlds = {}
    for order in orders:
        scene = scene_for(name, count, steps)
        renumber(scene, order, landed_step)
        worlds[order] = (scene, scene.build_world())
    scene, world = worlds[orders[0]]
    warm_up(world.broad_phase.name, sleeping=world.sleepers is not None)
    spent = dict.fromkeys(orders, 0.0)
    contacts = dict.fromkeys(orders, 0)
    hashes = dict.fromkeys(orders, "")
    for k in range(scene.steps):
        for order in orders if k % 2 == 0 else orders[::-1]:
            scene, world = worlds[order]
            started = time.perf_counter()
            stats = world.step(scene.dt)
            spent[order] += time.perf_counter() - started
            contacts[order] += stats.counts.contacts
            hashes[order] = stats.state_hash
    return scene.steps, {order: (spent[order], contacts[order], hashes[order]) for order in orders}


def measure(scene) -> dict:
    """Step the scene with every call timed: ms/step, phases, calls (s), pauses, contacts."""
    world = scene.build_world()
    warm_up(world.broad_phase.name, sleeping=world.sleepers is not None)
    seconds: Counter = Counter()
    returns: Counter = Counter()
    phases: Counter = Counter()
    contacts = 0
    with timed_calls(world, seconds, returns):
        started = time.perf_counter()
        for _ in range(scene.steps):
            stats = world.step(scene.dt)
            phases.update(stats.timings)
            contacts += stats.counts.contacts
        wall = time.perf_counter() - started
    pairs = world.last_step.pairs
    return {"steps": scene.steps, "wall": wall, "phases": phases, "calls": seconds, "contacts": contacts,
            "requery_pauses": returns[REQUERY],
            "index_distance": float(np.abs(pairs[:, 0] - pairs[:, 1]).mean()) if len(pairs) else 0.0}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scene", choices=("rain", "gas"), default="rain",
                        help="box-rain (benchmarks/box_rain.py's scene) or the exact gas at packing 0.3")
    parser.add_argument("--count", type=int, default=1000, help="spheres (at least 2)")
    parser.add_argument("--steps", type=int, default=None, help="default: 240 (rain), 200 or 10 (gas)")
    parser.add_argument("--order", choices=ORDERS, default="as-generated",
                        help="number the spheres as generated, at random, in Morton order of their places, "
                             "by columns, or in Morton order of their places after --landed-step steps")
    parser.add_argument("--landed-step", type=int, default=None, metavar="K",
                        help="with --order landed: the step whose places order the spheres (default: 9/10 of the run)")
    parser.add_argument("--in-turn", metavar="ORDER,ORDER,...", default=None,
                        help="step the scene in each of these orders in turn in one process and print only "
                             "each order's ms/step (instead of one order's calls)")
    args = parser.parse_args()
    if args.count < 2 or (args.steps is not None and args.steps < 1):
        parser.error("--count must be at least 2 and --steps at least 1")
    turns = args.in_turn.split(",") if args.in_turn else []
    if any(order not in ORDERS for order in turns) or len(set(turns)) != len(turns):
        parser.error(f"--in-turn takes distinct orders among {', '.join(ORDERS)}, separated by commas")
    if args.landed_step is not None and ("landed" not in turns + [args.order] or args.landed_step < 0):
        parser.error("--landed-step goes with --order landed (or landed in --in-turn), and is a step number >= 0")
    if turns:
        steps, results = in_turn(args.scene, args.count, args.steps, turns, args.landed_step)
        print(f"{args.scene} N={args.count}, {steps} steps, the orders stepped in turn in one process:")
        for order, (seconds, contacts, last_hash) in results.items():
            print(f"  {order:13s} {1000 * seconds / steps:9.3f} ms/step, {contacts} contacts, "
                  f"state hash {last_hash[:8]}")
        return
    scene = scene_for(args.scene, args.count, args.steps)
    renumber(scene, args.order, args.landed_step)
    result = measure(scene)
    steps = result["steps"]
    per_step = 1e6 / steps  # seconds over the run -> µs a step
    label = args.order
    if args.order == "landed":
        label += f" (Morton order of step {landing_step(steps, args.landed_step)}'s places)"
    print(f"{args.scene} N={args.count}, {steps} steps, spheres {label}: "
          f"{1000 * result['wall'] / steps:.3f} ms/step, {result['contacts']} contacts")
    print("  phases (ms/step): " + ", ".join(f"{name} {1000 * t / steps:.3f}" for name, t in result["phases"].items()))
    calls = result["calls"]
    for name, t in calls.most_common():
        print(f"  {name:24s} {t * per_step:9.1f} µs/step")
    print(f"  {'Python between them':24s} {(result['wall'] - sum(calls.values())) * per_step:9.1f} µs/step")
    print(f"  loop pauses for a re-query: {result['requery_pauses'] / steps:.3f} a step; mean index distance of the "
          f"last step's candidate pairs: {result['index_distance']:.0f}")


if __name__ == "__main__":
    main()
