"""Speed of the broad phases and of whole steps, measured side by side in one run.

    .venv/bin/python benchmarks/broadphase.py            # everything (~10 minutes on 2 cores)
    .venv/bin/python benchmarks/broadphase.py --quick    # smaller sizes, a minute or so

Prints markdown tables (the ones in docs/broadphase.md come from this command):

1. box-rain: r = 0.05, 10 % volume fraction, e = 0.8, dt = 1/240, speeds near 2 m/s,
   gravity, swept detection, time ordering, nothing recorded; ms/step, contacts/step and
   peak memory for N = 1k, 10k, 100k — and, when pybullet is importable, the same scene
   in pybullet in the same run, with the ratio.
2. scaling of each broad phase: build + query ms against N, equal and mixed radii.
3. exact hard-sphere gas, N = 1k, packing fraction 0.3: collisions processed per second.
4. numba compile time: cold (empty cache) and cached.

Each measurement of a whole run is made in a fresh subprocess so that peak memory (RSS)
belongs to that run alone. Machines here are noisy: compare numbers from one run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


# ----------------------------------------------------------------------------- scenes
def box_rain_toml(n: int, steps: int) -> str:
    side = (n * 4.0 / 3.0 * math.pi * 0.05**3 / 0.1) ** (1.0 / 3.0)
    return f"""
name = "box-rain"
dt = "1/240"
steps = {steps}
seed = 1
integrator = "exact"
detection = "swept"
ordering = "time"
gravity = [0.0, -9.81, 0.0]
[box]
min = [0.0, 0.0, 0.0]
max = [{side!r}, {side!r}, {side!r}]
restitution = 0.8
[generate]
kind = "rain"
count = {n}
radius = 0.05
speed = 2.0
restitution = 0.8
"""


def gas_toml(n: int, steps: int) -> str:
    return f"""
