"""How long diff and explain take on two 10,000-step recordings of 1,000 spheres, and what
checking every state against its stored hash (docs/recording.md, "Integrity") adds.

    .venv/bin/python benchmarks/analysis.py [--steps 10000] [--count 1000] [--keep DIR] [--rounds 3]

Records the gas scene twice (restitution 1 and 0.999999999: the runs part at the first
collision by a few nanometres, and the gap then grows over the whole run), then times, in
one process and alternating so the machine's drift falls on both alike:

* ``diff`` of the two (first divergence found and reported), with and without the check;
* ``diff`` of a recording against a copy of itself (equivalent: every state of both is
  read), with the check, and without it (then only the frame index is compared);
* ``explain`` (every check over every step), with and without the check.

Prints the best of ``--rounds`` for each, and what the check adds to each command.

Then ``check-run`` (``api.check_run``, once each: it records physdbg's reference every time)
of each recording taken as another engine's run of the exact scene: the exact one (SAME:
every state of both runs compared) and the nudged one (it departs at its first collision,
and every later step is taken again from the run's own state and judged: chaos), with the
time each part took (reading the run and importing it, recording the reference,
comparing).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from physdbg import api
from physdbg.analysis import diff, explain


def _best(rounds: int, run) -> tuple[float, object]:
    best, result = float("inf"), None
    for _ in range(rounds):
        started = time.perf_counter()
        result = run()
        best = min(best, time.perf_counter() - started)
    return best, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--detail", default="full")
    parser.add_argument("--rounds", type=int, default=3)
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
    copy = folder / f"{paths[0].stem}-copy.mcap"
    if not copy.exists():
        shutil.copy(paths[0], copy)
    cases = [
        ("diff, runs that part", lambda verify: diff(*paths, verify=verify)),
        ("diff, a file against its copy", lambda verify: diff(paths[0], copy, verify=verify)),
        ("explain", lambda verify: explain(paths[0], verify=verify)),
    ]
    print(f"\n| command | checked (s) | --no-verify (s) | the check adds |\n|---|---|---|---|")
    for name, run in cases:
        times = {True: float("inf"), False: float("inf")}
        for _ in range(args.rounds):  # alternate, so a slow spell falls on both
            for verify in (True, False):
                seconds, result = _best(1, lambda: run(verify))
                times[verify] = min(times[verify], seconds)
        added = times[True] - times[False]
        print(f"| {name} | {times[True]:.2f} | {times[False]:.2f} | {added:+.2f} s ({100 * added / times[False]:+.0f} %) |")
    report = diff(*paths)
    print(f"\ndiff said: {report.headline}")
    print("\n| check-run of | import (s) | reference (s) | compare (s) | total (s) | verdict |\n|---|---|---|---|---|---|")
    scene = ["gas", [f"generate.count={args.count}", f"steps={args.steps}"]]
    for name, path in (("the exact run", paths[0]), ("the nudged run", paths[1])):
        marks = [("start", time.perf_counter())]
        result = api.check_run(path, scene[0], scene[1],
                               on_status=lambda what: marks.append((what, time.perf_counter())))
        marks.append(("end", time.perf_counter()))
        # the run read and imported until the reference's run starts ("compiling", or
        # "running" on a warm cache), the reference recorded until "comparing"
        comparing = next(t for what, t in marks if what == "comparing")
        recording = next(t for what, t in marks if what in ("compiling", "running"))
        parts = (recording - marks[0][1], comparing - recording, marks[-1][1] - comparing)
        verdict = "SAME" if result.report.exit_code == 0 else f"DEPARTS ({result.report.first.cause})"
        print(f"| {name} | {parts[0]:.1f} | {parts[1]:.1f} | {parts[2]:.1f} | {marks[-1][1] - marks[0][1]:.1f} | "
              f"{verdict} |")


if __name__ == "__main__":
    main()
