"""physdbg's exact gas against Smallenburg's EDMD, a C event-driven code, in collisions per
CPU-second, in one run.

    .venv/bin/python benchmarks/edmd.py --edmd PATH [--count 1000] [--packing 0.3] [--steps 200]
        [--edmd-time 100]

PATH is a checkout of https://github.com/FSmallenburg/EDMD (F. Smallenburg, "Efficient
event-driven simulations of hard spheres", Eur. Phys. J. E 45, 22 (2022)); its ``Single``
code is the one measured (neighbour lists with a shell, one event per particle in a block
calendar: the paper's fastest). The project holds no foreign code: the script copies
``Single/`` into a temporary folder, sets the parameters its README says to edit (the
globals at the top of ``mdSingle.c``: ``maxtime``; the thermostat off, so that it conserves
energy as physdbg's e = 1 gas does), builds it with its own Makefile (gcc ``-Ofast
-march=native``) and gives it physdbg's initial positions, in its units (σ = the spheres'
diameter), in the same periodic cube. EDMD draws its own velocities (Gaussian, kT = 1), so
its collisions per unit of simulated time differ from physdbg's; what is compared is the
cost of a collision. Both run on one core; CPU time is the process's (EDMD's includes
reading its input and printing a line each unit of time, a few ms).

physdbg runs the built-in ``gas`` scene with ``box.periodic = true`` (swept, time-ordered,
exact integrator, dt 0.01 s) for ``--steps`` steps, its kernels loaded first and not timed.
Prints each engine's pair collisions, CPU seconds and collisions per CPU-second, and their
ratio (docs/benchmarks.md, "Against an event-driven code").
"""

from __future__ import annotations

import argparse
import re
import resource
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

# the globals of mdSingle.c the benchmark sets (the README: "All simulation parameters are
# defined as global variables near the top of the main code file")
SETTINGS = {
    r"^double maxtime = [^;]*;": "double maxtime = {maxtime!r};",
    r"^const int usethermostat = [^;]*;": "const int usethermostat = 0;",
    r'^char inputfilename\[100\] = "[^"]*";': 'char inputfilename[100] = "init.sph";',
    r"^int initialconfig = [^;]*;": "int initialconfig = 0;",
}


def gas_scene(count: int, packing: float, steps: int, event_loop: str = "step"):
    from physdbg.api import load_scene

    return load_scene("gas", [f"generate.count={count}", f"generate.packing_fraction={packing}", f"steps={steps}",
                              "box.periodic=true", f"event_loop={event_loop}"])


def write_sph(scene, path: Path) -> None:
    """The scene's spheres in EDMD's .sph format: N, the box in σ, then 'a x y z radius' (σ units)."""
    world = scene.build_world()
    state = world.state
    sigma = 2.0 * float(state.radius[0])
    if not (state.radius == state.radius[0]).all():
        raise SystemExit("edmd.py compares equal spheres only")
    side = scene.walls.period / sigma
    lines = [str(state.count), " ".join(f"{s:.17g}" for s in side)]
    lines += [f"a {x:.17g} {y:.17g} {z:.17g} 0.5" for x, y, z in state.positions / sigma]  # EDMD wraps them into its box
    path.write_text("\n".join(lines) + "\n")


def build_edmd(source: Path, into: Path, maxtime: float) -> Path:
    """Copy EDMD's Single/ into ``into``, set its parameters (SETTINGS), build it; the program's path."""
    for name in ("mdSingle.c", "mdSingle.h", "mt19937ar.c", "Makefile"):
        shutil.copy(source / name, into / name)
    code = (into / "mdSingle.c").read_text()
    for pattern, line in SETTINGS.items():
        code, found = re.subn(pattern, line.format(maxtime=float(maxtime)), code, count=1, flags=re.M)
        if not found:
            raise SystemExit(f"{source / 'mdSingle.c'}: no line matching {pattern!r} to set (another version of "
                             f"EDMD? this script knows the one of github.com/FSmallenburg/EDMD)")
    (into / "mdSingle.c").write_text(code)
    if shutil.which("make") is None or shutil.which("gcc") is None:
        raise SystemExit("building EDMD needs make and gcc on the PATH")
    built = subprocess.run(["make", "-s"], cwd=into, capture_output=True, text=True)
    if built.returncode != 0:
        raise SystemExit(f"building EDMD failed (make in {into}):\n{built.stderr[-2000:]}")
    return into / "md"


