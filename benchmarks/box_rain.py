"""box-rain: N spheres (r = 0.05 m, 10 % of the box's volume, e = 0.8) rain into a box.

    .venv/bin/python benchmarks/box_rain.py [--count 1000] [--steps 240] [--peers [--rounds R] [--with-run]] [--trace]
        [--stop-above-gb G] [--set KEY=VALUE ...] [--checkpoint FILE [--checkpoint-every K]] [--resume FILE]

The built-in ``rain`` scene with the box grown so the spheres fill 10 % of it, dt = 1/240 s;
its pile rules are left to ``auto``, which picks the TC rule and sleeping at 0.1 m/s after
0.1 s for a pile (docs/sleeping.md); ``--set rapid_contact_rule=hold --set
sleep_speed=0`` runs the exact rules instead.
Prints, for the run: steps stopped by a budget (the event cap or the held-contact
solve's), the largest overlap after any step, contacts, held contacts and sleeping spheres
per step at the start, middle and end, rapid-contact rule counts and held contacts
released (a pile's churn), and ms/step (the first step, which compiles nothing but builds the broad
phase, is counted). With --peers, pybullet and MuJoCo, set up by physdbg/peers.py for the
same physics (frictionless, the same restitution, no damping), step the same initial state
the same number of steps, when importable, and the ratios are printed from this one run
(these machines are noisy: compare ratios, not absolute times). With --rounds R
the three engines run again, one after another, R times in all, and each ratio is
printed for every round with its median and range: on this machine one round's ratio at
1k has ranged over a factor of two with no change to any engine.

A run longer than one sitting (box-rain 100k to rest: hours) can be carried on: with
``--checkpoint FILE`` the world and the run's tallies are pickled to FILE every K steps
(default 20; written to a temporary file, then renamed, so a killed run leaves the last
whole one), and ``--resume FILE`` (with the same --count and --set) carries on from it.
A resumed run is the same run, bit for bit (the world holds all its state;
``tests/test_benchmarks.py`` checks it): the trace's last column, the state hash, shows it.
Its time is summed over the sittings; its peak memory is the larger of theirs.
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import time

import numpy as np

from physdbg.engine.timeline import Buffers
from physdbg.analysis.engines import box_rain_scene
from physdbg.analysis.report import decision_words
from physdbg.engine.warm import warm_up
from physdbg.errors import SceneError
from physdbg.peers import PeerSetup, available, build
from physdbg.api import load_scene


def box_rain(count: int, steps: int, overrides: tuple[str, ...] = ()):
    """The scene (physdbg.analysis.engines.box_rain_scene: one definition for every
    benchmark); overrides: more KEY=VALUE settings, as `physdbg run -s` takes them."""
    return box_rain_scene(count, steps, overrides)


def peak_memory_mb() -> float:
    """This process's peak resident memory so far (MB; Linux reports ru_maxrss in kB)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_physdbg(scene, trace: bool = False, stop_above_gb: float | None = None, checkpoint: str | None = None,
                every: int = 20, resumed: dict | None = None, key: tuple = ()) -> dict:
    """Step the scene; trace: print every step (ms, contacts, held, rapid, released, events,
    swept tests, overlap, kinetic energy, spheres asleep / fallen asleep / woken, warnings,
    peak memory, the state hash's first 16 hex digits); stop_above_gb: stop early once the
    peak memory passes it; checkpoint: pickle the run to this file every ``every`` steps
    and at its end; resumed: a run loaded by load_checkpoint, carried on; key: what a
    checkpoint must match to be resumed (the count and settings)."""
    run = resumed or {"world": scene.build_world(), "capped": 0, "worst_overlap": 0.0, "rows": [],
                      "seconds": 0.0, "peak_mb": 0.0, "key": key}
    world = run["world"]
    if trace:
        print("step  ms  contacts  held  rapid  released  events  swept-tests  overlap(m)  kinetic(J)  asleep  "
              "slept  woken  warnings  peak-MB  hash", flush=True)
    started = time.perf_counter() - run["seconds"]
    for k in range(world.step_index, scene.steps):
        t0 = time.perf_counter()
        stats = world.step(scene.dt)
        run["capped"] += any(w.code.startswith("max_") for w in stats.warnings)
        run["worst_overlap"] = max(run["worst_overlap"], stats.max_overlap)
        run["rows"].append((stats.counts.contacts, stats.counts.held, stats.counts.rapid, stats.counts.released, stats.counts.events, stats.counts.asleep))
        if trace:
            print(f"{k + 1} {1000 * (time.perf_counter() - t0):.0f} {stats.counts.contacts} {stats.counts.held} {stats.counts.rapid} "
                  f"{stats.counts.released} {stats.counts.events} {stats.counts.swept_tests} {stats.max_overlap:.2g} {stats.kinetic:.4g} "
                  f"{stats.counts.asleep} {stats.counts.slept} {stats.counts.woken} {[w.code for w in stats.warnings]} "
                  f"{peak_memory_mb():.0f} {stats.state_hash[:16]}", flush=True)
        stopping = stop_above_gb is not None and peak_memory_mb() > 1024.0 * stop_above_gb
        if checkpoint and ((k + 1) % every == 0 or k + 1 == scene.steps or stopping):
            run["seconds"] = time.perf_counter() - started
            run["peak_mb"] = max(run["peak_mb"], peak_memory_mb())
            save_checkpoint(checkpoint, run)
        if stopping:
            print(f"stopped after step {k + 1}: peak memory {peak_memory_mb():.0f} MB > {stop_above_gb:g} GB")
            break
    run["seconds"] = time.perf_counter() - started
    run["peak_mb"] = max(run["peak_mb"], peak_memory_mb())
    return {**{name: run[name] for name in ("seconds", "capped", "worst_overlap", "rows", "peak_mb")},
            "steps": len(run["rows"]), "tolerance": scene.settings.contact_tolerance}


