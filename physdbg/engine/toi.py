"""Narrow phase: when does a sphere first touch a wall or another sphere inside a step?

Three detection methods (the seed's cases):

* ``swept``  exact time of impact along the integrator's path (:mod:`motion`);
* ``sampled`` k samples along the path, contact at the first overlapping sample (case c);
* ``discrete`` the end position only (case a) — ``sampled`` with k = 1.

A contact is only ever reported for a sphere that is *approaching*: a touching or
overlapping pair that separates is left alone, so a just-resolved contact is never
found again. All times returned are local (seconds after the start time of the test);
``INF`` means no contact before ``horizon``.

Sphere–wall (swept). With n the wall normal towards the sphere's side, the signed gap
g(tau) = n·position(tau) - d - r = g0 + p·P1 + q·P2 (p = n·v, q = n·a). For linear
paths this is the seed's ``t = (±r - ((n·C) - d)) / (n·v)``. In general g'' has one sign
over the whole step, so the first inward crossing is bracketed exactly (at most two
roots) and polished: closed-form quadratic when k = 0, safeguarded Newton otherwise.

Sphere–sphere (swept). The relative path D(tau) = dx + dv·P1 + da·P2. When both spheres
have the same path acceleration (da = 0: same gravity, or Euler's straight lines) D is
linear in u = P1(tau) and the seed's quadratic (v·v)u² + 2(v·s)u + (s·s - r²) = 0 gives
u exactly, then tau = P1⁻¹(u). Otherwise (a resting or immovable sphere against a
falling one) the gap |D| - R is advanced conservatively with a second-order lower
bound g(tau+s) >= g + g's - M s²/2, M = max|D''|: it converges like Newton and can never
step over the first root.
"""

from __future__ import annotations

import math


from .jit import borrowing, kernel
from .mesh.closest import closest_on_triangle
from .mesh.rigid_motion import in_body_frame
from .motion import STRAIGHT_PATH, closed_form_path, curvature_scale, path_coefficients, time_of_p1

INF = math.inf

SWEPT = 0
SAMPLED = 1
DISCRETE = 2
DETECTION_NAMES = ("swept", "sampled", "discrete")
# the most steps conservative advancement takes in one swept test against a triangle (a
# moving frame's spin shortens each step: its passes are what such a test costs)
MAX_PASSES = 500


@borrowing
def _gap(g0, p, q, integrator, k, tau):
    p1, p2, dp1 = path_coefficients(integrator, k, tau)
    return g0 + p * p1 + q * p2, p * dp1 + q * p1


@borrowing
def _root_in_bracket(g0, p, q, integrator, k, lo, hi):
    """The one root of the gap in [lo, hi], where the gap falls from >= 0 to <= 0."""
    if closed_form_path(integrator, k):
        # g0 + p*t + (q/2)*t² (q = 0 for Euler paths): numerically stable quadratic.
        aa = 0.0 if STRAIGHT_PATH[integrator] else 0.5 * q
        if aa == 0.0:
            t = -g0 / p if p != 0.0 else lo
        else:
            disc = p * p - 4.0 * aa * g0
            sq = math.sqrt(disc) if disc > 0.0 else 0.0
            qq = -0.5 * (p + sq) if p >= 0.0 else -0.5 * (p - sq)
            r1 = qq / aa
            r2 = g0 / qq if qq != 0.0 else r1
            # pick the root closest to the bracket (rounding may put it a hair outside)
            d1 = max(lo - r1, r1 - hi, 0.0)
            d2 = max(lo - r2, r2 - hi, 0.0)
            t = r1 if d1 < d2 or (d1 == d2 and r1 < r2) else r2
        return min(max(t, lo), hi)
    # drag: safeguarded Newton on the monotone bracket
    a_t = lo
    b_t = hi
    t = 0.5 * (lo + hi)
    for _ in range(100):
        g, dg = _gap(g0, p, q, integrator, k, t)
        if g > 0.0:
            a_t = t
        else:
            b_t = t
        if dg != 0.0:
            tn = t - g / dg
        else:
            tn = 0.5 * (a_t + b_t)
        if not (a_t < tn < b_t):
            tn = 0.5 * (a_t + b_t)
        if abs(tn - t) <= 1e-16 * max(1.0, abs(t)) or b_t - a_t <= 1e-16 * max(1.0, b_t):
            return tn
        t = tn
    return t


