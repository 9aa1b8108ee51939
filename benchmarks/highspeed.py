"""highspeed: the built-in scene (after Jolt's HighSpeed test) in physdbg and its peers, side by side.

    .venv/bin/python benchmarks/highspeed.py [--count 5000] [--steps 120]

5,000 spheres (r = 0.25 m) at 250 m/s in random directions in a 100 m room whose six walls
are 0.2 m thick slabs of triangles; a step of 1/60 s carries a sphere 4.2 m, 21 wall
thicknesses. Each engine steps the same initial state the same number of steps, one after
another in this one run (these machines are noisy: compare the ratios): physdbg with the
scene's settings (swept detection), pybullet with each wall a static triangle mesh and its
continuous collision on (each sphere a rigid body, ccdSweptSphereRadius 0.9 r) and without
it (each sphere a multibody, pybullet's default), MuJoCo with PGS and
10 iterations (its fastest honest setting in box_rain.py) and each wall as its mesh's convex
hull (exact for a slab). All frictionless, set up by physdbg/peers.py. Prints ms/step and
escapes (spheres whose centre got past a wall's outer face, |x| > 50.2 m on an axis, at the
end of any step) and the fastest sphere at the end (a pybullet multibody moves no faster
than 100 m/s: a clamp of its own, so that run is not the same physics) per engine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from physdbg import api
from physdbg.peers import PeerSetup, available, build

SETUPS = (PeerSetup("pybullet", ccd=True), PeerSetup("pybullet"), PeerSetup("mujoco", "PGS", 10))
HALF_SIDE = 50.2  # m: the walls' outer faces (a soft contact may press a centre past an inner face)


def _escapes(positions: np.ndarray) -> np.ndarray:
    return np.abs(positions).max(axis=1) > HALF_SIDE


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=5000)
    parser.add_argument("--steps", type=int, default=120)
    args = parser.parse_args()
    scene = api.load_scene("highspeed", [f"generate.count={args.count}", f"steps={args.steps}"])
    print(f"highspeed: {args.count} spheres at 250 m/s, {args.steps} steps of {scene.dt:.6g} s")
    world = scene.build_world()
    world.step(scene.dt)  # loads (or compiles) the kernels; counted below as a step all the same
    world = scene.build_world()
    out = np.zeros(scene.state.count, dtype=bool)
    start = time.perf_counter()
    for _ in range(args.steps):
        world.step(scene.dt)
        out |= _escapes(world.state.positions)
    rows = [("physdbg (swept)", (time.perf_counter() - start) / args.steps, int(out.sum()),
             float(np.linalg.norm(world.state.velocities, axis=1).max()))]
    for setup in SETUPS:
        if not available(setup.engine):
            rows.append((setup.label, float("nan"), -1, float("nan")))
            continue
        peer = build(scene, setup)
        out = np.zeros(scene.state.count, dtype=bool)
        start = time.perf_counter()
        for _ in range(args.steps):
            peer.step()
            out |= _escapes(peer.positions())
        rows.append((setup.label, (time.perf_counter() - start) / args.steps, int(out.sum()),
                     float(np.linalg.norm(peer.velocities(), axis=1).max())))
        peer.close()
    base = rows[0][1]
    print(f"{'engine':<18} {'ms/step':>9} {'physdbg is':>14} {'escapes':>8} {'fastest m/s':>12}")
    for label, seconds, escaped, fastest in rows:
        ratio = "" if label.startswith("physdbg") else f"{seconds / base:.2f}x as fast"
        print(f"{label:<18} {seconds * 1e3:9.1f} {ratio:>14} {escaped if escaped >= 0 else 'n/a':>8} {fastest:12.1f}")
    print("(reading each peer's positions every step, to count escapes, is part of its time)")


if __name__ == "__main__":
    main()