def save_checkpoint(path: str, run: dict) -> None:
    """Pickle the run (its world and tallies) to path, whole or not at all.

    The world's step scratch is left out: its loop buffers (grown to hundreds of MB in a
    dense bed) are pickled fresh, as a new world has them, and its last step's context
    not at all. The one thing the buffers carry from step to step, the id of the last
    batch of re-predictions, only has to differ from the ids the fresh buffers' marks
    hold, and does (the test beside this checks the resumed run bit for bit)."""
    world = run["world"]
    buffers, last_step = world._buf, world.last_step
    world._buf, world.last_step = Buffers(world.state.count), None
    try:
        partial = f"{path}.partial"
        with open(partial, "wb") as out:
            pickle.dump(run, out, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(partial, path)
    finally:
        world._buf, world.last_step = buffers, last_step


def load_checkpoint(path: str, key: tuple) -> dict:
    """A run saved by save_checkpoint, checked to be of the same scene (key); ValueError if
    not. Only load a checkpoint you wrote: it is a pickle."""
    with open(path, "rb") as file:
        run = pickle.load(file)
    if run.get("key") != key:
        raise ValueError(f"{path} is a checkpoint of another run ({_options(run.get('key'))}), not of "
                         f"{_options(key)}")
    return run


def _options(key) -> str:
    """A run's key (count, settings) as the options that give it."""
    if not (isinstance(key, tuple) and len(key) == 2):
        return repr(key)
    count, settings = key
    return " ".join([f"--count {count}", *(f"--set {setting}" for setting in settings)])


# The peers as benchmarked: each set up for physdbg's physics by physdbg/peers.py (the same
# translation record-peer uses), with the solver settings below; --peer-setups all times
# every one of them (docs/benchmarks.md, "The peers", says which is fastest and why).
FAST_SETUPS = (PeerSetup("pybullet"), PeerSetup("mujoco", "PGS", 10, sleep=True))
ALL_SETUPS = (PeerSetup("pybullet"),
              *(PeerSetup("mujoco", solver, iterations, speculative=speculative, sleep=sleep)
                for solver, iterations in (("PGS", 10), ("CG", 20), ("Newton", 10), ("Newton", 100))
                for speculative in (False, True) for sleep in (False, True)))


def run_peer_timed(scene, setup: PeerSetup) -> float | None:
    """Seconds the peer takes for the scene's steps (building it not counted); None when
    the peer cannot be imported."""
    if not available(setup.engine):
        return None
    world = build(scene, setup)
    try:
        started = time.perf_counter()
        for _ in range(scene.steps):
            world.step()
        return time.perf_counter() - started
    finally:
        world.close()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=240)
    parser.add_argument("--peers", action="store_true",
                        help="also step the scene in pybullet and MuJoCo, set up by physdbg/peers.py for the same "
                             "physics (frictionless, the same restitution, no damping, the same walls): pybullet with "
                             "its defaults, MuJoCo with PGS, 10 iterations and sleeping, its fastest honest setting "
                             "here (docs/benchmarks.md, \"The peers\")")
    parser.add_argument("--peer-setups", choices=("fast", "all"), default="fast",
                        help="with --peers: the fastest setting of each peer, or every MuJoCo solver (PGS, CG, "
                             "Newton), with and without speculative contacts and sleeping")
    parser.add_argument("--rounds", type=int, default=1, metavar="R",
                        help="with --peers: run the engines in turn R times; print each ratio's median and range")
    parser.add_argument("--with-run", action="store_true",
                        help="with --peers: in each round also time `physdbg run` (the engine and its default audit, "
                             "api.run) and print its speed against each peer")
    parser.add_argument("--trace", action="store_true", help="print every step, with the peak memory")
    parser.add_argument("--stop-above-gb", type=float, default=None, help="stop once peak memory passes this")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="another scene setting, as `physdbg run -s` takes it (repeatable)")
    parser.add_argument("--checkpoint", metavar="FILE", help="pickle the run here every --checkpoint-every steps")
    parser.add_argument("--checkpoint-every", type=int, default=20, metavar="K",
                        help="steps between checkpoints (default 20; one is also written at the end)")
    parser.add_argument("--resume", metavar="FILE",
                        help="carry on the run checkpointed in FILE (same --count and --set)")
    args = parser.parse_args()
    if args.checkpoint_every < 1:
        parser.error("--checkpoint-every must be at least 1")
    if args.rounds < 1 or (args.rounds > 1 and not args.peers):
        parser.error("--rounds must be at least 1, and more than 1 only with --peers")
    if args.with_run and not args.peers:
        parser.error("--with-run times `physdbg run` against the peers: give --peers too")
    try:
        scene = box_rain(args.count, args.steps, tuple(args.set))
    except SceneError as error:
        parser.error(str(error))
    key = (args.count, tuple(args.set))
    resumed = None
    if args.resume:
        try:
            resumed = load_checkpoint(args.resume, key)
        except (OSError, ValueError, pickle.UnpicklingError, EOFError) as error:
            parser.error(f"cannot resume from {args.resume}: {error}")
        print(f"resuming after step {resumed['world'].step_index} ({resumed['seconds']:.0f} s so far)")
    warm_up("grid", sleeping=scene.settings.sleep_speed > 0)
    result = run_physdbg(scene, args.trace, args.stop_above_gb, args.checkpoint, args.checkpoint_every, resumed, key)
    rows = np.array(result["rows"])
    steps = result["steps"]
    ms = 1000.0 * result["seconds"] / steps
    overrides = f" ({', '.join(args.set)})" if args.set else ""
    print(f"box-rain N={args.count}, {steps} of {args.steps} steps of {scene.dt:.6g} s{overrides}")
    s = scene.settings
    print(f"rules: rapid_contact_rule={s.rapid_contact_rule}, sleep_speed={s.sleep_speed:g} m/s, sleep_time="
          f"{s.sleep_time:g} s" + "".join(f"; auto {name}={d.value}: {decision_words(d)}"
                                          for name, d in scene.auto.items()
                                          if name in ("rapid_contact_rule", "sleep_speed")))
    print(f"physdbg: {ms:.1f} ms/step; steps stopped by a budget: {result['capped']}; largest overlap after any step: "
          f"{result['worst_overlap']:.3g} m (contact tolerance {result['tolerance']:g} m); peak memory "
          f"{result['peak_mb']:.0f} MB")
    for label, k in (("first", 0), ("middle", steps // 2), ("last", steps - 1)):
        c, h, r, released, e, asleep = rows[k]
        print(f"  {label} step: {c} contacts, {h} held, {r} rapid, {released} released, {e} events, {asleep} asleep")
    print(f"  last 10 steps: mean {rows[-10:, 0].mean():.0f} contacts/step, {rows[-10:, 1].mean():.0f} held, "
          f"{rows[-10:, 3].mean():.0f} released")
    if args.peers:
        compare_with_peers(scene, result["seconds"], args.rounds, FAST_SETUPS if args.peer_setups == "fast"
                           else ALL_SETUPS, with_run=args.with_run)


def run_audited(scene) -> float:
    """Seconds ``physdbg run`` takes for the scene: api.run, the engine with its default
    live audit (the world's building counted too, a few ms)."""
    from physdbg import api

    started = time.perf_counter()
    api.run(scene)
    return time.perf_counter() - started


def compare_with_peers(scene, physdbg_seconds: float, rounds: int, setups=FAST_SETUPS,
                       with_run: bool = False) -> dict[str, list[float]]:
    """Step the scene in each peer setup (when importable) and print physdbg's speed
    against each; over ``rounds`` rounds (physdbg, then each peer, in turn; the first
    round's physdbg run is the one already timed) also each ratio's median and range.
    with_run: each round also times ``physdbg run`` (run_audited) and its speed against
    each peer ("<peer> (run)"). Returns each setup's ratios, one per round."""
    ratios: dict[str, list[float]] = {}
    for round_number in range(rounds):
        if round_number:
            physdbg_seconds = run_physdbg(scene)["seconds"]
            print(f"round {round_number + 1}: physdbg {1000 * physdbg_seconds / scene.steps:.1f} ms/step")
        run_seconds = run_audited(scene) if with_run else None
        if run_seconds is not None:
            print(f"physdbg run (engine + default audit): {1000 * run_seconds / scene.steps:.1f} ms/step")
        for setup in setups:
            seconds = run_peer_timed(scene, setup)
            name = setup.label
            if seconds is None:
                if not round_number:
                    print(f"{name}: not importable (pip install 'physdbg[peers]')")
                continue
            ratios.setdefault(name, []).append(seconds / physdbg_seconds)
            print(f"{name}: {1000 * seconds / scene.steps:.1f} ms/step; physdbg is {ratios[name][-1]:.2f}x its speed"
                  + (f", `physdbg run` {seconds / run_seconds:.2f}x" if run_seconds is not None else ""))
            if run_seconds is not None:
                ratios.setdefault(f"{name} (run)", []).append(seconds / run_seconds)
    if rounds > 1:
        for name, values in ratios.items():
            print(f"physdbg against {name} over {rounds} rounds: median {np.median(values):.2f}x, "
                  f"range {min(values):.2f}-{max(values):.2f}x")
    return ratios

if __name__ == "__main__":
    main()