@borrowing
def _stationary_point(g0, p, q, integrator, k, horizon):
    """Where the gap's derivative (monotone, by the constant curvature) crosses zero."""
    if closed_form_path(integrator, k):
        return -p / q if q != 0.0 else horizon
    lo = 0.0
    hi = horizon
    _, d_lo = _gap(g0, p, q, integrator, k, lo)
    _, d_hi = _gap(g0, p, q, integrator, k, hi)
    if (d_hi > 0.0) == (d_lo > 0.0):
        return horizon  # the derivative keeps its sign over the whole horizon
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        _, d_mid = _gap(g0, p, q, integrator, k, mid)
        if (d_mid > 0.0) == (d_lo > 0.0):
            lo = mid
            d_lo = d_mid
        else:
            hi = mid
        if hi - lo <= 1e-16 * max(1.0, hi):
            break
    return 0.5 * (lo + hi)


@borrowing
def wall_toi_swept(g0, p, q, integrator, k, horizon):
    """First time in [0, horizon] the gap g0 + p·P1 + q·P2 crosses 0 going down, or INF.

    g0: gap at the start (m, negative = overlapping); p = n·v (m/s); q = n·a (m/s²).
    """
    if STRAIGHT_PATH[integrator]:
        q = 0.0
    cq, cp = curvature_scale(integrator, k)
    curv = cq * q + cp * p  # sign of g''
    if g0 <= 0.0:
        # touching or overlapping: a contact now if moving (or accelerating) inward
        if p < 0.0 or (p == 0.0 and curv < 0.0):
            return 0.0
        if curv >= 0.0:
            return INF  # separating and never coming back
        t_top = _stationary_point(g0, p, q, integrator, k, horizon)
        if t_top >= horizon:
            return INF
        g_top, _ = _gap(g0, p, q, integrator, k, t_top)
        if g_top <= 0.0:
            return t_top  # never left the overlap and is approaching again
        g_end, _ = _gap(g0, p, q, integrator, k, horizon)
        if g_end > 0.0:
            return INF
        return _root_in_bracket(g0, p, q, integrator, k, t_top, horizon)
    if curv >= 0.0:
        if p >= 0.0:
            return INF
        t_low = _stationary_point(g0, p, q, integrator, k, horizon) if curv > 0.0 else horizon
        t_low = min(t_low, horizon)
        g_low, _ = _gap(g0, p, q, integrator, k, t_low)
        if g_low > 0.0:
            return INF
        return _root_in_bracket(g0, p, q, integrator, k, 0.0, t_low)
    g_end, _ = _gap(g0, p, q, integrator, k, horizon)
    if g_end > 0.0:
        return INF
    return _root_in_bracket(g0, p, q, integrator, k, 0.0, horizon)


@borrowing
def wall_toi_sampled(g0, p, q, integrator, k, horizon, samples, depth):
    """First of ``samples`` evenly spaced instants in (0, horizon] with overlap and approach.

    depth: how far past contact (m, in gap terms) the sphere still overlaps the wall: INF
    for a one-sided wall (a half-space), 2·(r + h) for a two-sided slab. A sample beyond
    the slab is no overlap: the sphere is through, and the test is a miss (it tunnelled).
    """
    if STRAIGHT_PATH[integrator]:
        q = 0.0
    for m in range(1, samples + 1):
        t = horizon * m / samples
        g, dg = _gap(g0, p, q, integrator, k, t)
        if g < 0.0 and g > -depth and dg < 0.0:
            return t
    return INF


@borrowing
def _linear_pair_u(dx0, dx1, dx2, dv0, dv1, dv2, radius_sum):
    """The seed's quadratic: first u >= 0 with |dx + dv·u| = R while approaching, or INF."""
    a = dv0 * dv0 + dv1 * dv1 + dv2 * dv2
    b = dv0 * dx0 + dv1 * dx1 + dv2 * dx2
    c = dx0 * dx0 + dx1 * dx1 + dx2 * dx2 - radius_sum * radius_sum
    if b >= 0.0 or a == 0.0:
        return INF  # separating or at rest relative to each other
    if c <= 0.0:
        return 0.0  # touching or overlapping and approaching
    disc = b * b - a * c
    if disc < 0.0:
        return INF
    # smaller root (-b - sqrt(disc))/a written without cancellation
    return c / (-b + math.sqrt(disc))


@borrowing
def _relative_path(dx0, dx1, dx2, dv0, dv1, dv2, da0, da1, da2, integrator, k, t):
    """Relative position D(t) = dx + dv·P1 + da·P2 and its rate D'(t), as six floats."""
    p1, p2, dp1 = path_coefficients(integrator, k, t)
    return (dx0 + dv0 * p1 + da0 * p2, dx1 + dv1 * p1 + da1 * p2, dx2 + dv2 * p1 + da2 * p2,
            dv0 * dp1 + da0 * p1, dv1 * dp1 + da1 * p1, dv2 * dp1 + da2 * p1)


