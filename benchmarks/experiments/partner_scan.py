"""The re-prediction's core, replayed in four forms: is the event loop's time the memory's or the code's?

    .venv/bin/python benchmarks/experiments/partner_scan.py [--count 10000] [--step 200] [--spheres 400000]

Steps box-rain (benchmarks/box_rain.py's scene) to ``--step``, then replays the work the
loop does for each re-predicted sphere (timeline._repredict): scan its broad-phase
partners, keep those whose path box meets its own, and read what the pair test reads of
both (positions, velocities, path accelerations, radii), over the real partner lists, for
``--spheres`` spheres drawn at random among those with at least four partners. The test
itself is a stand-in of a few flops (approaching, and within a small gap), not the
engine's swept test: the point is the reads. Four forms of the same arithmetic on the
same data:

* ``numba``: one array per field, as the engine keeps them;
* ``numba, unsigned``: the same with unsigned indices (numba then drops the fix-up for
  negative indices it adds to every access with a signed one);
* ``numba, packed``: the same reads from one 128-byte row a sphere (positions,
  velocities, accelerations, radius) and one 64-byte row of its path box (a loop of its
  own: the first form's code on strided views of these rows measured ~30 % slower, numba's
  code for strided arrays, not the layout);
* ``C``: the first form in C (gcc -O2 -march=native, loaded with ctypes), if gcc is found.

Each must find the same hits (checked); prints nanoseconds per re-predicted sphere, best
of five. If the forms take about the same time, the time is the memory's (first touches
of scattered rows), not the compiler's (docs/benchmarks.md, "Measured and not kept").
"""

from __future__ import annotations

import argparse
import ctypes
import os
import shutil
import subprocess
import tempfile
import time

import numpy as np
from numba import njit, uint64

from physdbg.analysis.engines import box_rain_scene as box_rain  # noqa: E402

C_SOURCE = r"""
#include <stdint.h>
int64_t scan(const int64_t *seq, int64_t m, const int64_t *adj_start, const int64_t *adj, const double *x,
             const double *v, const double *a, const double *r, const double *lo, const double *hi, double h) {
    int64_t hits = 0;
    for (int64_t t = 0; t < m; t++) {
        int64_t p = seq[t];
        for (int64_t s = adj_start[p]; s < adj_start[p + 1]; s++) {
            int64_t q = adj[s];
            if (lo[3*p] > hi[3*q] || lo[3*q] > hi[3*p] || lo[3*p+1] > hi[3*q+1] || lo[3*q+1] > hi[3*p+1]
                || lo[3*p+2] > hi[3*q+2] || lo[3*q+2] > hi[3*p+2]) continue;
            double d0 = x[3*p] - x[3*q], d1 = x[3*p+1] - x[3*q+1], d2 = x[3*p+2] - x[3*q+2];
            double e0 = v[3*p] - v[3*q] + a[3*p] - a[3*q], e1 = v[3*p+1] - v[3*q+1] + a[3*p+1] - a[3*q+1];
            double e2 = v[3*p+2] - v[3*q+2] + a[3*p+2] - a[3*q+2];
            double radius_sum = r[p] + r[q];
            double b = d0*e0 + d1*e1 + d2*e2;
            double c = d0*d0 + d1*d1 + d2*d2 - radius_sum*radius_sum;
            if (b < 0 && c < h) hits++;
        }
    }
    return hits;
}
"""


def _scan_with(unsigned: bool):
    @njit(cache=False)
    def scan(seq, adj_start, adj, x, v, a, r, lo, hi, h):
        """Pairs (seq[t], partner) whose boxes meet, approaching and within h of touching."""
        hits = 0
        for t in range(seq.shape[0]):
            p = uint64(seq[t]) if unsigned else seq[t]
            for s in range(adj_start[p], adj_start[p + 1]):
                q = uint64(adj[s]) if unsigned else adj[s]
                if (lo[p, 0] > hi[q, 0] or lo[q, 0] > hi[p, 0] or lo[p, 1] > hi[q, 1] or lo[q, 1] > hi[p, 1]
                        or lo[p, 2] > hi[q, 2] or lo[q, 2] > hi[p, 2]):
                    continue
                d0 = x[p, 0] - x[q, 0]
                d1 = x[p, 1] - x[q, 1]
                d2 = x[p, 2] - x[q, 2]
                e0 = v[p, 0] - v[q, 0] + a[p, 0] - a[q, 0]
                e1 = v[p, 1] - v[q, 1] + a[p, 1] - a[q, 1]
                e2 = v[p, 2] - v[q, 2] + a[p, 2] - a[q, 2]
                radius_sum = r[p] + r[q]
                b = d0 * e0 + d1 * e1 + d2 * e2
                c = d0 * d0 + d1 * d1 + d2 * d2 - radius_sum * radius_sum
                if b < 0 and c < h:
                    hits += 1
        return hits
    return scan


# made once, at import: a compiled closure that is collected leaves a dead weak proxy
# among the collector's objects (numba's), which breaks a caller that walks them
_scan_signed = _scan_with(False)
_scan_unsigned = _scan_with(True)


