"""How a particle moves inside a step: the four integrators as paths.

Every integrator is written as a path from an *anchor* (position x, velocity v, path
acceleration a, all (3,) in m, m/s, m/s²) over a local time tau >= 0::

    position(tau)      = x + v * P1(tau) + a * P2(tau)
    path_velocity(tau) = v * dP1(tau) + a * dP2(tau)         (d position / d tau)
    velocity(tau)      = v * V0(tau) + a * V1(tau)           (the integrator's velocity)

with drag written as the seed writes it, v_new = v * d**t, and k = -ln(d) >= 0:

=============  ==========  ===========  ==========  ==========
integrator     P1          P2           V0          V1
=============  ==========  ===========  ==========  ==========
euler          tau         0            d**tau      tau
semi-implicit  tau         0            1           0     (velocity updated once, at step start)
verlet         tau         tau²/2       d**tau      tau
exact          phi1(tau)   phi2(tau)    e^(-k tau)  phi1(tau)
=============  ==========  ===========  ==========  ==========

phi1 = (1 - e^(-k tau)) / k and phi2 = (tau - phi1) / k are the closed form of
dv/dt = a - k v, which gives exactly v·d^t when a = 0 (phi1 -> tau, phi2 -> tau²/2 when
k = 0). dP1 = P1' = e^(-k tau) (1 without drag), and dP2 = P2' is P1 on the curved paths
(verlet, exact) and 0 on the straight ones (euler, semi-implicit: their position does not
follow the acceleration inside the step, their velocity does): ``path_acceleration_weight``.
So n·position(tau) has a second derivative of constant sign, which the swept tests in
:mod:`toi` rely on.

Explicit Euler moves on the straight line of its anchor velocity (the seed's
``P_new = P_old + v t``), semi-implicit on the straight line of the already-updated
velocity, Verlet on its parabola, exact on the true curve.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .broadphase.grid import cell_key, grid_frame
from .jit import borrowing, kernel

EULER = 0
SEMI_IMPLICIT = 1
VERLET = 2
EXACT = 3
INTEGRATOR_NAMES = ("euler", "semi-implicit", "verlet", "exact")

# What the rest of the engine asks about an integrator: one entry per integrator, indexed
# by its code, so a new integrator is its row here and its path in the functions below
# (path_coefficients, curvature_scale, velocity_coefficients), and nothing elsewhere
# branches on which integrator it is (docs/colliders.md, "Adding an integrator or a collider kind").
#   STRAIGHT_PATH       the position moves on the straight line of the anchor velocity
#                       inside a step (P2 = 0), whatever the acceleration does to v
#   KICK_AT_STEP_START  the velocity is updated once, before the paths (semi-implicit):
#                       the path acceleration is 0 and the velocity kick is the forces phase's
#   FLOW                re-anchoring mid-path leaves the path unchanged (without drag, index 0;
#                       with drag, index 1): Euler's straight line restarts from the new
#                       velocity, Verlet's parabola ignores drag's curve
#   REST_STEP_FACTOR    a straight path arrives at a rest with about one step of acceleration
#                       still in its velocity: how many dt of it count as resting (resting/)
#   POLYNOMIAL_WITH_DRAG  the path stays a polynomial in tau (P1 = tau) under drag too: its
#                       roots and extremes have closed forms at any drag (closed_form_path)
#   EXACT_UNDER         the forces under which the integrator's free flight is exact at any
#                       dt: "none", "gravity" or "gravity and drag" (the advisor's words)
#   FREE_FLIGHT_WEIGHTS (w0, w1): with no drag, a step with no contact moves a body by
#                       (w0·v_start + w1·v_end)·dt (check-run names a foreign run's integrator by it)
STRAIGHT_PATH = (True, True, False, False)
KICK_AT_STEP_START = (False, True, False, False)
FLOW = ((False, False), (True, True), (True, False), (True, True))
REST_STEP_FACTOR = (1.5, 1.5, 0.0, 0.0)
POLYNOMIAL_WITH_DRAG = (True, True, True, False)
EXACT_UNDER = ("none", "none", "gravity", "gravity and drag")
FREE_FLIGHT_WEIGHTS = ((1.0, 0.0), (0.0, 1.0), (0.5, 0.5), (0.5, 0.5))
INTEGRATOR_TABLES = {"STRAIGHT_PATH": STRAIGHT_PATH, "KICK_AT_STEP_START": KICK_AT_STEP_START, "FLOW": FLOW,
                     "REST_STEP_FACTOR": REST_STEP_FACTOR, "POLYNOMIAL_WITH_DRAG": POLYNOMIAL_WITH_DRAG,
                     "EXACT_UNDER": EXACT_UNDER, "FREE_FLIGHT_WEIGHTS": FREE_FLIGHT_WEIGHTS}


def check_integrator_tables(names=INTEGRATOR_NAMES, tables=None) -> None:
    """Raise ValueError naming each table above that has not one row per integrator name
    (an integrator added to INTEGRATOR_NAMES without its rows). Run at import."""
    tables = INTEGRATOR_TABLES if tables is None else tables
    short = [f"{name} has {len(rows)} rows" for name, rows in tables.items() if len(rows) != len(names)]
    if short:
        raise ValueError(f"engine/motion.py: {len(names)} integrators ({', '.join(names)}) but " + "; ".join(short)
                         + ": give each integrator its row in every table"
                         " (docs/colliders.md, \"Adding an integrator or a collider kind\")")


check_integrator_tables()

# Below this k*tau, phi1 and phi2 come from their Taylor series (truncation < 1e-17
# relative); above it the closed forms lose at most ~1e-14 to cancellation.
_SERIES_LIMIT = 1e-2


@borrowing
def path_coefficients(integrator, k, tau):
    """(P1, P2, dP1) of the table above at local time tau (s)."""
    if integrator == EXACT:
        if k == 0.0:
            return tau, 0.5 * tau * tau, 1.0
        kt = k * tau
        if kt < _SERIES_LIMIT:
            # phi1 = tau * sum (-kt)^n/(n+1)!, phi2 = tau² * sum (-kt)^n/(n+2)!
            s1 = 0.0
            s2 = 0.0
            term1 = 1.0  # (-kt)^n/(n+1)!
            term2 = 0.5  # (-kt)^n/(n+2)!
            for n in range(8):
                s1 += term1
                s2 += term2
                term1 *= -kt / (n + 2)
                term2 *= -kt / (n + 3)
            return tau * s1, tau * tau * s2, math.exp(-kt)
        phi1 = -math.expm1(-kt) / k
        return phi1, (tau - phi1) / k, math.exp(-kt)
    if integrator == VERLET:
        return tau, 0.5 * tau * tau, 1.0
    return tau, 0.0, 1.0


@njit(cache=True, inline="always")
def closed_form_path(integrator, k):
    """Whether the path is a polynomial in tau of degree <= 2 (P1 = tau, P2 = tau²/2 or
    0), so that its roots and extremes have closed forms: every path without drag
    (k = 0), and those of POLYNOMIAL_WITH_DRAG with it."""
    return k == 0.0 or POLYNOMIAL_WITH_DRAG[integrator]


@borrowing
def time_of_p1(integrator, k, u):
    """The local time tau (s) at which P1(tau) = u (the table above), or inf when the path
    never gets that far (drag stops it first): tau itself on a closed-form path, the
    inverse of phi1 on exact's curve under drag."""
    if closed_form_path(integrator, k):
        return u
    ku = k * u
    if ku >= 1.0:
        return math.inf
    return -math.log1p(-ku) / k