@borrowing
def _norm(x0, x1, x2):
    return math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)


@kernel
def pair_toi_swept(dx, dv, da, radius_sum, integrator, k, horizon, tolerance):
    """First time in [0, horizon] the spheres touch while approaching, or INF.

    dx, dv, da: (3,) relative position, path velocity and path acceleration (a - b)
    at the common start time; radius_sum: r_a + r_b (m); tolerance: gap (m) below which
    conservative advancement calls it a contact.
    """
    return pair_toi_swept_scalar(dx[0], dx[1], dx[2], dv[0], dv[1], dv[2], da[0], da[1], da[2], radius_sum,
                                 integrator, k, horizon, tolerance)


@borrowing
def pair_toi_swept_scalar(dx0, dx1, dx2, dv0, dv1, dv2, da0, da1, da2, radius_sum, integrator, k, horizon,
                          tolerance):
    """pair_toi_swept on scalars (the form the compiled loop calls: no arrays to pass)."""
    linear = STRAIGHT_PATH[integrator] or (da0 == 0.0 and da1 == 0.0 and da2 == 0.0)
    if linear:
        u = _linear_pair_u(dx0, dx1, dx2, dv0, dv1, dv2, radius_sum)
        if u == INF:
            return INF
        t = time_of_p1(integrator, k, u)
        return t if t <= horizon else INF
    # conservative advancement with a second-order bound
    # |D''| <= |cq·da + cp·dv| (curvature_scale: exact's curve bends by a − k·v)
    cq, cp = curvature_scale(integrator, k)
    m = _norm(cq * da0 + cp * dv0, cq * da1 + cp * dv1, cq * da2 + cp * dv2)
    t = 0.0
    for _ in range(500):
        if t > horizon:
            return INF
        d0, d1, d2, e0, e1, e2 = _relative_path(dx0, dx1, dx2, dv0, dv1, dv2, da0, da1, da2, integrator, k, t)
        dist = _norm(d0, d1, d2)
        rate = (d0 * e0 + d1 * e1 + d2 * e2) / dist if dist > 0.0 else -1.0
        step = _advance(dist - radius_sum, rate, (d0 * da0 + d1 * da1 + d2 * da2) < 0.0, m, tolerance, horizon)
        if step == 0.0:
            return t
        if step == INF:
            return INF
        t += step
    return t if t <= horizon else INF


@borrowing
def _advance(g, rate, pulled_in, m, tolerance, horizon):
    """Conservative advancement's next move, for a gap g (m) changing at ``rate`` (m/s)
    whose second derivative is at least -m (m/s²): 0.0 when it touches now (within
    ``tolerance``, approaching, or at rest and ``pulled_in`` by the path's acceleration);
    INF when it can never touch; else the longest step (s) the bound g + rate·s - m·s²/2
    allows before the gap could reach zero (or, separating from a touch, return to it).
    The one rule of the sphere pairs' and the triangles' swept tests."""
    if g <= tolerance:
        if rate < 0.0 or (rate == 0.0 and pulled_in):
            return 0.0
        if m == 0.0:
            return INF
        # separating from a touch: the bound says it cannot return before this
        gg = max(g, 0.0)
        return (rate + math.sqrt(rate * rate + 2.0 * m * gg)) / m + 1e-15 * max(horizon, 1.0)
    if rate < 0.0:
        return 2.0 * g / (math.sqrt(rate * rate + 2.0 * m * g) - rate)
    if m == 0.0:
        return INF
    return (rate + math.sqrt(rate * rate + 2.0 * m * g)) / m


@kernel
def pair_toi_sampled(dx, dv, da, radius_sum, integrator, k, horizon, samples):
    """First of ``samples`` instants in (0, horizon] with overlap while approaching."""
    return pair_toi_sampled_scalar(dx[0], dx[1], dx[2], dv[0], dv[1], dv[2], da[0], da[1], da[2], radius_sum,
                                   integrator, k, horizon, samples)


