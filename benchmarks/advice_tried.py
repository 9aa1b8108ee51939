"""The advisor held to its word: every advice physdbg gives that is a change of settings,
tried on the runs that earned it.

    .venv/bin/python benchmarks/advice_tried.py [--steps 60] [--try-steps 20] [--scenes bounce,ramp]

For each built-in scene and each example scene (docs/examples: *.toml, meshes/*.toml,
mistakes/*.toml), run with each method whose findings advise a change of settings
(detection = discrete, detection = sampled), it records the first ``--steps`` steps
(``--detail contacts``), audits the recording as ``physdbg explain --all`` does, and tries
each finding's advice on a fork of it (fork.try_advice: each kind's first finding per
change, from its step for ``--try-steps`` more). It prints one Markdown table row per
(finding kind, advice): in how many runs the advice was tried, in how many the finding
was gone from the fork, and the findings of that kind left in the forks' windows against
the runs' own; then the findings whose advice is not a change of settings, by kind, with
the advice's first words. The table in docs/check.md ("Advice, tried") is this script's
output.
"""

from __future__ import annotations

import argparse
import tempfile
from collections import Counter, defaultdict
from pathlib import Path

from physdbg import api
from physdbg.fork import try_advice
from physdbg.scenes import builtin_names

EXAMPLES = Path(__file__).resolve().parent.parent / "docs" / "examples"
METHODS = (("discrete", ["detection=discrete"]), ("sampled", ["detection=sampled"]))


def example_scenes() -> list[str]:
    """The example scenes a user can record (the damaged and foreign files are not scenes)."""
    found = [EXAMPLES / "thin-wall.toml", *sorted((EXAMPLES / "meshes").glob("*.toml")),
             *sorted((EXAMPLES / "mistakes").glob("*.toml"))]
    return [str(path) for path in found]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=60, help="steps recorded of each scene (default 60)")
    parser.add_argument("--try-steps", type=int, default=20, help="steps a try runs after the finding's (default 20)")
    parser.add_argument("--scenes", default="", help="comma-separated scenes instead of all of them")
    args = parser.parse_args()
    scenes = args.scenes.split(",") if args.scenes else [*builtin_names(), *example_scenes()]
    tried = defaultdict(lambda: {"runs": 0, "gone": 0, "left": 0, "left_in_run": 0, "where": []})
    untried = Counter()
    advice_of = {}
    with tempfile.TemporaryDirectory() as folder:
        for scene in scenes:
            label = Path(scene).stem
            for method, overrides in METHODS:
                path = Path(folder) / f"{label}-{method}.mcap"
                try:
                    api.record(scene, [*overrides, f"steps={args.steps}"], mcap_path=str(path), rrd=False,
                               detail="contacts", audit=False)
                except Exception as err:  # noqa: BLE001 (a scene that cannot run so is said, not fatal)
                    print(f"<!-- {label} {method}: not recorded: {err} -->")
                    continue
                report = api.explain(path, every_finding=True)
                for finding in report.findings:
                    if not finding.try_settings:
                        untried[finding.kind] += 1
                        advice_of.setdefault(finding.kind, finding.advice.split(":")[0].split(";")[0][:90])
                for t in try_advice(path, report, args.try_steps):
                    change = ", ".join(f"{k}={v}" for k, v in t["settings"].items())
                    row = tried[(t["kind"], change)]
                    row["runs"] += 1
                    row["gone"] += t["gone"]
                    row["left"] += t["left"]
                    row["left_in_run"] += t["left_in_run"]
                    row["where"].append(f"{label} ({method}, step {t['step']}{'' if t['gone'] else ': stays'})")
                print(f"<!-- {label} {method}: {report.counts or 'clean'} -->", flush=True)
    print()
    print("| finding | advice tried | runs | finding gone | its kind in the windows: forks / runs | where |")
    print("|---|---|---|---|---|---|")
    for (kind, change), row in sorted(tried.items()):
        print(f"| {kind} | {change} | {row['runs']} | {row['gone']} of {row['runs']} "
              f"({100 * row['gone'] / row['runs']:.0f} %) | {row['left']} / {row['left_in_run']} | "
              f"{'; '.join(row['where'])} |")
    print()
    print("| finding | findings whose advice is not a change of settings | the advice |")
    print("|---|---|---|")
    for kind, count in sorted(untried.items()):
        print(f"| {kind} | {count} | {advice_of[kind]} |")


if __name__ == "__main__":
    main()
