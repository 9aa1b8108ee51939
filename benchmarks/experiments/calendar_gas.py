"""The exact gas with an event calendar that outlives the step: how fast the design of the
fastest hard-sphere codes runs in numba, before the engine is rebuilt on it.

    .venv/bin/python benchmarks/experiments/calendar_gas.py [--count 1000] [--steps 200]
        [--packing 0.3] [--shells 1.1 1.2 1.3 1.5 1.8] [--rounds 2]

Smallenburg's EDMD (docs/benchmarks.md, "Against an event-driven code") keeps, per sphere,
a path anchor (x, v, t₀) that only an event changes, a neighbour list of the spheres within
``shell``·σ of its *shell centre* (where it was when the list was made), and one event: the
earliest of a collision with a neighbour and leaving its shell (moving δ = (shell − 1)·σ/2
from the centre). Two spheres not on each other's lists are at least shell·σ = σ + 2δ apart
between centres, so neither can reach the other before one of them leaves its shell, and
then its list is made again from a grid of the centres. Steps are output points: the
positions at each step's end are read from the anchors, and nothing is predicted again.

This script runs that design on the built-in ``gas`` scene in a periodic box (the scene of
``benchmarks/edmd.py``), with the engine's own rules for what it shares with the engine (the
swept pair test ``toi.pair_toi_swept_scalar``, the impulse ``resolve.seed_impulse``, the
minimum image ``periodic.image``), and two queues of the per-sphere events: a binary heap
of the N minima (``heap``) and a calendar (``calendar``: buckets of a fixed width in time,
each an unordered list, the earliest found by a scan of the first non-empty bucket, events
past the calendar's year in an overflow list spread out again when the year turns). It
prints, for each shell and queue, pair collisions per second over the same simulated time
as the engine's time-ordered loop (run here too, in turns, best of ``--rounds``), and how
many collisions, shell crossings and stale pops it took. It also checks the design is
exact: the first collisions (pairs and times) must be the engine's.

A measurement, not a second engine: what it found is in docs/benchmarks.md, "An event
calendar that outlives the step".
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

from physdbg.engine.calendar import _before, _heap_fix, _link, _unlink  # the engine's heap and grid lists
from physdbg.engine.motion import INTEGRATOR_NAMES
from physdbg.engine.periodic import image
from physdbg.engine.resolve import seed_impulse
from physdbg.engine.toi import pair_toi_swept_scalar

if str(Path(__file__).resolve().parents[2]) not in sys.path:  # run as a script: benchmarks/ importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

EXACT = INTEGRATOR_NAMES.index("exact")
INF = math.inf
COLLIDE = 0
LEAVE_SHELL = 1
MOST_NEIGHBOURS = 96  # room in each list; a list that would overflow stops the run with an error
HEAP = 0
CALENDAR = 1
NONE = -1


# ------------------------------------------------------------------ the heap of per-sphere minima
# ------------------------------------------------------------------ the calendar
@njit(cache=True)
def _cal_unlink(cal_next, cal_prev, cal_head, cal_bucket, i):
    """Sphere i out of its bucket's list (the grid's linked lists: _unlink), if it is in one."""
    if cal_bucket[i] != NONE:
        _unlink(cal_head, cal_next, cal_prev, cal_bucket[i], i)
        cal_bucket[i] = NONE


@njit(cache=True)
def _cal_link(cal_next, cal_prev, cal_head, cal_bucket, i, b):
    cal_bucket[i] = b
    _link(cal_head, cal_next, cal_prev, b, i)


@njit(cache=True)
def _cal_place(when, cal, cal_next, cal_prev, cal_head, cal_bucket, i):
    """File sphere i's event in the bucket of its time (the last bucket is the overflow)."""
    _cal_unlink(cal_next, cal_prev, cal_head, cal_bucket, i)
    width, year_start, buckets = cal[0], cal[1], cal_head.shape[0] - 1
    k = (when[i] - year_start) / width
    b = int(k) if k < buckets else buckets
    if b < 0:
        b = 0
    _cal_link(cal_next, cal_prev, cal_head, cal_bucket, i, b)


