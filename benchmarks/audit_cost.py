"""What the default audit adds to a run: box-rain and the exact gas, the engine alone against
`physdbg run`'s engine + audit, with the audit's time split by check.

    .venv/bin/python benchmarks/audit_cost.py [--count 10000] [--steps 240] [--gas-count 1000]
        [--gas-steps 200] [--rounds 2]

Each scene runs through ``physdbg.api.run`` with ``audit=False`` and ``audit=True`` (what
`physdbg run` and `record` do by default), one after the other, ``--rounds`` times; the
best time of each is kept (these machines are noisy) and the overhead is audited / alone − 1
(the target: at most 25 %), and with ``audit="full"`` (``--full-audit``: every pair's path walked
again, as ``physdbg explain`` does). Then one more run with the full audit and each check of
``physdbg.analysis.audit.Auditor`` and the pair test's kernels timed (ms a step; the timing
adds a little of its own): docs/benchmarks.md, "What the audit costs".
"""

from __future__ import annotations

import argparse
import time
from contextlib import contextmanager
from dataclasses import replace


def _ms_per_step(scene, steps: int, audit: bool | str) -> float:
    """One run through api.run with this audit (False, True or "full"): ms a step."""
    from physdbg import api

    started = time.perf_counter()
    api.run(scene, audit=audit)
    return 1e3 * (time.perf_counter() - started) / steps


@contextmanager
def _timed(owners_and_names):
    """Wrap each (owner, name) so its calls are timed; yields the dict of seconds by name."""
    spent: dict[str, float] = {}
    saved = []
    for owner, name in owners_and_names:
        original = getattr(owner, name)
        saved.append((owner, name, original))

        def wrapper(*args, _original=original, _name=name, **kwargs):
            started = time.perf_counter()
            try:
                return _original(*args, **kwargs)
            finally:
                spent[_name] = spent.get(_name, 0.0) + time.perf_counter() - started

        setattr(owner, name, wrapper)
    try:
        yield spent
    finally:
        for owner, name, original in saved:
            setattr(owner, name, original)


def measure(label: str, scene, steps: int, rounds: int) -> None:
    from physdbg import api
    from physdbg.analysis import audit, tunnel

    api.run(scene, audit=True)  # kernels loaded, caches warm
    alone = audited = full = float("inf")
    for _ in range(rounds):  # in turn, so a slow spell of the machine falls on all three
        alone = min(alone, _ms_per_step(scene, steps, False))
        audited = min(audited, _ms_per_step(scene, steps, True))
        full = min(full, _ms_per_step(scene, steps, "full"))
    print(f"{label}: engine alone {alone:.2f} ms/step, with the default audit {audited:.2f} ms/step "
          f"(+{100 * (audited / alone - 1):.0f} %; target <= +25 %), with --full-audit {full:.2f} ms/step "
          f"(+{100 * (full / alone - 1):.0f} %)")
    checks = [(audit.Auditor, name) for name in ("_end_step", "_check_crossings", "_check_overlap", "_check_order",
                                                 "_check_simultaneous", "_check_energy", "_check_collapse")]
    kernels = [(tunnel, name) for name in ("grid_pairs", "pair_crossings", "_pinned_kernel")]
    with _timed(checks + kernels) as spent:
        table = audit.AUDIT_CHECKS  # the audit calls its checks through this table: the timed ones in it
        audit.AUDIT_CHECKS = tuple(replace(check, method=getattr(audit.Auditor, check.method.__name__))
                                   for check in table)
        try:
            started = time.perf_counter()
            api.run(scene, audit="full")
            whole = time.perf_counter() - started
        finally:
            audit.AUDIT_CHECKS = table
    step_end = spent.get("_end_step", 0.0)
    print(f"  run with --full-audit (timed): {1e3 * whole / steps:.2f} ms/step; the audit's step ends "
          f"{1e3 * step_end / steps:.2f} ms/step, of which:")
    for name, seconds in sorted(spent.items(), key=lambda kv: -kv[1]):
        if name != "_end_step":
            print(f"    {name:22s} {1e3 * seconds / steps:6.2f} ms/step")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=10000, help="box-rain spheres (0: skip)")
    parser.add_argument("--steps", type=int, default=240)
    parser.add_argument("--gas-count", type=int, default=1000, help="gas spheres (0: skip)")
    parser.add_argument("--gas-steps", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    if min(args.count, args.gas_count) < 0 or min(args.steps, args.gas_steps, args.rounds) < 1 \
            or (0 < args.count < 2) or (0 < args.gas_count < 2):
        parser.error("--count and --gas-count must be 0 (skip) or at least 2; --steps, --gas-steps and --rounds "
                     "at least 1")
    from physdbg.analysis.engines import box_rain_scene
    from physdbg.api import load_scene

    if args.count:
        measure(f"box-rain {args.count}", box_rain_scene(args.count, args.steps), args.steps, args.rounds)
    if args.gas_count:
        gas = load_scene("gas", [f"generate.count={args.gas_count}", "generate.packing_fraction=0.3",
                                 f"steps={args.gas_steps}"])
        measure(f"exact gas {args.gas_count} (packing 0.3)", gas, args.gas_steps, args.rounds)


if __name__ == "__main__":
    main()