@njit(cache=True, inline="always")
def path_acceleration_weight(integrator, p1):
    """dP2 = d P2 / d tau from P1 (path_coefficients at the same tau): the path's velocity
    is v * dP1 + a * dP2 (the table above). P1 on the curved paths, 0 on the straight
    ones: on Euler's line it is the anchor velocity, not the integrator's v + a tau."""
    return 0.0 if STRAIGHT_PATH[integrator] else p1


@borrowing
def curvature_scale(integrator, k):
    """How the second derivative of n·position relates to (q, p) = (n·a, n·v).

    Returns (cq, cp) with  d²/dtau² (n·position) = (cq*q + cp*p) * (positive factor).
    """
    if integrator == EXACT:
        return 1.0, -k
    if integrator == VERLET:
        return 1.0, 0.0
    return 0.0, 0.0


@borrowing
def velocity_coefficients(integrator, drag, k, tau):
    """(V0, V1) of the table above: the integrator's velocity after tau seconds."""
    if integrator == EXACT:
        p1, _, e = path_coefficients(integrator, k, tau)
        return e, p1
    if integrator == SEMI_IMPLICIT:
        return 1.0, 0.0
    damp = 1.0 if drag == 1.0 else drag**tau
    return damp, tau


@borrowing
def kick(v, acc, drag, dt) -> None:
    """The velocity update of an integrator that kicks at a step's start
    (KICK_AT_STEP_START: semi-implicit Euler), in place: v <- v·d^dt + acc·dt for every
    row of v, acc (N, 3) (m/s, m/s²); drag d, dt (s). The one place it is written."""
    damp = 1.0 if drag == 1.0 else drag ** dt
    for i in range(v.shape[0]):
        for d in range(3):
            v[i, d] = v[i, d] * damp + acc[i, d] * dt