@njit(cache=True)
def _cal_first(when, cal, cal_next, cal_prev, cal_head, cal_bucket, cursor):
    """The sphere with the earliest event (ties: the lower number): scan from the cursor's
    bucket to the first that is not empty; when the year is out, start the next year from
    the earliest overflow event and file the overflow again."""
    buckets = cal_head.shape[0] - 1
    while True:
        while cursor[0] < buckets and cal_head[cursor[0]] == NONE:
            cursor[0] += 1
        if cursor[0] < buckets:
            best = cal_head[cursor[0]]
            i = cal_next[best]
            while i != NONE:
                if _before(when, i, best):
                    best = i
                i = cal_next[i]
            return best
        first = INF  # a new year, from the earliest event in the overflow
        i = cal_head[buckets]
        while i != NONE:
            first = min(first, when[i])
            i = cal_next[i]
        if first == INF:
            return NONE
        cal[1] = first
        cursor[0] = 0
        i = cal_head[buckets]
        while i != NONE:
            following = cal_next[i]
            _cal_place(when, cal, cal_next, cal_prev, cal_head, cal_bucket, i)
            i = following


@njit(cache=True)
def _file(p, when, queue, heap, where, cal, cal_next, cal_prev, cal_head, cal_bucket):
    """Sphere p's event time changed: put it where it now belongs in the queue (at once:
    a heap fixed for several changed keys together is no heap)."""
    if queue == HEAP:
        _heap_fix(heap, where, when, p, heap.shape[0])
    else:
        _cal_place(when, cal, cal_next, cal_prev, cal_head, cal_bucket, p)


# ------------------------------------------------------------------ the gas
@njit(cache=True)
def _cell_of(c, i, period, cells):
    out = 0
    for d in range(3):
        k = int(math.floor(c[i, d] / period * cells)) % cells
        out = out * cells + k
    return out


@njit(cache=True, inline="always")
def _position(x, v, t0, i, t, d):
    return x[i, d] + v[i, d] * (t - t0[i])


@njit(cache=True)
def _anchor(x, v, t0, i, t, period):
    """Sphere i's anchor moved to time t along its path, wrapped into the box [0, period)."""
    for d in range(3):
        p = x[i, d] + v[i, d] * (t - t0[i])
        x[i, d] = p - period * math.floor(p / period)
    t0[i] = t


@njit(cache=True, inline="always")
def _near(d, length):
    """periodic.image of a separation of two spheres near the box (anchors wrapped into it,
    each sphere within its shell of them): the bits image computes (d - length, d + length
    or d), with a comparison for its floor."""
    if d > 0.5 * length:
        return d - length
    if d < -0.5 * length:
        return d + length
    return d


@njit(cache=True)
def _find_neighbours(i, c, head, nxt, cells, period, reach, nbr, count, symmetric):
    """i's list made again from the grid of shell centres: every j whose centre is within
    ``reach`` of i's; symmetric: also take i off the old neighbours' lists and put it on the
    new ones' (a rebuild; the first build makes every list whole)."""
    if symmetric:
        for s in range(count[i]):
            j = nbr[i, s]
            for q in range(count[j]):
                if nbr[j, q] == i:
                    count[j] -= 1
                    nbr[j, q] = nbr[j, count[j]]
                    break
    count[i] = 0
    k0 = int(math.floor(c[i, 0] / period * cells))
    k1 = int(math.floor(c[i, 1] / period * cells))
    k2 = int(math.floor(c[i, 2] / period * cells))
    for a in range(-1, 2):
        for b in range(-1, 2):
            for e in range(-1, 2):
                k = (((k0 + a) % cells) * cells + (k1 + b) % cells) * cells + (k2 + e) % cells
                j = head[k]
                while j != NONE:
                    if j != i:
                        d0 = image(c[i, 0] - c[j, 0], period)
                        d1 = image(c[i, 1] - c[j, 1], period)
                        d2 = image(c[i, 2] - c[j, 2], period)
                        if d0 * d0 + d1 * d1 + d2 * d2 < reach * reach:
                            if count[i] == MOST_NEIGHBOURS or (symmetric and count[j] == MOST_NEIGHBOURS):
                                raise ValueError("a neighbour list is full: a smaller shell")
                            nbr[i, count[i]] = j
                            count[i] += 1
                            if symmetric:
                                nbr[j, count[j]] = i
                                count[j] += 1
                    j = nxt[j]


@njit(cache=True)
def _collide(x, v, t0, i, j, now, period):
    """The pair's elastic collision at ``now``: both anchored there, the seed's impulse
    (e = 1, equal masses) along the line of centres."""
    _anchor(x, v, t0, i, now, period)
    _anchor(x, v, t0, j, now, period)
    n0 = _near(x[i, 0] - x[j, 0], period)
    n1 = _near(x[i, 1] - x[j, 1], period)
    n2 = _near(x[i, 2] - x[j, 2], period)
    norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    n0 /= norm
    n1 /= norm
    n2 /= norm
    closing = -((v[i, 0] - v[j, 0]) * n0 + (v[i, 1] - v[j, 1]) * n1 + (v[i, 2] - v[j, 2]) * n2)
    impulse = seed_impulse(closing, 1.0, 2.0)  # inverse masses 1 and 1: only the ratio matters
    v[i, 0] += impulse * n0
    v[i, 1] += impulse * n1
    v[i, 2] += impulse * n2
    v[j, 0] -= impulse * n0
    v[j, 1] -= impulse * n1
    v[j, 2] -= impulse * n2


