"""The first ten minutes, timed: README commands on a fresh clone, venv and kernel cache.

    python3 benchmarks/first_run.py [--repo .] [--keep]

Clones the repository (its committed state) into a temporary folder, points
``XDG_CACHE_HOME`` at an empty folder there (so physdbg's numba cache starts cold; pip's
own download cache is this machine's, as a developer's would be), and runs, in order and
each timed as a whole process from the shell:

1. README command 1: ``python3 -m venv .venv && .venv/bin/pip install --no-compile -e . && .venv/bin/physdbg record bounce``;
2. ``physdbg record cradle``, ``physdbg record bullet-wall -s detection=discrete -o discrete.mcap --no-rrd``;
3. ``physdbg explain discrete.mcap``, ``physdbg diff recordings/ci/cradle.mcap recordings/cradle.mcap``;
4. ``physdbg check-run docs/examples/student-bounce.csv --scene bounce -s integrator=euler``;
5. after the background compile has ended: a second clone of the same commit (its own venv,
   the same cache), README command 1's install and then ``physdbg record bounce`` timed apart
   (its kernels are the first clone's: physdbg files numba's cache by the path inside the
   package, not by where the clone lives);
6. ``physdbg run rain -s generate.count=2000`` on the now warm cache, then again on an empty
   cache (a large cold run: compiled in the foreground).

Prints one table (the figures docs/benchmarks.md quotes, "The first run") with each
command's exit code and the tier its summary names.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

COMMANDS = [
    ("README command 1 (venv, install, record bounce)",
     "python3 -m venv .venv && .venv/bin/pip install -q --no-compile -e . && .venv/bin/physdbg record bounce"),
    ("record cradle", ".venv/bin/physdbg record cradle"),
    ("record bullet-wall (discrete)", ".venv/bin/physdbg record bullet-wall -s detection=discrete -o discrete.mcap "
                                      "--no-rrd"),
    ("explain discrete.mcap", ".venv/bin/physdbg explain discrete.mcap"),
    ("diff golden cradle vs new", ".venv/bin/physdbg diff recordings/ci/cradle.mcap recordings/cradle.mcap"),
    ("check-run student-bounce.csv", ".venv/bin/physdbg check-run docs/examples/student-bounce.csv --scene bounce "
                                     "-s integrator=euler"),
]


def timed(command: str, cwd: Path, env: dict) -> tuple[float, int, str]:
    started = time.perf_counter()
    done = subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    kernels = next((line.split(None, 1)[1] for line in done.stdout.splitlines() if line.startswith("kernels ")),
                   "compiled" if "compiled/loaded" in done.stdout else "")
    return seconds, done.returncode, kernels


def wait_for_background(limit: float = 900.0) -> float:
    """Seconds until no background compile (physdbg.tier) is running."""
    started = time.perf_counter()
    while time.perf_counter() - started < limit:
        found = subprocess.run(["pgrep", "-f", "physdbg.tier as t"], capture_output=True, text=True).stdout.strip()
        if not found:
            break
        time.sleep(1.0)
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", default=str(Path(__file__).resolve().parent.parent))
    parser.add_argument("--keep", action="store_true", help="Keep the temporary folder.")
    args = parser.parse_args()
    root = Path(tempfile.mkdtemp(prefix="physdbg-first-run-"))
    clone = root / "clone"
    subprocess.run(["git", "clone", "-q", args.repo, str(clone)], check=True)
    env = dict(os.environ, XDG_CACHE_HOME=str(root / "cache"))
    for key in ("NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT", "PHYSDBG_COMPILE", "VIRTUAL_ENV"):
        env.pop(key, None)
    rows = [(label, *timed(command, clone, env)) for label, command in COMMANDS]
    waited = wait_for_background()
    rows.append((f"(the background compile ended {waited:.0f} s after the last command)", 0.0, 0, ""))
    # a second clone of the same version on the same (now warm) cache, as a student who
    # clones again for the next assignment: its kernels are the first clone's
    second = root / "clone-2"
    subprocess.run(["git", "clone", "-q", args.repo, str(second)], check=True)
    rows.append(("second clone: venv and install", *timed(COMMANDS[0][1].rsplit(" && ", 1)[0], second, env)))
    rows.append(("second clone: record bounce", *timed(".venv/bin/physdbg record bounce", second, env)))
    rain = ".venv/bin/physdbg run rain -s generate.count=2000"
    rows.append(("run rain -s generate.count=2000, warm cache", *timed(rain, clone, env)))
    cold = dict(env, XDG_CACHE_HOME=str(root / "cache-2"))
    rows.append(("run rain -s generate.count=2000, cold cache", *timed(rain, clone, cold)))
    print(f"{'command':52s} {'s':>7s} {'exit':>4s}  kernels")
    for label, seconds, code, kernels in rows:
        print(f"{label:52s} {seconds:7.1f} {code:4d}  {kernels}")
    if not args.keep:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
