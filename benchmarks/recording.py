"""What recording costs: time against recording off, and bytes on disk, in one run.

    .venv/bin/python benchmarks/recording.py            # box-rain 1k (240 steps) and 10k (120 steps)
    .venv/bin/python benchmarks/recording.py --quick    # 1k, 60 steps, and 10k, 24 steps
    .venv/bin/python benchmarks/recording.py --size 10000 240   # bytes only, one whole second
    .venv/bin/python benchmarks/recording.py --meshes    # what the search of the meshes' trees adds

Prints markdown tables (docs/recording.md comes from this command):

1. box-rain (the scene of benchmarks/broadphase.py): ms/step with recording off, MCAP only
   at --detail state / contacts / full with the view channels (the default) and without
   (--no-view), and MCAP full + Rerun; the ratio to "off" is what recording costs. Each configuration runs in a fresh subprocess, after the kernels are
   loaded, on the same steps; the configurations take turns, three rounds (two with
   --quick), and the fastest round of each is reported (the least disturbed by the rest
   of the machine).
2. size: bytes per particle-step of an MCAP file at --detail state (the packed float64
   positions and velocities, with the hash and the per-step stats, which are a rounding
   error here), against 48 raw; and the sizes of the other files.
3. `physdbg --help` wall time (best of 5, fresh interpreter each time).

Machines here are noisy: compare the numbers of one run with each other.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

CONFIGS = [  # (label, detail or None for off, Rerun too, view channels)
    ("off", None, False, False),
    ("mcap state --no-view", "state", False, False),
    ("mcap state", "state", False, True),
    ("mcap contacts --no-view", "contacts", False, False),
    ("mcap contacts", "contacts", False, True),
    ("mcap full --no-view", "full", False, False),
    ("mcap full", "full", False, True),
    ("mcap full + rerun", "full", True, True),
]


def worker(n: int, steps: int, detail: str | None, rerun: bool, folder: str, view: bool = True) -> dict:
    """One configuration, in its own process: ms/step and file sizes."""
    from physdbg.analysis.engines import box_rain_scene
    from physdbg.engine import warm_up
    from physdbg.observe import FanOut
    from physdbg.record.header import RecordingHeader
    from physdbg.record.mcap_sink import McapRecorder

    scene = box_rain_scene(n, steps)
    sinks = []
    mcap = Path(folder) / f"rain-{n}-{detail}-{view}.mcap"
    rrd = Path(folder) / f"rain-{n}.rrd"
    if detail is not None:
        header = RecordingHeader.from_scene(scene, detail)
        sinks.append(McapRecorder(mcap, header, view=view))
        if rerun:
            from physdbg.record.rerun_sink import RerunSink

            sinks.append(RerunSink(header, rrd))
    world = scene.build_world(FanOut(*sinks) if sinks else None)
    warm_up(world.broad_phase.name, sleeping=world.sleepers is not None)
    started = time.perf_counter()
    for _ in range(scene.steps):
        world.step(scene.dt)
    for sink in sinks:  # closing (summary, flushing rerun) is part of the cost
        sink.close()
    wall = time.perf_counter() - started
    out = {"ms_per_step": 1e3 * wall / scene.steps}
    if detail is not None:
        out["mcap_bytes"] = mcap.stat().st_size
        out["bytes_per_particle_step"] = mcap.stat().st_size / (n * (scene.steps + 1))
    if rerun:
        out["rrd_bytes"] = rrd.stat().st_size
    return out


MESH_CONFIGS = [  # (label, detail, the search recorded); the view channels written (the default)
    ("mcap full, no search", "full", False), ("mcap full", "full", True),
    ("mcap contacts, no search", "contacts", False), ("mcap contacts", "contacts", True),
]


def mesh_worker(name: str, detail: str, search: bool, folder: str) -> dict:
    """A built-in mesh scene recorded whole, with or without the search of the meshes'
    trees (a recorder that does not read MeshSearch: the file is what it was before the
    search was recorded), in its own process: ms/step, bytes, and the search channels'
    message bytes (protobuf, before compression)."""
    from physdbg import api
    from physdbg.engine import warm_up
    from physdbg.record import format as fmt
    from physdbg.record.header import RecordingHeader
    from physdbg.record.mcap_sink import McapRecorder
    from physdbg.record.reader import open_recording

    class Recorder(McapRecorder):
        wants_mesh_search = search

    scene = api.load_scene(name)
    mcap = Path(folder) / f"{name}-{detail}-{search}.mcap"
    recorder = Recorder(mcap, RecordingHeader.from_scene(scene, detail))
    world = scene.build_world(recorder)
    warm_up(world.broad_phase.name, sleeping=world.sleepers is not None)
    lengths = list(scene.step_lengths())
    started = time.perf_counter()
    for dt in lengths:
        world.step(dt)
    recorder.close()
    wall = time.perf_counter() - started
    with open_recording(mcap) as rec:
        channel = sum(len(data) for topic in (fmt.TOPIC_MESH_QUERIES, fmt.TOPIC_MESH_SEARCH)
                      for _, data in rec.raw_messages(topic))
    return {"ms_per_step": 1e3 * wall / len(lengths), "mcap_bytes": mcap.stat().st_size, "search_bytes": channel,
            "steps": len(lengths)}


def mesh_search_cost(rounds: int = 3) -> None:
    """The time and bytes the search channels add to `physdbg record` of funnel and paddle."""
    print("| scene | steps | recording | ms/step | MCAP KB | search messages KB |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        for name in ("funnel", "paddle"):
            best: dict[str, dict] = {}
            for _ in range(rounds):
                for label, detail, search in MESH_CONFIGS:
                    code = (f"import sys, json; sys.path.insert(0, {str(ROOT / 'benchmarks')!r}); import recording; "
                            f"print(json.dumps(recording.mesh_worker({name!r}, {detail!r}, {search}, {folder!r})))")
                    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
                    if done.returncode != 0:
                        raise SystemExit(done.stderr)
                    r = json.loads(done.stdout.strip().splitlines()[-1])
                    if label not in best or r["ms_per_step"] < best[label]["ms_per_step"]:
                        best[label] = r
            for label, _, _ in MESH_CONFIGS:
                r = best[label]
                print(f"| {name} | {r['steps']} | {label} | {r['ms_per_step']:.2f} | {r['mcap_bytes'] / 1e3:.0f} "
                      f"| {r['search_bytes'] / 1e3:.0f} |", flush=True)


def _in_subprocess(n: int, steps: int, detail: str | None, rerun: bool, folder: str, view: bool = True) -> dict:
    code = (f"import sys, json; sys.path.insert(0, {str(ROOT / 'benchmarks')!r}); import recording; "
            f"print(json.dumps(recording.worker({n}, {steps}, {detail!r}, {rerun}, {folder!r}, {view})))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    if done.returncode != 0:
        raise SystemExit(done.stderr)
    return json.loads(done.stdout.strip().splitlines()[-1])


def help_seconds(repeats: int = 5) -> float:
    exe = [sys.executable, "-m", "physdbg.cli", "--help"]
    best = float("inf")
    for _ in range(repeats):
        started = time.perf_counter()
        subprocess.run(exe, capture_output=True, check=True, cwd=ROOT)
        best = min(best, time.perf_counter() - started)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer steps")
    parser.add_argument("--size", nargs=2, type=int, metavar=("N", "STEPS"),
                        help="only the size of a --detail state recording of box-rain N for STEPS steps")
    parser.add_argument("--meshes", action="store_true",
                        help="only what recording the search of the meshes' trees adds (funnel, paddle)")
    args = parser.parse_args()
    if args.meshes:
        mesh_search_cost(2 if args.quick else 3)
        return
    if args.size:
        n, steps = args.size
        with tempfile.TemporaryDirectory() as folder:
            r = _in_subprocess(n, steps, "state", False, folder, view=False)
        print(f"box-rain N = {n}, {steps} steps, --detail state: {r['mcap_bytes'] / 1e6:.2f} MB, "
              f"{r['bytes_per_particle_step']:.1f} bytes per particle-step (raw positions + velocities: 48), "
              "without the view channels")
        return
    sizes = [(1000, 60 if args.quick else 240), (10_000, 24 if args.quick else 120)]
    print(f"box-rain, dt = 1/240, swept, time ordering; {os.cpu_count()} cores\n")
    print("| N | steps | recording | ms/step | × off | MCAP MB | bytes/particle-step | .rrd MB |")
    print("|---|---|---|---|---|---|---|---|")
    rounds = 2 if args.quick else 3
    with tempfile.TemporaryDirectory() as folder:
        for n, steps in sizes:
            best: dict[str, dict] = {}
            for _ in range(rounds):
                for label, detail, rerun, view in CONFIGS:
                    r = _in_subprocess(n, steps, detail, rerun, folder, view)
                    if label not in best or r["ms_per_step"] < best[label]["ms_per_step"]:
                        best[label] = r
            base = best["off"]["ms_per_step"]
            for label, _, _, _ in CONFIGS:
                r = best[label]
                mcap = f"{r['mcap_bytes'] / 1e6:.2f}" if "mcap_bytes" in r else "-"
                per = f"{r['bytes_per_particle_step']:.1f}" if "bytes_per_particle_step" in r else "-"
                rrd = f"{r['rrd_bytes'] / 1e6:.1f}" if "rrd_bytes" in r else "-"
                print(f"| {n} | {steps} | {label} | {r['ms_per_step']:.1f} | {r['ms_per_step'] / base:.2f} "
                      f"| {mcap} | {per} | {rrd} |", flush=True)
    print(f"\n`physdbg --help`: {help_seconds():.3f} s (best of 5, fresh interpreter)")


if __name__ == "__main__":
    main()