@borrowing
def advance_particle(x, v, a, sigma, i, to_time, integrator, drag, k) -> None:
    """Move particle i's anchor forward to time ``to_time`` in the step (s).

    x, v, a: (N, 3) anchor positions, velocities and path accelerations; sigma: (N,)
    time in the step of each anchor (s). Updated in place; an anchor already at or past
    ``to_time`` stays.
    """
    tau = to_time - sigma[i]
    if tau <= 0.0:
        return
    p1, p2, _ = path_coefficients(integrator, k, tau)
    v0, v1 = velocity_coefficients(integrator, drag, k, tau)
    for c in range(3):
        xc = x[i, c] + v[i, c] * p1 + a[i, c] * p2
        v[i, c] = v[i, c] * v0 + a[i, c] * v1
        x[i, c] = xc
    sigma[i] = to_time


@borrowing
def advance_particles(x, v, a, sigma, indices, to_time, integrator, drag, k) -> None:
    """advance_particle for each of ``indices`` (M,) int64."""
    for m in range(indices.shape[0]):
        advance_particle(x, v, a, sigma, indices[m], to_time, integrator, drag, k)


@borrowing
def particle_box(x, v, a, radius, sigma, i, step_end, integrator, k, margin, out_lo, out_hi):
    """AABB (out_lo, out_hi: (3,)) of particle i's path from its anchor to ``step_end``.

    Each coordinate of a path is convex or concave in tau, so its extremes are at the
    ends or at the one interior point where its derivative vanishes.
    """
    tau_end = step_end - sigma[i]
    if tau_end < 0.0:
        tau_end = 0.0
    p1e, p2e, _ = path_coefficients(integrator, k, tau_end)
    for c in range(3):
        x0 = x[i, c]
        x1 = x0 + v[i, c] * p1e + a[i, c] * p2e
        mn = min(x0, x1)
        mx = max(x0, x1)
        if a[i, c] != 0.0 and not STRAIGHT_PATH[integrator]:
            # interior extremum where v*dP1 + a*P1 = 0; bisection on the monotone derivative
            lo_t = 0.0
            hi_t = tau_end
            f_lo = v[i, c]
            q1, _, dq = path_coefficients(integrator, k, hi_t)
            f_hi = v[i, c] * dq + a[i, c] * q1
            if f_lo * f_hi < 0.0 and closed_form_path(integrator, k):
                # a parabola (P1 = tau, P2 = tau²/2): the extremum is at tau = -v/a, in
                # closed form (the bisection below took 1.6 µs a call, 60 steps on each axis)
                t_ext = min(max(-v[i, c] / a[i, c], 0.0), tau_end)
                e1, e2, _ = path_coefficients(integrator, k, t_ext)
                xe = x0 + v[i, c] * e1 + a[i, c] * e2
                mn = min(mn, xe)
                mx = max(mx, xe)
            elif f_lo * f_hi < 0.0:
                for _ in range(60):
                    mid = 0.5 * (lo_t + hi_t)
                    m1, _, dm = path_coefficients(integrator, k, mid)
                    f_mid = v[i, c] * dm + a[i, c] * m1
                    if f_mid * f_lo > 0.0:
                        lo_t = mid
                        f_lo = f_mid
                    else:
                        hi_t = mid
                for t_ext in (lo_t, hi_t):
                    e1, e2, _ = path_coefficients(integrator, k, t_ext)
                    xe = x0 + v[i, c] * e1 + a[i, c] * e2
                    mn = min(mn, xe)
                    mx = max(mx, xe)
        r = radius[i] + margin
        out_lo[c] = mn - r
        out_hi[c] = mx + r


