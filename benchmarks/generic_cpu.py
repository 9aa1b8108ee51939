"""Kernels compiled for a generic CPU against kernels compiled for this one: speed and result.

    .venv/bin/python benchmarks/generic_cpu.py [--rounds 3]

numba compiles for the host CPU (its name and features, e.g. AVX2) unless told otherwise;
``NUMBA_CPU_NAME=generic`` compiles for the architecture's baseline instead (x86-64: SSE2),
and numba keys its on-disk cache by that name and those features, so a generic cache is
found on any machine of the architecture (a CI runner of another CPU model), where a
native one is recompiled. This measures what the portable cache costs a run: each scene
is run with both, alternately (a slow spell of this noisy machine falls on both), first
once each to compile (``PHYSDBG_COMPILE=now``, not timed), then ``--rounds`` times; it
prints the median engine ms/step of each (the summary's ``engine_ms_per_step``: the
steps alone, without the audit or recording) and whether the final state hashes agree
(they must: neither build fuses multiply-adds, so both do the same float64 operations).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

PHYSDBG = str(Path(sys.executable).with_name("physdbg"))
SCENES = [
    ("rain, 2,000 spheres: a pile (held-contact solves)", ["rain", "-s", "generate.count=2000"]),
    ("gas, 4,000 spheres: free flight and pair collisions (the time-ordered loop)",
     ["gas", "-s", "generate.count=4000", "-s", "steps=100"]),
]


def run(scene: list[str], generic: bool) -> dict:
    env = dict(os.environ, PHYSDBG_COMPILE="now")
    env.pop("NUMBA_CPU_NAME", None)
    env.pop("NUMBA_CPU_FEATURES", None)
    if generic:
        env["NUMBA_CPU_NAME"] = "generic"
    done = subprocess.run([PHYSDBG, "run", *scene, "--json", "--no-progress"], env=env, capture_output=True,
                          text=True)
    if done.returncode not in (0, 1):
        raise SystemExit(f"physdbg run {' '.join(scene)} exited {done.returncode}:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    print("| scene | native ms/step | generic ms/step | generic / native | same final hash |\n"
          "|---|---:|---:|---:|---|")
    for label, scene in SCENES:
        for generic in (False, True):  # compile both first (or load them), untimed
            run(scene, generic)
        times: dict[bool, list[float]] = {False: [], True: []}
        hashes: dict[bool, set[str]] = {False: set(), True: set()}
        for _ in range(args.rounds):
            for generic in (False, True):
                summary = run(scene, generic)
                times[generic].append(summary["engine_ms_per_step"])
                hashes[generic].add(summary["final_hash"])
        native, generic = statistics.median(times[False]), statistics.median(times[True])
        same = len(hashes[False] | hashes[True]) == 1
        print(f"| {label} | {native:.1f} ({min(times[False]):.1f}–{max(times[False]):.1f}) | {generic:.1f} "
              f"({min(times[True]):.1f}–{max(times[True]):.1f}) | {generic / native:.2f}× | "
              f"{'yes' if same else 'NO: ' + ', '.join(sorted(hashes[False] | hashes[True]))} |")


if __name__ == "__main__":
    main()