def run_edmd(program: Path) -> tuple[int, float, str]:
    """Run it in its folder: (collisions, CPU seconds, its packing-fraction line)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([str(program)], cwd=program.parent, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"EDMD stopped with exit code {done.returncode}:\n{done.stdout[-2000:]}")
    counts = re.findall(r"Collisions: (\d+)", done.stdout)
    packing = re.findall(r"Packing fraction\s*: ([0-9.]+)", done.stdout)
    if not counts:
        raise SystemExit(f"EDMD printed no collision count:\n{done.stdout[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return int(counts[-1]), cpu, packing[-1] if packing else "?"


def run_physdbg(scene) -> tuple[int, float]:
    """(pair collisions, CPU seconds) of the scene's steps, its kernels loaded first."""
    from physdbg.engine.warm import warm_up
    from physdbg.events import KIND_PAIR

    world = scene.build_world()
    warm_up(world.broad_phase.name, calendar=world.settings.event_loop == "calendar")
    pairs = 0
    started = time.process_time()
    for _ in range(scene.steps):
        stats = world.step(scene.dt)
        kinds = world._buf.contacts["kind"][:stats.counts.contacts]  # the step's rows, read without observing
        pairs += int((kinds == KIND_PAIR).sum())
    return pairs, time.process_time() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--edmd", required=True, metavar="PATH", help="a checkout of github.com/FSmallenburg/EDMD")
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--packing", type=float, default=0.3)
    parser.add_argument("--steps", type=int, default=200, help="physdbg's steps of 0.01 s")
    parser.add_argument("--edmd-time", type=float, default=100.0, help="EDMD's run, in its time unit τ")
    args = parser.parse_args()
    source = Path(args.edmd).expanduser() / "Single"
    if not (source / "mdSingle.c").is_file():
        parser.error(f"--edmd {args.edmd}: no Single/mdSingle.c there (give a checkout of "
                     f"github.com/FSmallenburg/EDMD)")
    if args.count < 2 or args.steps < 1 or not 0.0 < args.packing <= 0.45 or not args.edmd_time > 0.0:
        parser.error("--count at least 2, --steps at least 1, --packing in (0, 0.45], --edmd-time > 0")
    scene = gas_scene(args.count, args.packing, args.steps)
    with tempfile.TemporaryDirectory(prefix="physdbg-edmd-") as folder:
        into = Path(folder)
        write_sph(scene, into / "init.sph")
        program = build_edmd(source, into, args.edmd_time)
        edmd_collisions, edmd_cpu, edmd_packing = run_edmd(program)
    edmd_rate = edmd_collisions / edmd_cpu
    print(f"hard-sphere gas, N = {args.count}, packing {args.packing}, periodic cube, one core")
    print(f"  EDMD (Single, {args.edmd_time:g} τ, packing {edmd_packing}): {edmd_collisions} collisions in "
          f"{edmd_cpu:.2f} s CPU: {edmd_rate:.3g}/s")
    for loop in ("step", "calendar"):  # physdbg's two event loops (docs/space-order.md, "The event calendar")
        ours, our_cpu = run_physdbg(gas_scene(args.count, args.packing, args.steps, loop))
        our_rate = ours / our_cpu
        print(f"  physdbg, event_loop = {loop} ({args.steps} steps of {scene.dt:g} s): {ours} pair collisions in "
              f"{our_cpu:.2f} s CPU: {our_rate:.3g}/s; EDMD per collision is {edmd_rate / our_rate:.2f}x faster "
              f"(target: at most 1.5x)")


if __name__ == "__main__":
    main()