name = "gas-bench"
dt = "1/100"
steps = {steps}
seed = 7
gravity = [0.0, 0.0, 0.0]
[generate]
kind = "gas"
count = {n}
radius = 0.05
packing_fraction = 0.3
speed = 1.0
restitution = 1.0
"""


# ----------------------------------------------------------------------------- workers (subprocess)
def _peak_rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker_physdbg(text: str) -> dict:
    from physdbg.engine import warm_up
    from physdbg.scene import parse_scene

    scene = parse_scene(text, "bench")
    world = scene.build_world()
    compile_s = warm_up(world.broad_phase.name)
    contacts = 0
    capped = 0
    started = time.perf_counter()
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
        contacts += stats.contacts
        capped += any(w.code == "max_events_per_step" for w in stats.warnings)
    wall = time.perf_counter() - started
    return {"ms_per_step": 1e3 * wall / scene.steps, "contacts": contacts, "steps": scene.steps,
            "collisions_per_s": contacts / wall, "broad_phase": world.broad_phase.name,
            "compile_s": compile_s, "peak_mb": _peak_rss_mb(), "capped_steps": capped}


def worker_pybullet(n: int, steps: int) -> dict:
    import pybullet as p

    side = (n * 4.0 / 3.0 * math.pi * 0.05**3 / 0.1) ** (1.0 / 3.0)
    from physdbg.scene import parse_scene

    scene = parse_scene(box_rain_toml(n, 1), "bench")  # the same initial conditions
    p.connect(p.DIRECT)
    p.setGravity(0, -9.81, 0)
    p.setTimeStep(1.0 / 240.0)
    p.setPhysicsEngineParameter(restitutionVelocityThreshold=0.0)
    wall = p.createCollisionShape(p.GEOM_BOX, halfExtents=[side, side, 0.5])
    for pos, orn in (([side / 2, -0.5, side / 2], [1, 0, 0]), ([side / 2, side + 0.5, side / 2], [1, 0, 0]),
                     ([-0.5, side / 2, side / 2], [0, 1, 0]), ([side + 0.5, side / 2, side / 2], [0, 1, 0]),
                     ([side / 2, side / 2, -0.5], None), ([side / 2, side / 2, side + 0.5], None)):
        q = p.getQuaternionFromEuler([math.pi / 2 * orn[0], math.pi / 2 * orn[1], 0]) if orn else [0, 0, 0, 1]
        body = p.createMultiBody(0, wall, basePosition=pos, baseOrientation=q)
        p.changeDynamics(body, -1, restitution=0.8)
    sphere = p.createCollisionShape(p.GEOM_SPHERE, radius=0.05)
    for x, v in zip(scene.state.positions, scene.state.velocities, strict=True):
        body = p.createMultiBody(1.0, sphere, basePosition=x.tolist())
        p.resetBaseVelocity(body, linearVelocity=v.tolist())
        p.changeDynamics(body, -1, restitution=0.8, linearDamping=0.0, angularDamping=0.0)
    started = time.perf_counter()
    for _ in range(steps):
        p.stepSimulation()
    wall_s = time.perf_counter() - started
    p.disconnect()
    return {"ms_per_step": 1e3 * wall_s / steps, "steps": steps, "peak_mb": _peak_rss_mb()}


def worker_scaling(n: int, mixed: bool, names: list[str], repeats: int) -> dict:
    import numpy as np

    from physdbg.engine import make_broad_phase, warm_up

    warm_up()
    rng = np.random.default_rng(n)
    side = (n * 4.0 / 3.0 * math.pi * 0.05**3 / 0.1) ** (1.0 / 3.0)
    centres = rng.uniform(0.0, side, (n, 3))
    radius = 0.05 * (10.0 ** rng.uniform(-1.0, 1.0, n) if mixed else np.ones(n))
    lo, hi = centres - radius[:, None], centres + radius[:, None]
    out = {}
    for name in names:
        bp = make_broad_phase(name)
        bp.pairs(lo, hi)  # compile / first build
        best = math.inf
        for _ in range(repeats):
            bp = make_broad_phase(name)
            started = time.perf_counter()
            pairs = bp.pairs(lo, hi)
            best = min(best, time.perf_counter() - started)
        out[name] = {"ms": 1e3 * best, "pairs": len(pairs)}
    return out


def run_worker(kind: str, *args, env=None, timeout=3600) -> dict:
    code = (f"import sys, json; sys.path.insert(0, {str(ROOT)!r}); import benchmarks.broadphase as b; "
            f"print(json.dumps(b.worker_{kind}(*json.loads(sys.argv[1]))))")
    result = subprocess.run([sys.executable, "-c", code, json.dumps(list(args))], capture_output=True, text=True,
                            env=env, timeout=timeout, cwd=ROOT)
    if result.returncode != 0:
        raise RuntimeError(f"{kind} worker failed:\n{result.stderr[-2000:]}")
    return json.loads(result.stdout.strip().splitlines()[-1])


def pybullet_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("pybullet") is not None


# ----------------------------------------------------------------------------- main
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes and few steps (a minute or so)")
    parser.add_argument("--steps", type=int, default=240, help="box-rain steps per size (240 = 1 s simulated)")
    parser.add_argument("--pybullet-max-n", type=int, default=10000,
                        help="largest N also run in pybullet (it takes ~0.2 s a step at 10k)")
    args = parser.parse_args()
    sizes = [1000, 10000] if args.quick else [1000, 10000, 100000]
    steps = 24 if args.quick else args.steps

    print("## box-rain (r = 0.05, 10 % volume, e = 0.8, dt = 1/240, swept, time ordering)\n")
    have_bullet = pybullet_available()
    print("| N | broad phase | ms/step | contacts/step | steps at the event cap | peak MB | pybullet ms/step | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for n in sizes:
        ours = run_worker("physdbg", box_rain_toml(n, steps))
        bullet = "not installed"
        ratio = "-"
        if have_bullet and n <= args.pybullet_max_n:
            theirs = run_worker("pybullet", n, steps)  # the same steps: the same second of rain
            bullet = f"{theirs['ms_per_step']:.1f}"
            speedup = theirs["ms_per_step"] / ours["ms_per_step"]
            ratio = f"{speedup:.1f}x faster" if speedup >= 1 else f"{1 / speedup:.1f}x slower"
        elif have_bullet:
            bullet = "not run (too slow)"
        print(f"| {n:,} | {ours['broad_phase']} | {ours['ms_per_step']:.2f} | {ours['contacts'] / ours['steps']:.0f} "
              f"| {ours['capped_steps']} of {ours['steps']} | {ours['peak_mb']:.0f} | {bullet} | {ratio} |", flush=True)

    print("\n## Broad phase alone: build + query ms (best of 3), uniform random boxes, 10 % volume\n")
    names = ["brute-force", "grid", "bvh-sah", "bvh-median", "bvh-mean", "bvh-lbvh"]
    scaling_sizes = [1000, 10000] if args.quick else [1000, 10000, 100000]
    print("| radii | N | " + " | ".join(names) + " | pairs |")
    print("|---|---|" + "---|" * len(names) + "---|")
    for mixed in (False, True):
        for n in scaling_sizes:
            chosen = [name for name in names if not (name == "brute-force" and n > 10000)]
            row = run_worker("scaling", n, mixed, chosen, 3)
            cells = [f"{row[name]['ms']:.2f}" if name in row else "-" for name in names]
            print(f"| {'mixed 100x' if mixed else 'equal'} | {n:,} | " + " | ".join(cells)
                  + f" | {next(iter(row.values()))['pairs']:,} |", flush=True)

    print("\n## Exact hard-sphere gas, N = 1000, packing fraction 0.3, e = 1\n")
    gas = run_worker("physdbg", gas_toml(1000, 20 if args.quick else 100))
    print(f"{gas['collisions_per_s']:,.0f} collisions processed per second "
          f"({gas['contacts']:,} in {gas['steps']} steps, {gas['ms_per_step']:.1f} ms/step, {gas['broad_phase']})")

    print("\n## numba compile time\n")
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        cold = run_worker("physdbg", box_rain_toml(100, 2), env=env)["compile_s"]
        warm = run_worker("physdbg", box_rain_toml(100, 2), env=env)["compile_s"]
    print(f"cold (empty cache): {cold:.1f} s; cached: {warm:.2f} s")


if __name__ == "__main__":
    main()
