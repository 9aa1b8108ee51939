"""How long diff and explain take on two 10,000-step recordings of 1,000 spheres.

    .venv/bin/python benchmarks/analysis.py [--steps 10000] [--count 1000] [--keep DIR]

Records the gas scene twice (restitution 1 and 0.999999999: the runs part at the first
collision by a few nanometres, and the gap then grows over the whole run), then times ``diff`` (first divergence
found and reported) and ``explain`` (every check over every step). Targets (issue 9):
diff under 1 s, explain under 10 s.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from physdbg import api
from physdbg.analysis import diff, explain


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--detail", default="full")
    parser.add_argument("--keep", type=Path, default=None, help="reuse/keep the recordings in this folder")
    args = parser.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="physdbg-bench-"))
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, extra in (("exact", []), ("nudged", ["generate.restitution=0.999999999"])):
        path = folder / f"gas{args.count}-{args.steps}-{name}-{args.detail}.mcap"
        if not path.exists():
            started = time.perf_counter()
            api.record("gas", [f"generate.count={args.count}", f"steps={args.steps}", *extra], mcap_path=str(path),
                       rrd=False, detail=args.detail)
            print(f"recorded {path.name}: {path.stat().st_size / 2**20:.1f} MiB in {time.perf_counter() - started:.1f} s")
        paths.append(path)
    started = time.perf_counter()
    report = diff(*paths)
    diff_seconds = time.perf_counter() - started
    started = time.perf_counter()
    audit = explain(paths[0])
    explain_seconds = time.perf_counter() - started
    print("\n| what | seconds | target |\n|---|---|---|")
    print(f"| diff: first divergence (step {report.divergence.step if report.divergence else '-'}) found and "
          f"reported | {diff_seconds:.2f} | < 1 |")
    print(f"| explain: {audit.checked} steps audited, {sum(audit.counts.values())} findings | {explain_seconds:.2f} "
          f"| < 10 |")
    print(f"\ndiff said: {report.headline}")


if __name__ == "__main__":
    main()
