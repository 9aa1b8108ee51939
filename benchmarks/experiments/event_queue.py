"""The event queue's cost per operation: the engine's binary heap against a 4-ary one.

    .venv/bin/python benchmarks/experiments/event_queue.py [--sizes 1000 5000 50000 500000] [--ops 1000000]

The time-ordered loop (engine/timeline.py) keeps every prediction that hits within the
step in a binary heap ordered by (time, test-log row) and drops stale ones as they come
out. At box-rain 10k a contact costs 2.3 pushes and 2.3 pops (the step stats' events per
contact; docs/benchmarks.md, "Where the time goes"). This replays the queue's work at a
steady size: fill it to ``size`` entries, then ``ops`` times pop the earliest and push a
later one, with the engine's ``heap_push``/``heap_pop`` and with a 4-ary heap (half the
levels, four children side by side) written here for the comparison. Both must pop the
same entries in the same order (checked on every run); prints nanoseconds per pop + push,
best of five, for each size.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from numba import njit

from physdbg.engine.timeline import COUNTERS, HEAP_SIZE, _precedes, heap_pop, heap_push

ARITY = 4


@njit(cache=True)
def _move(toi, data, to, source):
    """Entry ``source`` (time, row, batch) copied to slot ``to``."""
    toi[to] = toi[source]
    data[to, 0] = data[source, 0]
    data[to, 1] = data[source, 1]


@njit(cache=True)
def quaternary_push(toi, data, counters, t, rid, batch):
    """heap_push's contract on a 4-ary heap (children of i: 4i+1 .. 4i+4)."""
    n = counters[HEAP_SIZE]
    counters[HEAP_SIZE] = n + 1
    while n > 0:
        up = (n - 1) // ARITY
        if _precedes(t, rid, toi[up], data[up, 0]):
            _move(toi, data, n, up)
            n = up
        else:
            break
    toi[n] = t
    data[n, 0] = rid
    data[n, 1] = batch


@njit(cache=True)
def quaternary_pop(toi, data, counters):
    """heap_pop's contract on a 4-ary heap: the earliest entry moved just past the heap."""
    n = counters[HEAP_SIZE] - 1
    counters[HEAP_SIZE] = n
    last_t = toi[n]
    last_rid = data[n, 0]
    last_batch = data[n, 1]
    _move(toi, data, n, 0)
    i = 0
    while True:
        first = ARITY * i + 1
        if first >= n:
            break
        best = first
        for child in range(first + 1, min(first + ARITY, n)):
            if _precedes(toi[child], data[child, 0], toi[best], data[best, 0]):
                best = child
        if _precedes(toi[best], data[best, 0], last_t, last_rid):
            _move(toi, data, i, best)
            i = best
        else:
            break
    if n > 0:
        toi[i] = last_t
        data[i, 0] = last_rid
        data[i, 1] = last_batch
    return n


@njit(cache=False)
def churn(push, pop, toi, data, counters, gaps, size, ops, popped):
    """With the queue functions push and pop: fill to ``size``, then ``ops`` times pop the
    earliest and push it again a gap later; popped (ops,) <- the rows popped, in order."""
    for m in range(size):
        push(toi, data, counters, gaps[m % gaps.shape[0]], m, 0)
    row = size
    for m in range(ops):
        slot = pop(toi, data, counters)
        popped[m] = data[slot, 0]
        push(toi, data, counters, toi[slot] + gaps[row % gaps.shape[0]], row, 0)
        row += 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 5000, 50000, 500000])
    parser.add_argument("--ops", type=int, default=1_000_000)
    args = parser.parse_args()
    if min(args.sizes) < 1 or args.ops < 1:
        parser.error("--sizes and --ops must be positive")
    engines = {"binary (engine)": (heap_push, heap_pop), "4-ary": (quaternary_push, quaternary_pop)}
    gaps = np.random.default_rng(1).random(1 << 20)
    for size in args.sizes:
        line = [f"size {size:>7}:"]
        orders = []
        for name, (push, pop) in engines.items():
            toi = np.empty(size + 1)
            data = np.empty((size + 1, 2), dtype=np.int64)
            counters = np.zeros(COUNTERS, dtype=np.int64)
            popped = np.empty(args.ops, dtype=np.int64)
            churn(push, pop, toi, data, counters, gaps, 1, 1, popped)  # compile before timing
            best = float("inf")
            for _ in range(5):
                counters[:] = 0
                started = time.perf_counter()
                churn(push, pop, toi, data, counters, gaps, size, args.ops, popped)
                best = min(best, time.perf_counter() - started)
            orders.append(popped.copy())
            line.append(f"{name} {1e9 * best / args.ops:6.1f} ns")
        if not np.array_equal(orders[0], orders[1]):
            raise SystemExit(f"event_queue.py: the two heaps popped different orders at size {size}")
        print("  ".join(line) + "  per pop + push (same order popped)")


if __name__ == "__main__":
    main()