@njit(cache=True)
def _predict_all(i, now, x, v, t0, c, nbr, count, sigma, delta, period, when, what, partner, partner_count,
                 stamp, q):
    """Sphere i's one event from ``now``: leaving its shell, or the earliest collision with
    a neighbour (the engine's swept pair test). A pair's next collision need be no one's
    event: i's event is never later than it, and whatever i's event turns out to be (a
    collision, a shell crossing, or stale when it pops) i is predicted again no later, with
    j, until the pair's collision is i's (or j changed and predicted it). Giving j the
    collision too when it was earlier than j's own event cost more heap work and more stale
    pops than it saved (3.58 against 3.99·10⁵ collisions/s at N = 1,000, shell 1.5).
    q: the queue (_file's arguments after ``when``; queue -1 before it is built), i's
    new event filed at once."""
    d0 = _near(x[i, 0] - c[i, 0], period)
    d1 = _near(x[i, 1] - c[i, 1], period)
    d2 = _near(x[i, 2] - c[i, 2], period)
    a = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2]
    b = d0 * v[i, 0] + d1 * v[i, 1] + d2 * v[i, 2]
    cc = d0 * d0 + d1 * d1 + d2 * d2 - delta * delta
    best = INF
    if a > 0.0:  # |x(t) - c| = delta, from i's anchor
        best = t0[i] + (-b + math.sqrt(max(b * b - a * cc, 0.0))) / a
    kind = LEAVE_SHELL
    other = NONE
    xi0 = _position(x, v, t0, i, now, 0)
    xi1 = _position(x, v, t0, i, now, 1)
    xi2 = _position(x, v, t0, i, now, 2)
    for s in range(count[i]):
        j = nbr[i, s]
        dx0 = _near(xi0 - _position(x, v, t0, j, now, 0), period)
        dx1 = _near(xi1 - _position(x, v, t0, j, now, 1), period)
        dx2 = _near(xi2 - _position(x, v, t0, j, now, 2), period)
        u = pair_toi_swept_scalar(dx0, dx1, dx2, v[i, 0] - v[j, 0], v[i, 1] - v[j, 1], v[i, 2] - v[j, 2],
                                  0.0, 0.0, 0.0, sigma, EXACT, 0.0, INF, 0.0)
        if u == INF:
            continue
        t = now + u
        if t < best:
            best = t
            kind = COLLIDE
            other = j
    when[i] = best
    what[i] = kind
    partner[i] = other
    partner_count[i] = stamp[other] if other != NONE else 0
    if q[0] >= 0:
        _file(i, when, q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7])


