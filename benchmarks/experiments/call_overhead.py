"""What one call of a small compiled helper costs, compiled with and without numba's NRT.

    .venv/bin/python benchmarks/experiments/call_overhead.py [--calls 10000000]

The helper is resting._end's body (which sphere is at one end of a held contact), taking
the held-contact store, a NamedTuple of 17 arrays. Compiled the ordinary way (``kernel``)
it increfs and decrefs each of those arrays on every call, since its body branches and
numba prunes such pairs only in straight-line code; compiled ``borrowing`` (without NRT,
physdbg/engine/jit.py) it does not. Prints ns per call of each, and how many NRT calls
each one's optimised LLVM IR holds.
"""

from __future__ import annotations

import argparse
import time

from numba import njit

from physdbg.engine.resting import new_held
from physdbg.events import KIND_PAIR


def _end_body(h, c, e, pair_kind):
    if e == 0:
        return h.a[c]
    return h.other[c] if h.kind[c] == pair_kind else -1


with_nrt = njit(_end_body)
without_nrt = njit(_nrt=False)(_end_body)


@njit
def _calls(helper, h, n, reps):
    """reps·n calls of helper (a compiled function, passed in: one loop compiled per helper)."""
    total = 0
    for _ in range(reps):
        for c in range(n):
            total += helper(h, c, c & 1, KIND_PAIR)
    return total


def nrt_calls(dispatcher) -> int:
    """NRT_incref/NRT_decref calls in the dispatcher's own function of its optimised IR."""
    signature = next(iter(dispatcher.overloads))
    count = 0
    inside = False
    for line in dispatcher.inspect_llvm(signature).splitlines():
        if line.startswith("define "):
            inside = "_end_body" in line and "cpython" not in line and "cfunc" not in line
        elif line.startswith("}"):
            inside = False
        elif inside and "call" in line and ("@NRT_incref" in line or "@NRT_decref" in line):
            count += 1
    return count


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--calls", type=int, default=10_000_000)
    args = parser.parse_args()
    store = new_held(16, capacity=1000)
    reps = max(args.calls // 1000, 1)
    print(f"{'compiled':<22}{'ns/call':>9}{'NRT calls in IR':>17}")
    for name, helper in (("kernel (with NRT)", with_nrt), ("borrowing (no NRT)", without_nrt)):
        _calls(helper, store, 1000, 1)
        started = time.perf_counter()
        _calls(helper, store, 1000, reps)
        seconds = time.perf_counter() - started
        print(f"{name:<22}{1e9 * seconds / (reps * 1000):>9.1f}{nrt_calls(helper):>17}")


if __name__ == "__main__":
    main()
