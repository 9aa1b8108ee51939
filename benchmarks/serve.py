"""The time from a page's finish() to its verdict: `physdbg check-run --serve` answering one
POST of the run, as physdbg-trace.js sends it, kernels warm (docs/foreign-runs.md, "Speed
of the page's verdict").

    .venv/bin/python benchmarks/serve.py [--repeat 3]

bounce (300 steps, 1 ball) and billiards (480 steps, 12 bodies), each traced by the student
engine of tests/student_engine.py with integrator = euler (a SAME run: every step compared)
and billiards with the "1 +" missing (a departing run: every step after the departure
judged). One warm-up check first (the kernels load), then --repeat checks of each.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def run_text(name: str, mistake: str | None = None) -> bytes:
    from physdbg.api import load_scene
    from tests.student_engine import simulate_swept, trace_text

    scene = load_scene(name, ["integrator=euler"])
    return trace_text(scene, *simulate_swept(scene, scene.steps, scene.dt, mistake))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    from physdbg.serve import CheckServer

    with tempfile.TemporaryDirectory() as folder:
        server = CheckServer(Path(folder) / "runs", port=0)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        runs = {"bounce (300 steps, 1 ball), SAME": run_text("bounce"),
                "billiards (480 steps, 12 bodies), SAME": run_text("billiards"),
                "billiards, the 1 + missing: DEPARTS": run_text("billiards", "one-missing")}

        def post(body: bytes) -> tuple[float, str]:
            started = time.perf_counter()
            with urllib.request.urlopen(urllib.request.Request(server.url + "/check", data=body), timeout=600) as a:
                verdict = json.loads(a.read())["verdict"]
            return time.perf_counter() - started, verdict

        post(runs["bounce (300 steps, 1 ball), SAME"])  # warm-up: the kernels load
        print(f"{'run':<42} {'verdict':<8} seconds (each of {args.repeat})")
        for label, body in runs.items():
            times = [post(body) for _ in range(args.repeat)]
            print(f"{label:<42} {times[0][1]:<8} " + "  ".join(f"{t:.2f}" for t, _ in times))
        server.shutdown()


if __name__ == "__main__":
    main()