@njit(cache=True)
def run(x, v, radius, period, until, dt, shell, queue, most_collisions, first_pairs, first_times):
    """The gas from t = 0 to ``until`` (s): x, v (N, 3) m, m/s (changed in place: the state at
    ``until``); radius (m), equal for all; period (m) of the cubic box; dt: the output
    points' spacing (positions at every step end are read from the anchors, as a recording
    would); shell: the lists' reach over σ; queue HEAP or CALENDAR. first_pairs (K, 2),
    first_times (K,): the first K collisions, filled. Returns (collisions, shell crossings,
    stale pops, pops, a checksum of the output positions)."""
    n = x.shape[0]
    sigma = 2.0 * radius
    delta = 0.5 * (shell - 1.0) * sigma
    reach = shell * sigma
    cells = max(3, int(period / reach))
    t0 = np.zeros(n)
    for i in range(n):
        _anchor(x, v, t0, i, 0.0, period)  # into [0, period)
    c = x.copy()
    head = np.full(cells ** 3, NONE, dtype=np.int64)
    nxt = np.full(n, NONE, dtype=np.int64)
    prv = np.full(n, NONE, dtype=np.int64)
    cell = np.empty(n, dtype=np.int64)
    nbr = np.empty((n, MOST_NEIGHBOURS), dtype=np.int64)
    count = np.zeros(n, dtype=np.int64)
    stamp = np.zeros(n, dtype=np.int64)  # collisions each sphere took part in (stale events)
    when = np.full(n, INF)
    what = np.zeros(n, dtype=np.int64)
    partner = np.full(n, NONE, dtype=np.int64)
    partner_count = np.zeros(n, dtype=np.int64)
    for i in range(n):
        cell[i] = _cell_of(c, i, period, cells)
        _link(head, nxt, prv, cell[i], i)
    for i in range(n):
        _find_neighbours(i, c, head, nxt, cells, period, reach, nbr, count, False)
    # the queue
    heap = np.arange(n)
    where = np.arange(n)
    cal = np.array([0.0, 0.0])
    buckets = max(16, n)
    cal_head = np.full(buckets + 1, NONE, dtype=np.int64)
    cal_next = np.full(n, NONE, dtype=np.int64)
    cal_prev = np.full(n, NONE, dtype=np.int64)
    cal_bucket = np.full(n, NONE, dtype=np.int64)
    cursor = np.zeros(1, dtype=np.int64)
    unfiled = (np.int64(-1), heap, where, cal, cal_next, cal_prev, cal_head, cal_bucket)  # the queue is built after
    for i in range(n):
        _predict_all(i, 0.0, x, v, t0, c, nbr, count, sigma, delta, period, when, what, partner, partner_count,
                     stamp, unfiled)
    # a calendar bucket holds about one event: its width the mean time between events
    finite = when[when < INF]
    width = (finite.max() - finite.min()) / n if finite.shape[0] > 1 else dt
    cal[0] = width if width > 0.0 else dt
    cal[1] = finite.min() if finite.shape[0] else 0.0
    if queue == HEAP:
        for i in range(n):  # one at a time: the first i + 1 slots are a heap
            _heap_fix(heap, where, when, i, i + 1)
    else:
        for i in range(n):
            _cal_place(when, cal, cal_next, cal_prev, cal_head, cal_bucket, i)
    q = (np.int64(queue), heap, where, cal, cal_next, cal_prev, cal_head, cal_bucket)
    collisions = 0
    crossings = 0
    stale = 0
    pops = 0
    checksum = 0.0
    next_output = dt
    while True:
        i = heap[0] if queue == HEAP else _cal_first(when, cal, cal_next, cal_prev, cal_head, cal_bucket, cursor)
        now = when[i] if i != NONE else INF
        while next_output <= until and next_output <= now:  # a step's end: positions from the anchors
            for p in range(n):
                checksum += _position(x, v, t0, p, next_output, 0)
            next_output += dt
        if now > until:
            break
        pops += 1
        if what[i] == LEAVE_SHELL:
            crossings += 1
            _anchor(x, v, t0, i, now, period)
            _unlink(head, nxt, prv, cell[i], i)
            for d in range(3):
                c[i, d] = x[i, d]
            cell[i] = _cell_of(c, i, period, cells)
            _link(head, nxt, prv, cell[i], i)
            _find_neighbours(i, c, head, nxt, cells, period, reach, nbr, count, True)
            _predict_all(i, now, x, v, t0, c, nbr, count, sigma, delta, period, when, what, partner, partner_count,
                         stamp, q)
        else:
            j = partner[i]
            if stamp[j] != partner_count[i]:  # j collided since: predict i again from now
                stale += 1
                _predict_all(i, now, x, v, t0, c, nbr, count, sigma, delta, period, when, what, partner,
                             partner_count, stamp, q)
            else:
                if collisions < first_pairs.shape[0]:
                    first_pairs[collisions, 0] = min(i, j)
                    first_pairs[collisions, 1] = max(i, j)
                    first_times[collisions] = now
                collisions += 1
                _collide(x, v, t0, i, j, now, period)
                stamp[i] += 1
                stamp[j] += 1
                _predict_all(i, now, x, v, t0, c, nbr, count, sigma, delta, period, when, what, partner,
                             partner_count, stamp, q)
                _predict_all(j, now, x, v, t0, c, nbr, count, sigma, delta, period, when, what, partner,
                             partner_count, stamp, q)
                if collisions >= most_collisions:
                    break
    for p in range(n):  # the state at ``until``
        _anchor(x, v, t0, p, until, period)
    return collisions, crossings, stale, pops, checksum


# ------------------------------------------------------------------ the measurement
def engine_gas(scene, first: int):
    """The engine's time-ordered loop on the scene: (pair collisions, CPU seconds: edmd.py's
    run, the first ``first`` pair collisions as (pairs (K, 2) in the scene's numbering, times (K,) s))."""
    from physdbg.engine.warm import warm_up
    from physdbg.events import KIND_PAIR, Contacts
    from physdbg.observe import ListObserver

    seen = ListObserver()
    world = scene.build_world(seen)
    warm_up(world.broad_phase.name)
    pairs, times = [], []
    while len(pairs) < first and world.step_index < scene.steps:
        world.step(scene.dt)
        batch = seen.of_type(Contacts)[-1]
        for row in batch.rows:
            if row["kind"] == KIND_PAIR and len(pairs) < first:
                pairs.append(sorted((int(row["a"]), int(row["other"]))))
                times.append(world.time - scene.dt + float(row["time_in_step"]))
    from benchmarks.edmd import run_physdbg

    collisions, seconds = run_physdbg(scene)
    return collisions, seconds, np.array(pairs, dtype=np.int64).reshape(-1, 2), np.array(times)


