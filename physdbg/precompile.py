"""Compiling the engine's kernels before a run: ``compile_kernels``, on two cores when it can.

A fresh cache compiles about 190 functions (numba: typing, lowering, LLVM): 65–80 s on
this project's 2-core machines, in one thread, nearly all of it in two call trees of
``engine.warm_up``'s world: the forces phase's held-contact solve (``settle_held`` and
the resting solve beneath it, about 40 %) and the rest of the step (the grid, the narrow
phase, the time-ordered loop). On a cold cache with a second CPU free, a helper process
compiles the first tree (``engine.warm.warm_up_held_solve``) while this one compiles the
second (``warm_up_without_forces``). Both write numba's on-disk cache (the folder
``physdbg`` names per version of the engine's sources), and numba looks there before it
compiles any function, callees included. The trees meet in one place, the resting solve,
which the loop's held solve calls: this process compiles all that needs no resting solve
first (~15 s) and the loop last, and reaches the resting solve some 23 s in, by when the
helper has cached it (its callees first). Then ``engine.warm_up`` runs as ever and loads
everything. (Waiting for the helper's resting solve before starting the loop was
measured, and lost: the loop's own part is the longer.) For an audited run (``physdbg
run``, ``record``) the helper then compiles the audit's step checker
(``analysis.audit.warm_up``, ~11 s alone), which its shorter share leaves room for; before,
the first audited step compiled it, and the run reported it as the audit's time a step.

No helper when only one CPU is this process's to use (``taskset``, a CI runner's quota),
when the cache already holds the held solve, or when ``parallel`` is False. It is waited
for (at most HELPER_TIMEOUT), never left running past the call, and killed if this
process is interrupted; if it fails (or is slow), this process compiles what it did not,
which costs time and changes nothing. Whichever process compiles a kernel, the machine
code is the same (the golden hashes do not move). Outside the engine, which starts no
processes.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from time import perf_counter

# The helper compiles for about half a minute here; a slow machine may take a few minutes.
# One still running after this long is stuck (a numba deadlock, a machine swapping): it is
# killed, and this process compiles what it did not.
HELPER_TIMEOUT = 900.0  # s


def compile_kernels(broad_phase: str | None = None, sleeping: bool = False, parallel: bool = True,
                    audit: bool = False, meshes: bool = False, calendar: bool = False) -> float:
    """``engine.warm_up(broad_phase, sleeping, meshes)``, on two processes when the cache is
    cold and two CPUs are free (module docstring); audit: also the audit's step checker
    (``analysis.audit.warm_up``, ~11 s cold; on the helper, after the held solve, where it
    fits in the time this process spends on the rest); returns the seconds taken."""
    from .engine.warm import warm_up, warm_up_without_forces

    started = perf_counter()
    helper = start_helper(audit) if parallel and cache_is_cold() and usable_cpus() >= 2 else None
    try:
        if helper is not None:
            warm_up_without_forces(broad_phase)
            try:
                helper.wait(timeout=HELPER_TIMEOUT)
            except subprocess.TimeoutExpired:
                pass  # killed below; warm_up compiles the rest
        warm_up(broad_phase, sleeping, meshes, calendar)
        if audit:
            from .analysis.audit import warm_up as warm_up_audit

            warm_up_audit()
    finally:
        if helper is not None and helper.poll() is None:  # interrupted or stuck: leave nothing running
            helper.kill()
            helper.wait()
    return perf_counter() - started


def cache_is_cold() -> bool:
    """Whether numba's cache holds no compiled held solve for these engine sources and this
    CPU (then it holds next to nothing): its index lists no version compiled for this
    machine's CPU name and features (numba's "magic tuple"; a folder filled on another CPU
    model is recompiled here, docs/compiling.md, "A cache for any CPU"), or the code it names
    is not there yet (numba writes the index first). Reads numba's cache object, an
    internal: should that change, the cache counts as warm, and kernels compile in one
    process as before."""
    from .engine.resolve import settle_held

    try:
        cache_file = settle_held._cache._cache_file
        here = this_cpu()
        versions = [name for key, name in cache_file._load_index().items() if key[1] == here]
        return not (versions and all(os.path.exists(cache_file._data_path(name)) for name in versions))
    except Exception:  # noqa: BLE001 - numba internals: fall back to the one-process compile
        return False


def this_cpu() -> tuple:
    """This machine's CPU as numba keys a cached kernel by it (its "magic tuple": target
    triple, CPU name, features; NUMBA_CPU_NAME=generic makes it the same on every machine)."""
    from numba.core.registry import cpu_target

    return cpu_target.target_context.codegen().magic_tuple()


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity, where the system tells it)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def helper_command(audit: bool = False) -> list[str]:
    """The helper's command line: this interpreter, with the folder this physdbg was
    imported from first on its path (so neither the working folder nor PYTHONPATH can put
    another physdbg before it: it compiles these very sources); the environment is
    inherited, so numba's cache folder is this process's. audit: the audit's step checker
    after the held solve."""
    root = str(Path(__file__).resolve().parent.parent)
    program = (f"import sys; sys.path.insert(0, {root!r}); "
               "from physdbg.engine.warm import warm_up_held_solve; warm_up_held_solve()")
    if audit:
        program += "; from physdbg.analysis.audit import warm_up; warm_up()"
    return [sys.executable, "-c", program]


def start_helper(audit: bool = False) -> subprocess.Popen | None:
    """The helper process, compiling the held solve (and the audit's checker); None if it
    cannot be started."""
    try:
        return subprocess.Popen(helper_command(audit), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    except OSError:
        return None