@borrowing
def pair_toi_sampled_scalar(dx0, dx1, dx2, dv0, dv1, dv2, da0, da1, da2, radius_sum, integrator, k, horizon,
                            samples):
    """pair_toi_sampled on scalars."""
    if STRAIGHT_PATH[integrator]:
        da0 = 0.0
        da1 = 0.0
        da2 = 0.0
    for m in range(1, samples + 1):
        t = horizon * m / samples
        d0, d1, d2, e0, e1, e2 = _relative_path(dx0, dx1, dx2, dv0, dv1, dv2, da0, da1, da2, integrator, k, t)
        if d0 * d0 + d1 * d1 + d2 * d2 < radius_sum * radius_sum and d0 * e0 + d1 * e1 + d2 * e2 < 0.0:
            return t
    return INF



# ----------------------------------------------------------------------------- sphere–triangle
# A triangle is a convex set, so the distance f(x) from a point to it is convex and has unit
# gradient n = (x − q)/|x − q| (q its closest point): along the centre's path x(tau) the gap
# g = f(x) − r has g'' = x'ᵀ∇²f x' + n·x'' ≥ −|x''| ≥ −M, the same second-order lower bound
# as a sphere pair's, so the same conservative advancement can never step over the first
# touch, converges like Newton when approaching head-on, and finds a face, an edge or a
# corner alike (the closest point's feature says which).


@borrowing
def _center_path(x0, x1, x2, v0, v1, v2, a0, a1, a2, integrator, k, t):
    """The centre at local time t and its rate, as six floats (x + v·P1 + a·P2)."""
    return _relative_path(x0, x1, x2, v0, v1, v2, a0, a1, a2, integrator, k, t)


@borrowing
def _from_triangle(p0, p1, p2, tri):
    """(d0, d1, d2, feature): from the point of triangle ``tri`` (3, 3) closest to p to p,
    and the feature it lies on (mesh.closest)."""
    q0, q1, q2, feature = closest_on_triangle(p0, p1, p2, tri[0, 0], tri[0, 1], tri[0, 2], tri[1, 0], tri[1, 1],
                                              tri[1, 2], tri[2, 0], tri[2, 1], tri[2, 2])
    return p0 - q0, p1 - q1, p2 - q2, feature


@borrowing
def triangle_toi_swept(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, integrator, k, horizon, tolerance):
    """(t, feature, passes): the first local time in [0, horizon] a sphere (centre x + v·P1
    + a·P2, ``radius`` m) touches the fixed triangle ``tri`` (3, 3: corners as rows, m)
    while approaching it, and the feature touched (closest.FACE, an edge or a corner);
    (INF, -1) when it does not; passes: the advancement's steps taken (its cost).
    ``tolerance`` (m): the gap below which it counts as touching."""
    return _triangle_toi_swept(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, False, tri[0], 0.0, integrator, k,
                               horizon, tolerance)


@borrowing
def triangle_toi_sampled(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, integrator, k, horizon, samples):
    """(t, feature, y0, y1, y2): the first of ``samples`` instants in (0, horizon] at which
    the sphere overlaps the triangle while approaching it (the seed's case c; ``samples`` =
    1 is the discrete test), or (INF, -1, ...), and where the centre is then (m; for a
    moving triangle, seen from its mesh as it stood at the step's start): a mesh's
    collider asks whether this triangle is the mesh's nearest there."""
    return _triangle_toi_sampled(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, False, tri[0], 0.0, integrator, k,
                                 horizon, samples)


# ------------------------------------------------------------------ sphere–moving triangle
# A kinematic mesh moves rigidly: its pivot P at v_m and its body turning at ω about it. In
# the body's frame (the triangle's corners frozen where they were at the step's start) the
# centre is y(τ) = R(-ω·τ)(x - P - v_m·τ) + P, τ the time since the step began, and the
# triangle is fixed, so the distance is convex in y as above and g'' >= -|y''|. With
# z = x - P - v_m·τ, y'' = R(-ω·τ)(x'' - 2ω×z' + ω×(ω×z)) (Coriolis and centripetal), so
# |y''| <= |x''| + 2|ω|·|z'| + |ω|²·|z| bounds the curvature over the test's horizon by
# the bounds of |z'| and |z| over it: the same conservative advancement (_advance) then
# never steps over the first touch of a moving triangle either.


@borrowing
def moving_triangle_toi_swept(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, motion, tau0, integrator, k,
                              horizon, tolerance):
    """(t, feature, passes): triangle_toi_swept for a triangle of a moving mesh: ``tri`` (3, 3) its
    corners at the step's start, ``motion`` (9,) as in_body_frame's, ``tau0`` (s) the
    sphere's anchor time in the step (the test's local time t is at tau0 + t)."""
    return _triangle_toi_swept(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, True, motion, tau0, integrator, k,
                               horizon, tolerance)