def calendar_gas(scene, shell: float, queue: int, first: int, order: bool = True):
    """This design on the scene: (collisions, CPU seconds, crossings, stale, pops, first pairs, first times)."""
    state = scene.build_world().state
    x = state.positions.copy()
    v = state.velocities.copy()
    radius = float(state.radius[0])
    if not (state.radius == radius).all() or not (state.inverse_mass == state.inverse_mass[0]).all():
        raise SystemExit("calendar_gas.py runs equal spheres only")
    period = scene.walls.period
    if not (period > 0).all() or not (period == period[0]).all():
        raise SystemExit("calendar_gas.py runs a cubic periodic box only")
    pairs = np.zeros((first, 2), dtype=np.int64)
    times = np.zeros(first)
    started = time.process_time()
    if order:  # numbered in Morton order of where they start, as the engine numbers its spheres (space_order.py)
        from physdbg.engine.space_order import morton_order

        old_of_new = morton_order(x)
        x, v = x[old_of_new], v[old_of_new]
    collisions, crossings, stale, pops, _ = run(x, v, radius, float(period[0]), scene.steps * scene.dt, scene.dt,
                                                shell, queue, 1 << 62, pairs, times)
    seconds = time.process_time() - started
    if order:
        pairs = np.sort(old_of_new[pairs], axis=1)  # in the scene's numbering again
    return collisions, seconds, crossings, stale, pops, pairs[:min(first, collisions)], times[:min(first, collisions)]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--packing", type=float, default=0.3)
    parser.add_argument("--shells", type=float, nargs="+", default=[1.1, 1.2, 1.3, 1.5, 1.8])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--first", type=int, default=200, help="collisions compared with the engine's")
    args = parser.parse_args(argv)
    if args.count < 2 or args.steps < 1 or args.rounds < 1 or args.first < 1 or min(args.shells) <= 1.0:
        parser.error("--count at least 2, --steps, --rounds and --first at least 1, every shell above 1")
    from benchmarks.edmd import gas_scene

    scene = gas_scene(args.count, args.packing, args.steps)
    calendar_gas(gas_scene(args.count, args.packing, 2), args.shells[0], HEAP, 1)  # compiled, not timed
    calendar_gas(gas_scene(args.count, args.packing, 2), args.shells[0], CALENDAR, 1)
    best: dict = {}
    for _ in range(args.rounds):  # in turns: a slow spell of the machine falls on every one
        runs = [("engine", None, None)] + [(f"shell {s:g}, {q}", s, k) for s in args.shells
                                           for q, k in (("heap", HEAP), ("calendar", CALENDAR))]
        for label, shell, queue in runs:
            out = engine_gas(scene, args.first) if shell is None else calendar_gas(scene, shell, queue, args.first)
            if label not in best or out[1] < best[label][1]:
                best[label] = out
    engine = best["engine"]
    print(f"gas N={args.count}, packing {args.packing}, periodic, {scene.steps} steps of {scene.dt:g} s "
          f"({scene.steps * scene.dt:g} s), best of {args.rounds}:")
    print(f"  engine (time-ordered loop, steps): {engine[0]} collisions in {engine[1]:.3f} CPU s: "
          f"{engine[0] / engine[1]:.3g}/s")
    for label, out in best.items():
        if label == "engine":
            continue
        collisions, seconds, crossings, stale, pops, pairs, times = out
        k = min(len(pairs), len(engine[2]))
        same = bool(k) and (pairs[:k] == engine[2][:k]).all() and np.allclose(times[:k], engine[3][:k], rtol=1e-12,
                                                                               atol=1e-12)
        print(f"  {label:22s} {collisions} collisions in {seconds:.3f} CPU s: {collisions / seconds:.3g}/s "
              f"({engine[1] / seconds * collisions / engine[0]:.2f}x the engine a collision); "
              f"{crossings / max(collisions, 1):.2f} shell crossings, {stale / max(collisions, 1):.2f} stale pops "
              f"a collision; first {k} collisions the engine's: {'yes' if same else 'NO'}")


if __name__ == "__main__":
    main()