@njit(cache=False)
def _scan_packed(seq, adj_start, adj, rows, boxes, h):
    """rows (N, 16): x, v, a, radius; boxes (N, 8): lo, hi."""
    hits = 0
    for p in seq:
        for s in range(adj_start[p], adj_start[p + 1]):
            q = adj[s]
            if (boxes[p, 0] > boxes[q, 3] or boxes[q, 0] > boxes[p, 3] or boxes[p, 1] > boxes[q, 4]
                    or boxes[q, 1] > boxes[p, 4] or boxes[p, 2] > boxes[q, 5] or boxes[q, 2] > boxes[p, 5]):
                continue
            d0 = rows[p, 0] - rows[q, 0]
            d1 = rows[p, 1] - rows[q, 1]
            d2 = rows[p, 2] - rows[q, 2]
            e0 = rows[p, 3] - rows[q, 3] + rows[p, 6] - rows[q, 6]
            e1 = rows[p, 4] - rows[q, 4] + rows[p, 7] - rows[q, 7]
            e2 = rows[p, 5] - rows[q, 5] + rows[p, 8] - rows[q, 8]
            radius_sum = rows[p, 9] + rows[q, 9]
            b = d0 * e0 + d1 * e1 + d2 * e2
            c = d0 * d0 + d1 * d1 + d2 * d2 - radius_sum * radius_sum
            if b < 0 and c < h:
                hits += 1
    return hits


def _c_scan(folder: str):
    """(the C form as a Python callable, None) or (None, why it was not built)."""
    if shutil.which("gcc") is None:
        return None, "gcc not found"
    source = os.path.join(folder, "scan.c")
    library = os.path.join(folder, "scan.so")
    with open(source, "w") as f:
        f.write(C_SOURCE)
    built = subprocess.run(["gcc", "-O2", "-march=native", "-shared", "-fPIC", "-o", library, source],
                           capture_output=True, text=True)
    if built.returncode != 0:
        errors = [line for line in built.stderr.splitlines() if "error" in line]
        why = errors[0].strip() if errors else f"exit status {built.returncode}"
        return None, f"gcc failed: {why}"
    scan = ctypes.CDLL(library).scan
    scan.restype = ctypes.c_int64
    scan.argtypes = [ctypes.c_void_p, ctypes.c_int64] + [ctypes.c_void_p] * 8 + [ctypes.c_double]

    def call(seq, adj_start, adj, x, v, a, r, lo, hi, h):
        return scan(seq.ctypes.data, seq.shape[0], *(array.ctypes.data for array in (adj_start, adj, x, v, a, r, lo,
                                                                                     hi)), h)
    return call, None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=10000)
    parser.add_argument("--step", type=int, default=200, help="the step whose partner lists are replayed")
    parser.add_argument("--spheres", type=int, default=400000, help="re-predicted spheres replayed")
    args = parser.parse_args()
    if args.count < 2 or args.step < 1 or args.spheres < 1:
        parser.error("--count must be at least 2, --step and --spheres at least 1")
    scene = box_rain(args.count, args.step)
    world = scene.build_world()
    for _ in range(args.step):
        world.step(scene.dt)
    ctx, st = world.last_step, world._st  # the world's own numbering, as the loop sees it
    data = [np.ascontiguousarray(array) for array in (ctx.adj_start, ctx.adj, st.positions, st.velocities,
                                                      ctx.path_accel, st.radius, ctx.path_lo, ctx.path_hi)]
    adj_start, adj, x, v, a, r, lo, hi = data
    busy = np.nonzero(np.diff(adj_start) >= 4)[0]
    if busy.size == 0:
        parser.error(f"no sphere has four partners at step {args.step}: take a later step or more spheres")
    seq = np.random.default_rng(0).choice(busy, args.spheres).astype(np.int64)
    rows = np.zeros((len(r), 16))  # 128 bytes a sphere
    rows[:, 0:3], rows[:, 3:6], rows[:, 6:9], rows[:, 9] = x, v, a, r
    boxes = np.zeros((len(r), 8))  # 64 bytes a sphere
    boxes[:, 0:3], boxes[:, 3:6] = lo, hi
    h = 1e-3
    with tempfile.TemporaryDirectory() as folder:
        forms = {"numba": lambda s: _scan_signed(s, *data, h), "numba, unsigned": lambda s: _scan_unsigned(s, *data, h),
                 "numba, packed": lambda s: _scan_packed(s, adj_start, adj, rows, boxes, h)}
        c_scan, not_built = _c_scan(folder)
        if c_scan is not None:
            forms["C"] = lambda s: c_scan(s, *data, h)
        hits = {}
        print(f"box-rain N={args.count}, step {args.step}: {args.spheres} re-predicted spheres, "
              f"{np.diff(adj_start)[seq].mean():.1f} partners each on average")
        for name, form in forms.items():
            form(seq[:2])  # compile
            best = float("inf")
            for _ in range(5):
                started = time.perf_counter()
                hits[name] = form(seq)
                best = min(best, time.perf_counter() - started)
            print(f"  {name:16s} {1e9 * best / args.spheres:7.1f} ns a sphere ({hits[name]} hits)")
        if c_scan is None:
            print(f"  C                (not run: {not_built})")
        if len(set(hits.values())) != 1:
            raise SystemExit(f"partner_scan.py: the forms found different hits: {hits}")


if __name__ == "__main__":
    main()