@borrowing
def moving_triangle_toi_sampled(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, motion, tau0, integrator, k,
                                horizon, samples):
    """(t, feature, y0, y1, y2): triangle_toi_sampled for a triangle of a moving mesh
    (arguments as moving_triangle_toi_swept's): overlap and approach judged in the mesh's
    frame."""
    return _triangle_toi_sampled(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, True, motion, tau0, integrator, k,
                                 horizon, samples)


@borrowing
def _seen_from_triangle(p0, p1, p2, e0, e1, e2, moving, motion, tau):
    """A centre and its rate as the triangle sees them: themselves for a fixed triangle, in
    the mesh's frame (in_body_frame) for a moving one."""
    if moving:
        return in_body_frame(p0, p1, p2, e0, e1, e2, motion, tau)
    return p0, p1, p2, e0, e1, e2


@borrowing
def _triangle_toi_swept(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, moving, motion, tau0, integrator, k,
                        horizon, tolerance):
    """The swept test against a fixed or (``moving``) a moving triangle: conservative
    advancement (_advance) on the gap seen from the triangle, with the path's curvature
    bound, plus the frame's Coriolis and centripetal terms when it moves (section doc).
    Returns (t, feature, passes): passes, how many steps of the advancement it took (at
    most MAX_PASSES), is its cost, which grows with a moving frame's spin."""
    if STRAIGHT_PATH[integrator]:
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
    cq, cp = curvature_scale(integrator, k)
    m = _norm(cq * a0 + cp * v0, cq * a1 + cp * v1, cq * a2 + cp * v2)
    if moving:
        # bounds over the horizon: |x'| <= |v| + |x''|·h, |z'| <= that + |v_m|, |z| <= |z(0)| + |z'|·h
        rate_bound = _norm(v0, v1, v2) + m * horizon + _norm(motion[3], motion[4], motion[5])
        z_bound = _norm(x0 - motion[0] - motion[3] * tau0, x1 - motion[1] - motion[4] * tau0,
                        x2 - motion[2] - motion[5] * tau0) + rate_bound * horizon
        spin = _norm(motion[6], motion[7], motion[8])
        m = m + 2.0 * spin * rate_bound + spin * spin * z_bound
    t = 0.0
    feature = -1
    for passes in range(1, MAX_PASSES + 1):
        if t > horizon:
            return INF, -1, passes
        p0, p1, p2, e0, e1, e2 = _center_path(x0, x1, x2, v0, v1, v2, a0, a1, a2, integrator, k, t)
        y0, y1, y2, r0, r1, r2 = _seen_from_triangle(p0, p1, p2, e0, e1, e2, moving, motion, tau0 + t)
        d0, d1, d2, feature = _from_triangle(y0, y1, y2, tri)
        dist = _norm(d0, d1, d2)
        rate = (d0 * r0 + d1 * r1 + d2 * r2) / dist if dist > 0.0 else -1.0
        # pulled in: the path's own acceleration towards the triangle (a moving frame's is in m)
        step = _advance(dist - radius, rate, (d0 * a0 + d1 * a1 + d2 * a2) < 0.0, m, tolerance, horizon)
        if step == 0.0:
            return t, feature, passes
        if step == INF:
            return INF, -1, passes
        t += step
    if t <= horizon:
        return t, feature, MAX_PASSES
    return INF, -1, MAX_PASSES


@borrowing
def _triangle_toi_sampled(x0, x1, x2, v0, v1, v2, a0, a1, a2, radius, tri, moving, motion, tau0, integrator, k,
                          horizon, samples):
    """The sampled test against a fixed or (``moving``) a moving triangle: overlap and
    approach at each sample, seen from the triangle; (t, feature, y0, y1, y2) as
    triangle_toi_sampled's."""
    if STRAIGHT_PATH[integrator]:
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
    for s in range(1, samples + 1):
        t = horizon * s / samples
        p0, p1, p2, e0, e1, e2 = _center_path(x0, x1, x2, v0, v1, v2, a0, a1, a2, integrator, k, t)
        y0, y1, y2, r0, r1, r2 = _seen_from_triangle(p0, p1, p2, e0, e1, e2, moving, motion, tau0 + t)
        d0, d1, d2, feature = _from_triangle(y0, y1, y2, tri)
        if d0 * d0 + d1 * d1 + d2 * d2 < radius * radius and d0 * r0 + d1 * r1 + d2 * r2 < 0.0:
            return t, feature, y0, y1, y2
    return INF, -1, 0.0, 0.0, 0.0
