"""Every built-in scene on the event calendar: where it serves, why not elsewhere, and its phases.

    .venv/bin/python benchmarks/calendar_scenes.py [--longest 2.0] [--scene NAME ...]

Runs each built-in scene (or those named) twice, with ``event_loop = "step"`` and
``"calendar"``, without the audit and with the kernels loaded first (a first run of each
scene is not timed), over the scene's duration or ``--longest`` seconds of simulated
time, whichever is shorter. Prints, per scene: the steps the calendar took (the run
summary's ``event loop`` words: where it did not, why), the engine's ms a step with each
loop, and the calendar run's phase timings as the run summary measures them
(docs/space-order.md, "The event calendar"; docs/engine.md, "The event calendar on the
built-in scenes").
"""

from __future__ import annotations

import argparse
import math

from physdbg import api
from physdbg.scenes import builtin_names


def _run(name: str, loop: str, longest: float) -> api.RunSummary:
    scene = api.load_scene(name, [f"event_loop={loop}"])
    duration = min(scene.duration or longest, longest)
    steps = max(1, int(math.floor(duration / scene.dt + 0.5)))
    return api.run(scene, dts=[scene.dt] * steps, audit=False)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--longest", type=float, default=2.0, help="simulated seconds a scene runs at most")
    parser.add_argument("--scene", action="append", help="only these scenes (default: every built-in one)")
    args = parser.parse_args()
    names = args.scene or builtin_names()
    print(f"{'scene':12s} {'steps':>6s} {'step ms':>8s} {'cal. ms':>8s}  calendar phases (forces, broad, narrow, "
          "resolve, finish)  event loop")
    for name in names:
        _run(name, "calendar", min(args.longest, 0.05))  # kernels loaded (or compiled): not timed
        step = _run(name, "step", args.longest)
        calendar = _run(name, "calendar", args.longest)
        total = sum(calendar.phase_seconds.values()) or 1.0
        shares = ", ".join(f"{100 * s / total:.0f}%" for s in calendar.phase_seconds.values())
        served = calendar.event_loop  # RunSummary.event_loop: {calendar_steps, steps, unfit}
        unfit = f"; the time-ordered loop took the rest, which it cannot serve: {served['unfit']}" if served["unfit"] else ""
        print(f"{name:12s} {calendar.steps:6d} {step.engine_ms_per_step:8.3f} {calendar.engine_ms_per_step:8.3f}  "
              f"{shares:40s}  calendar in {served['calendar_steps']} of {served['steps']} steps{unfit}", flush=True)


if __name__ == "__main__":
    main()
