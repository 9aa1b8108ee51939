"""Memory layout for compiled loops: rows of fields against separate arrays (numba).

    .venv/bin/python benchmarks/experiments/layout.py [--rows 1000 200000]

A loop of 2 000 000 random row reads, each reading two fields of a row and writing a
third, over the same data held three ways: one structured array of rows (numba records,
80 bytes a row, like the held store's per-contact fields), one plain array per field, and
two 2-D arrays of columns (ints and floats, rows contiguous). Prints the best of five
runs of each, for each row count. The question it answers for packing the engine's
arrays into fewer (fewer arguments compile faster: ``benchmarks/compile.py --arguments``):
what a packed layout costs the loops that read a few fields of scattered rows.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from numba import njit

HELD_LIKE = np.dtype([("kind", np.int64), ("a", np.int64), ("other", np.int64), ("normal", np.float64, (3,)),
                      ("lam", np.float64), ("jv", np.float64), ("target", np.float64), ("seen", np.int64)])


@njit
def _records(rows, order):
    total = 0.0
    for t in range(order.shape[0]):
        c = order[t]
        if rows[c].other > 50:
            total += rows[c].lam
        rows[c].jv = total
    return total


@njit
def _arrays(other, lam, jv, order):
    total = 0.0
    for t in range(order.shape[0]):
        c = order[t]
        if other[c] > 50:
            total += lam[c]
        jv[c] = total
    return total


@njit
def _columns(ints, floats, order):
    total = 0.0
    for t in range(order.shape[0]):
        c = order[t]
        if ints[c, 2] > 50:
            total += floats[c, 3]
        floats[c, 4] = total
    return total


def best_of(function, args, runs: int = 5) -> float:
    times = []
    for _ in range(runs):
        started = time.perf_counter()
        function(*args)
        times.append(time.perf_counter() - started)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rows", type=int, nargs="+", default=[1000, 200_000])
    parser.add_argument("--reads", type=int, default=2_000_000)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    for n in args.rows:
        order = rng.integers(0, n, args.reads)
        rows = np.zeros(n, HELD_LIKE)
        rows["other"] = rng.integers(0, 100, n)
        rows["lam"] = rng.random(n)
        other, lam, jv = rows["other"].copy(), rows["lam"].copy(), np.zeros(n)
        ints, floats = np.zeros((n, 4), np.int64), np.zeros((n, 6))
        ints[:, 2], floats[:, 3] = other, lam
        cases = (("records (one structured array)", _records, (rows, order)),
                 ("one array per field", _arrays, (other, lam, jv, order)),
                 ("2-D columns (ints, floats)", _columns, (ints, floats, order)))
        print(f"{n} rows, {args.reads} random reads:")
        for name, function, call_args in cases:
            function(*call_args)  # compile first
            print(f"  {name}: {1000 * best_of(function, call_args):.1f} ms")


if __name__ == "__main__":
    main()