@kernel
def _quantile_99(values):
    """np.quantile(values, 0.99) (its default, linear interpolation) to the bit, NaN if
    any value is NaN; values (N,), N >= 1. The two order statistics it needs are the
    smallest two of the m = N - k largest values (k = floor(0.99 (N - 1))), kept in a
    min-heap of m in one pass: O(N log m) at worst, about O(N) for speeds in no order.
    (np.partition did the same in O(N), but compiling it and the sorts its argument
    checks use took about 4 s of the cold compile.)"""
    n = values.shape[0]
    largest = -math.inf
    for i in range(n):
        if values[i] != values[i]:
            return math.nan
        largest = max(largest, values[i])
    virtual = (n - 1) * 0.99
    below = math.floor(virtual)
    if virtual >= n - 1:
        return largest
    gamma = virtual - below
    m = n - int(below)  # >= 2: the k-th smallest value onwards
    top = np.empty(m)  # a min-heap of the m largest values so far
    size = 0
    # visit the values with a stride near n / golden ratio, coprime to n (so each once): a
    # run of rising values (spheres numbered by height) comes in well mixed, not each one
    # displacing the heap's least (n log m: 5.2 ms for 100 000 rising speeds, 0.5 ms mixed)
    stride = max(1, int(0.6180339887 * n))
    while math.gcd(stride, n) != 1:
        stride += 1
    i = 0
    for _ in range(n):
        i += stride
        if i >= n:
            i -= n
        value = values[i]
        if size < m:
            c = size
            size += 1
            while c > 0 and top[(c - 1) // 2] > value:
                top[c] = top[(c - 1) // 2]
                c = (c - 1) // 2
            top[c] = value
        elif value > top[0]:
            c = 0
            while 2 * c + 1 < m:
                child = 2 * c + 1
                if child + 1 < m and top[child + 1] < top[child]:
                    child += 1
                if top[child] >= value:
                    break
                top[c] = top[child]
                c = child
            top[c] = value
    x = top[0]  # the k-th smallest of all
    y = top[1] if m == 2 else min(top[1], top[2])  # the (k+1)-th: the heap's second smallest
    step = y - x
    return y - step * (1.0 - gamma) if gamma >= 0.5 else x + step * gamma


@kernel
def grow_to_reach(x, v, a, radius, dt, margin, lo, hi):
    """Grow each swept box lo, hi (N, 3) to the cube x ± (reach + r + margin) with reach =
    max(own speed, min(the 99th-percentile speed, the fastest nearby)) · dt, speed = |v| +
    |a| dt (see World._add_reach, and nearby_fastest for "nearby"), in place; NaN speeds
    give NaN boxes, as numpy's would."""
    n = x.shape[0]
    if n == 0:
        return
    speed = np.empty(n)
    for i in range(n):
        speed[i] = (math.sqrt(v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2])
                    + math.sqrt(a[i, 0] * a[i, 0] + a[i, 1] * a[i, 1] + a[i, 2] * a[i, 2]) * dt)
    typical = _quantile_99(speed)
    nearby = nearby_fastest(x, speed, radius, typical, dt)
    for i in range(n):
        s = speed[i]
        others = nearby[i] if nearby[i] < typical else typical
        fastest = math.nan if (s != s or typical != typical) else (s if s > others else others)
        reach = fastest * dt + radius[i] + margin
        for c in range(3):
            low = x[i, c] - reach
            high = x[i, c] + reach
            if low != low or lo[i, c] != lo[i, c]:
                lo[i, c] = math.nan
            elif low < lo[i, c]:
                lo[i, c] = low
            if high != high or hi[i, c] != hi[i, c]:
                hi[i, c] = math.nan
            elif high > hi[i, c]:
                hi[i, c] = high


@kernel
def nearby_fastest(x, speed, radius, typical, dt):
    """(N,) for each sphere the largest speed (m/s) among the spheres in its own and the 26
    neighbouring cells of a grid of side 2·max(r) + 2·typical·dt (m) over the centres x
    (N, 3) (broadphase.grid's grid_frame and cell_key); typical for every sphere where no
    such grid is worth building (no finite centre, one far away, more cells than 8 N +
    4096, a zero cell). speed: (N,) m/s, a NaN counted as infinite.

    Why: a contact can only pass on the speed of a sphere that reaches this one in the
    step, and one that moves at most ``typical`` starts within a cell. A pile's depths,
    far under a rain still falling, need not have their boxes grown for the rain's speed
    (box-rain 100k's first second: 36 % fewer swept tests, docs/benchmarks.md); a path
    that does outrun its box is re-queried, as before, so no pair is missed.
    """
    n = x.shape[0]
    out = np.empty(n)
    out[:] = typical
    if n == 0 or typical != typical:
        return out
    largest_radius = 0.0
    for i in range(n):
        largest_radius = max(largest_radius, radius[i])
    cell = 2.0 * largest_radius + 2.0 * typical * dt
    if not cell > 0.0:
        return out
    origin = np.empty(3)
    dims = np.empty(3, dtype=np.int64)
    extent = grid_frame(x, cell, origin, dims)
    if not 0.0 <= extent < 1e6 * cell:  # no number, or one sphere far away
        return out
    cells = dims[0] * dims[1] * dims[2]
    if cells > 8 * n + 4096:
        return out
    in_cell = np.zeros(cells)  # the fastest speed in each cell
    # the fastest in each cell's neighbourhood, worked out once for a cell however many
    # spheres share it (-1: not yet; a pile has ~3 a cell: 372 -> 158 µs at 10 000 spheres)
    near = np.full(cells, -1.0)
    key = np.empty(n, dtype=np.int64)
    for i in range(n):
        key[i] = cell_key(x, i, origin, cell, dims)
        s = speed[i] if speed[i] == speed[i] else np.inf
        in_cell[key[i]] = max(in_cell[key[i]], s)
    plane = dims[1] * dims[2]
    for i in range(n):
        own = key[i]
        if near[own] < 0.0:
            cx = own // plane
            cy = (own // dims[2]) % dims[1]
            cz = own % dims[2]
            best = 0.0
            for bx in range(max(cx - 1, 0), min(cx + 2, dims[0])):
                for by in range(max(cy - 1, 0), min(cy + 2, dims[1])):
                    row = (bx * dims[1] + by) * dims[2]
                    for bz in range(max(cz - 1, 0), min(cz + 2, dims[2])):
                        best = max(best, in_cell[row + bz])
            near[own] = best
        out[i] = near[own]
    return out


@borrowing
def swept_boxes(x, v, a, radius, sigma, step_end, integrator, k, margin, lo, hi):
    """particle_box for every particle: lo, hi (N, 3) out, padded by radius + margin (m)."""
    for i in range(x.shape[0]):
        particle_box(x, v, a, radius, sigma, i, step_end, integrator, k, margin, lo[i], hi[i])
