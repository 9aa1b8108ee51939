"""The cold compile: every kernel compiled into an empty cache, timed (the ≤ 10 s target, docs/benchmarks.md).

    .venv/bin/python benchmarks/compile.py [--one-process] [--by-function [--top 40]] [--arguments]

Points ``NUMBA_CACHE_DIR`` at a new temporary folder (removed afterwards), then times
``physdbg.precompile.compile_kernels("grid", sleeping=True)``: what ``physdbg record`` and
``run`` do before their first step. By default on two processes when two CPUs are free;
``--one-process`` forces one. Prints the wall time and this process's CPU time (the
helper's is its own). ``--by-function`` (implies one process) lists each compiled
function's own time and with its callees, from numba's ``numba:compile`` events, the
largest first: where a cold compile goes. ``--arguments`` (instead) times numba compiling
a trivial function and one caller of it, taking 4, 16 or 40 arrays (the engine's kernels
take 10–45): what each array argument costs a compile, whatever the function does; and
the same pair taking the 16 arrays' data as one structured array (rows of 16 fields).
"""

from __future__ import annotations

import os
import shutil
import tempfile

# before physdbg is imported (it keeps a NUMBA_CACHE_DIR that is already set)
CACHE = tempfile.mkdtemp(prefix="physdbg-compile-")
os.environ["NUMBA_CACHE_DIR"] = CACHE

import argparse  # noqa: E402
import time  # noqa: E402


class _CompileTimes:
    """numba:compile events -> (own seconds, seconds with callees, function, depth)."""

    def __init__(self):
        from numba.core import event

        self.rows: list[tuple[float, float, str, int]] = []
        self._open: list[tuple[str, float, list[float]]] = []
        listener = self

        class Listener(event.Listener):
            def on_start(self, ev):
                function = ev.data["dispatcher"].py_func
                listener._open.append((f"{function.__module__}.{function.__qualname__}", time.perf_counter(), []))

            def on_end(self, ev):
                name, started, callees = listener._open.pop()
                total = time.perf_counter() - started
                listener.rows.append((total - sum(callees), total, name, len(listener._open)))
                if listener._open:
                    listener._open[-1][2].append(total)

        event.register("numba:compile", Listener())


def argument_cost() -> None:
    """Compile time of a trivial callee and its caller by the number of arrays they take."""
    import numpy as np
    from numba import njit

    def pair(tag: str, params: str, body: str, sites: int):
        """A fresh callee ``(i, params) -> body`` and a caller calling it ``sites`` times in a
        loop (fresh functions: nothing cached, nothing shared), compiled on first call."""
        calls = "".join(f"        out += callee_{tag}(i % 4, {params})\n" for _ in range(sites))
        source = (f"def callee_{tag}(i, {params}):\n    return {body}\n"
                  f"def caller_{tag}({params}):\n    out = 0.0\n    for i in range(8):\n{calls}    return out\n")
        space: dict = {}
        exec(source, space)
        space[f"callee_{tag}"] = njit(space[f"callee_{tag}"])  # the caller finds it in the same namespace
        return njit(space[f"caller_{tag}"])

    def arrays_pair(tag: str, arrays: int, sites: int):
        return pair(tag, ", ".join(f"a{i}" for i in range(arrays)), " + ".join(f"a{i}[i, 0]" for i in range(arrays)),
                    sites)

    def record_pair(tag: str, fields: int, sites: int):
        """The same pair taking one structured array of ``fields`` float fields instead."""
        return pair(tag, "r", " + ".join(f"r[i].f{k}" for k in range(fields)), sites)

    array = np.ones((4, 3))
    arrays_pair("warm", 2, 1)(array, array)  # numba's own first-use setup, not counted
    for arrays in (4, 16, 40):
        for sites in (1, 5):
            caller = arrays_pair(f"{arrays}_{sites}", arrays, sites)
            started = time.perf_counter()
            caller(*([array] * arrays))
            print(f"  {arrays:2d} arrays, {sites} call site{'s' if sites > 1 else ' '}: "
                  f"{time.perf_counter() - started:.2f} s to compile")
    rows = np.zeros(8, dtype=[(f"f{k}", np.float64) for k in range(16)])
    record_pair("warm", 16, 1)(rows)
    for sites in (1, 5):
        caller = record_pair(f"record_{sites}", 16, sites)
        started = time.perf_counter()
        caller(rows)
        print(f"  one structured array of 16 fields, {sites} call site{'s' if sites > 1 else ' '}: "
              f"{time.perf_counter() - started:.2f} s to compile")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--one-process", action="store_true", help="no helper process, even with two CPUs free")
    parser.add_argument("--by-function", action="store_true", help="each function's compile time (one process)")
    parser.add_argument("--top", type=int, default=40, help="functions --by-function lists (default 40)")
    parser.add_argument("--arguments", action="store_true", help="compile time by array arguments, alone")
    args = parser.parse_args()
    if args.top < 1:
        parser.error(f"--top must be at least 1, got {args.top}")
    try:
        if args.arguments:
            argument_cost()
            return
        times = _CompileTimes() if args.by_function else None
        from physdbg.precompile import compile_kernels, usable_cpus

        parallel = not (args.one_process or args.by_function)
        cpu = time.process_time()
        wall = compile_kernels("grid", sleeping=True, parallel=parallel)
        cpu = time.process_time() - cpu
        processes = "two processes" if parallel and usable_cpus() >= 2 else "one process"
        print(f"cold compile on {processes}: {wall:.1f} s wall, {cpu:.1f} s CPU in this process")
        if times is not None:
            print(f"{len(times.rows)} compiled functions; own s, with callees s, depth, function:")
            for own, total, name, depth in sorted(times.rows, reverse=True)[:args.top]:
                print(f"  {own:6.2f} {total:6.2f} {depth} {name}")
    finally:
        shutil.rmtree(CACHE, ignore_errors=True)


if __name__ == "__main__":
    main()
