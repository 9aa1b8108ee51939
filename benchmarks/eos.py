"""A paper's table: the hard-sphere equation of state and collision rate, read off recordings.

    .venv/bin/python benchmarks/eos.py             # N = 1000, phi 0.1-0.4 (docs/pressure.md comes from this)
    .venv/bin/python benchmarks/eos.py --quick     # N = 500, 1e5 collisions: wider error bars
    .venv/bin/python benchmarks/eos.py --count 2000 --collisions 1e6 --jobs 2

For each packing fraction, the built-in ``gas`` scene (e = 1, exact integrator, swept
detection, time order) is recorded in a periodic box (``-s box.periodic=true``): the
run lasts long enough for about ``--collisions`` sphere–sphere collisions after the
first ``--skip`` of it, which the gas spends forgetting its lattice start. Then, from the
recording alone (physdbg.analysis.pressure.equation_of_state):

* Z = PV/(NkT) from the collisional virial, with the standard error over 10 blocks,
  against Carnahan–Starling (Z = 1.5213, 2.4062, 3.9738, 6.7901);
* collisions per sphere per second, against Enskog's 4 n σ² g(σ) sqrt(π kT/m) with the
  Carnahan–Starling contact value g(σ) (the rate and Z - 1 = 4 φ g(σ) measure the same
  g(σ), so both columns agree with theory or neither does);
* the speed: pair collisions per wall-clock second of the whole recorded run.

Prints a Markdown table. The error bars are statistical only; a finite N also shifts Z
by O(1/N) (a few 0.1 % at N = 1000 and phi = 0.4), which is why the table says N.
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

PACKING = (0.1, 0.2, 0.3, 0.4)
RADIUS = 0.05  # m, the gas scene's
SPEED = 1.0  # m/s rms, the gas scene's: kT = m v_rms² / 3


def duration_for(phi: float, count: int, collisions: float, skip: float) -> float:
    """Simulated seconds that give about ``collisions`` pair collisions after the skipped part."""
    from physdbg.analysis.pressure import enskog_collision_rate

    rate = enskog_collision_rate(phi, 2 * RADIUS, SPEED**2 / 3, 1.0)  # per sphere per second
    return collisions / (0.5 * count * rate) / (1 - skip)


def one(phi: float, count: int, collisions: float, skip: float, dt: str, folder: str) -> dict:
    """Record one packing fraction and read its equation of state back."""
    import physdbg
    import physdbg.api
    import physdbg.engine
    from physdbg.analysis.pressure import equation_of_state

    duration = duration_for(phi, count, collisions, skip)
    path = Path(folder) / f"gas-{phi}.mcap"
    overrides = ["box.periodic=true", f"generate.count={count}", f"generate.packing_fraction={phi}",
                 f"duration={duration:.6g}", f"dt={dt}"]
    physdbg.engine.warm_up("grid")  # load the kernels before the clock starts
    started = time.perf_counter()
    physdbg.api.record("gas", overrides, mcap_path=str(path), rrd=False, detail="state", view=False, force=True)
    seconds = time.perf_counter() - started
    rec = physdbg.open_recording(path)
    eos = equation_of_state(rec, skip=skip)
    total = int(rec.stats()["collisions"].sum())
    return {"phi": phi, "count": count, "duration": duration, "steps": rec.steps, "seconds": seconds,
            "collisions": total, "eos": eos, "command": "physdbg record gas -s " + " -s ".join(overrides)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=1000, help="spheres (default 1000)")
    parser.add_argument("--collisions", type=float, default=5e5, help="pair collisions averaged over (default 5e5)")
    parser.add_argument("--skip", type=float, default=0.2, help="fraction of each run left out (default 0.2)")
    parser.add_argument("--dt", default="1/50", help="recorded step (default 1/50 s; exact at any dt)")
    parser.add_argument("--jobs", type=int, default=2, help="packing fractions run at once (default 2)")
    parser.add_argument("--quick", action="store_true", help="N = 500 and 1e5 collisions")
    parser.add_argument("--packing", type=float, nargs="+", default=list(PACKING),
                        help="packing fractions (default 0.1 0.2 0.3 0.4)")
    args = parser.parse_args(argv)
    k = len(args.packing)
    if args.quick:
        args.count, args.collisions = 500, 1e5
    with tempfile.TemporaryDirectory(prefix="physdbg-eos-") as folder:
        with ProcessPoolExecutor(max_workers=max(1, args.jobs), mp_context=multiprocessing.get_context("spawn")) as pool:
            rows = list(pool.map(one, args.packing, [args.count] * k, [args.collisions] * k, [args.skip] * k,
                                 [args.dt] * k, [folder] * k))
    print(f"Hard spheres, N = {args.count}, periodic box, e = 1, exact integrator; averaged over the last "
          f"{1 - args.skip:.0%} of each run (about {args.collisions:.3g} collisions); ± is one standard error "
          f"over 10 blocks.\n")
    print("| φ | Z (physdbg) | Z (Carnahan–Starling) | off by | collisions/sphere/s | Enskog | off by "
          "| collisions | steps | wall s | collisions/s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for r in rows:
        e = r["eos"]
        dz = (e.z_virial - e.z_carnahan_starling) / e.z_carnahan_starling
        dr = (e.collision_rate - e.collision_rate_enskog) / e.collision_rate_enskog
        worst = max(worst, abs(dz))
        print(f"| {r['phi']:.1f} | {e.z_virial:.4f} ± {e.z_virial_error:.4f} | {e.z_carnahan_starling:.4f} "
              f"| {100 * dz:+.2f} % | {e.collision_rate:.3f} ± {e.collision_rate_error:.3f} "
              f"| {e.collision_rate_enskog:.3f} | {100 * dr:+.2f} % | {r['collisions']:,} | {r['steps']} "
              f"| {r['seconds']:.1f} | {r['collisions'] / r['seconds']:.3g} |")
    print(f"\nlargest |Z - Z_CS| / Z_CS: {100 * worst:.2f} % (target 0.5 %)")
    print("\nEach row is one recording, e.g.:\n\n    " + rows[-1]["command"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
