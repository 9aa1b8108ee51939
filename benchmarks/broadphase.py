"""Speed of the broad phases alone, side by side in one run.

    .venv/bin/python benchmarks/broadphase.py            # N = 1k, 10k, 100k (a few minutes on 2 cores)
    .venv/bin/python benchmarks/broadphase.py --quick    # N = 1k, 10k

Prints the markdown table of docs/broadphase.md: build + query milliseconds (best of 3) of
every broad phase on uniform random boxes filling 10 % of a cube, all of one radius or
radii spread over a factor 100, and the pairs found (the same for every broad phase). Each
size runs in a fresh subprocess. Whole runs against the peers are box_rain.py's; the gas
is gas.py's.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NAMES = ["brute-force", "grid", "bvh-sah", "bvh-median", "bvh-mean", "bvh-lbvh"]


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


def run_worker(kind: str, *args, timeout=3600) -> dict:
    code = (f"import sys, json; sys.path.insert(0, {str(ROOT)!r}); import benchmarks.broadphase as b; "
            f"print(json.dumps(b.worker_{kind}(*json.loads(sys.argv[1]))))")
    result = subprocess.run([sys.executable, "-c", code, json.dumps(list(args))], capture_output=True, text=True,
                            timeout=timeout, cwd=ROOT)
    if result.returncode != 0:
        raise RuntimeError(f"{kind} worker failed:\n{result.stderr[-2000:]}")
    return json.loads(result.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="N = 1k and 10k only")
    args = parser.parse_args()
    sizes = [1000, 10000] if args.quick else [1000, 10000, 100000]
    print("| radii | N | " + " | ".join(NAMES) + " | pairs |")
    print("|---|---|" + "---|" * len(NAMES) + "---|")
    for mixed in (False, True):
        for n in sizes:
            chosen = [name for name in NAMES if not (name == "brute-force" and n > 10000)]
            row = run_worker("scaling", n, mixed, chosen, 3)
            cells = [f"{row[name]['ms']:.2f}" if name in row else "-" for name in NAMES]
            print(f"| {'mixed 100x' if mixed else 'equal'} | {n:,} | " + " | ".join(cells)
                  + f" | {next(iter(row.values()))['pairs']:,} |", flush=True)


if __name__ == "__main__":
    main()
