"""A large held-contact cluster solved as a bound-constrained quadratic program (MPRGP).

The held contacts' complementarity problem (resting/) is: multipliers x (m,) with
x >= lower, and relative normal values rel(x) = rel0 + K (x - x0) that end >= target,
equal to it wherever x > lower, with K = J W Jᵀ (m, m) symmetric positive semidefinite.
That is the optimality condition of

    minimise ½ xᵀ K x - bᵀ x  subject to  x >= lower,

whose gradient g(x) = rel(x) - target. Projected Gauss–Seidel (resting._gauss_seidel)
solves it at a rate set by K's conditioning: a pile ten spheres deep takes hundreds of
sweeps per impact, and a jammed pile of 500 spheres took 16 000–130 000 updates per solve
(`benchmarks/rain_pile.py`, docs/benchmarks.md). Conjugate gradients need about the
square root of that. MPRGP (modified proportioning with reduced gradient projections,
Dostál & Schöberl, Comput. Optim. Appl. 30, 23 (2005); Dostál, *Optimal Quadratic
Programming Algorithms*, Springer 2009, ch. 8) is conjugate gradients on the free
contacts, with a projected step when a contact reaches its bound and a proportioning
step that frees a contact whose bound holds it wrongly. It converges for any positive
semidefinite K whose problem has a solution, and needs only products K·d.

K is never formed: K·d is two passes over the contacts through the spheres
(u_p = w_p Σ ±n_c d_c, then (K d)_c = n_c·(u_a - u_b)), so one product costs about
what one Gauss–Seidel sweep does. The variables are scaled by sqrt(diag K) (Jacobi
scaling, which keeps the bounds simple bounds) so that walls, whose contacts have half
the diagonal of a pair's, do not slow it.

Pure numeric code on arrays: it knows nothing of the held-contact store, which
resting/ gathers into these arrays and writes back.
"""

from __future__ import annotations

import math

import numpy as np

from .jit import borrowing, kernel

# The gradient is recomputed from the multipliers every this many iterations (the
# recurrence drifts by rounding), and always before the answer is accepted.
REFRESH_EVERY = 50


@borrowing
def _product(end_a, end_b, normal, inverse_mass, scale, d, u, out) -> None:
    """out = S⁻¹ K S⁻¹ d for the scaled variables (S = diag(scale)); u (n_spheres, 3) scratch."""
    m = d.shape[0]
    u[:, :] = 0.0
    for r in range(m):
        f = d[r] / scale[r]
        if f == 0.0:
            continue
        p = end_a[r]
        if p >= 0:
            wp = f * inverse_mass[p]
            u[p, 0] += wp * normal[r, 0]
            u[p, 1] += wp * normal[r, 1]
            u[p, 2] += wp * normal[r, 2]
        q = end_b[r]
        if q >= 0:
            wq = f * inverse_mass[q]
            u[q, 0] -= wq * normal[r, 0]
            u[q, 1] -= wq * normal[r, 1]
            u[q, 2] -= wq * normal[r, 2]
    for r in range(m):
        acc = 0.0
        p = end_a[r]
        if p >= 0:
            acc += normal[r, 0] * u[p, 0] + normal[r, 1] * u[p, 1] + normal[r, 2] * u[p, 2]
        q = end_b[r]
        if q >= 0:
            acc -= normal[r, 0] * u[q, 0] + normal[r, 1] * u[q, 1] + normal[r, 2] * u[q, 2]
        out[r] = acc / scale[r]


@borrowing
def _along(end_a, end_b, normal, inverse_mass, scale, d, u, kd, g):
    """kd = K·d (scaled, as _product), and (dᵀKd, gᵀd): the curvature and the slope along d."""
    _product(end_a, end_b, normal, inverse_mass, scale, d, u, kd)
    curvature = 0.0
    slope = 0.0
    for r in range(d.shape[0]):
        curvature += d[r] * kd[r]
        slope += g[r] * d[r]
    return curvature, slope


@borrowing
def _move(y, g, d, kd, alpha) -> None:
    """A step of length alpha along -d: y -= alpha·d, and the gradient with it, g -= alpha·K·d."""
    for r in range(y.shape[0]):
        y[r] -= alpha * d[r]
        g[r] -= alpha * kd[r]


@borrowing
def _worst_violation(y, lower, grad, scale) -> float:
    """The largest change a Gauss–Seidel update would make, in the units of the relative
    values: max_r scale_r²·|max(x_r - g_r/K_rr, lower_r) - x_r| (scaled: scale·|max(y - g, l) - y|)."""
    worst = 0.0
    for r in range(y.shape[0]):
        step = max(y[r] - grad[r], lower[r]) - y[r]
        worst = max(worst, abs(step) * scale[r])
    return worst


@kernel
def solve_bound_qp(end_a, end_b, normal, inverse_mass, x, lower, grad, tolerance, max_products, stop):
    """Minimise ½ xᵀKx - bᵀx over x >= lower by MPRGP, from a feasible x.

    end_a, end_b: (m,) int64 the contact's two spheres as indices into ``inverse_mass``
    (-1: a wall, or an immovable sphere, which takes no share); normal: (m, 3) unit, from
    end_b to end_a; inverse_mass: (n_spheres,) 1/kg; x: (m,) the start (>= lower),
    overwritten with the answer; lower: (m,); grad: (m,) g(x) = rel(x) - target at the
    start (units of the relative values: m/s for impulses, m/s² for multipliers);
    tolerance: the answer is accepted when no Gauss–Seidel update of any contact would
    move its relative value by more than half of it; max_products: the most products K·d
    to spend; stop: (1,) int64, read at every iteration: nonzero ends the solve at once
    (the world was asked to stop, World.request_stop). Every contact must have K_rr > 0.

    Returns (products used, whether it converged). x is feasible either way.
    """
    m = x.shape[0]
    scale = np.empty(m)
    for r in range(m):
        w = 0.0
        if end_a[r] >= 0:
            w += inverse_mass[end_a[r]]
        if end_b[r] >= 0:
            w += inverse_mass[end_b[r]]
        scale[r] = math.sqrt(w)
    y = x * scale
    ly = lower * scale
    g = grad / scale
    y0 = y.copy()
    g0 = g.copy()
    u = np.zeros((inverse_mass.shape[0], 3))
    # a bound on ||S⁻¹KS⁻¹|| (Gershgorin, |n_r·n_q| <= 1), for the projected step length
    column = np.zeros(inverse_mass.shape[0])
    for r in range(m):
        if end_a[r] >= 0:
            column[end_a[r]] += 1.0 / scale[r]
        if end_b[r] >= 0:
            column[end_b[r]] += 1.0 / scale[r]
    norm = 0.0
    for r in range(m):
        row = 0.0
        if end_a[r] >= 0:
            row += inverse_mass[end_a[r]] * column[end_a[r]]
        if end_b[r] >= 0:
            row += inverse_mass[end_b[r]] * column[end_b[r]]
        norm = max(norm, row / scale[r])
    step_length = 1.95 / norm  # MPRGP asks for (0, 2/||A||]

    free = np.empty(m, np.bool_)
    phi = np.empty(m)  # the free gradient
    beta = np.empty(m)  # the chopped gradient
    p = np.empty(m)
    kp = np.empty(m)
    dy = np.empty(m)
    products = 0
    since_refresh = 0

    def refresh(y, g, products):  # noqa: E306 (numba closure)
        for r in range(m):
            dy[r] = y[r] - y0[r]
        _product(end_a, end_b, normal, inverse_mass, scale, dy, u, kp)
        for r in range(m):
            g[r] = g0[r] + kp[r]
        return products + 1

    def split(y, g):  # free set, free and chopped gradients; returns (β·β, φ̃·φ)
        bb = 0.0
        pf = 0.0
        for r in range(m):
            free[r] = y[r] > ly[r]
            if free[r]:
                phi[r] = g[r]
                beta[r] = 0.0
                reduced = min((y[r] - ly[r]) / step_length, g[r]) if g[r] > 0.0 else g[r]
                pf += reduced * g[r]
            else:
                phi[r] = 0.0
                beta[r] = min(g[r], 0.0)
                bb += beta[r] * beta[r]
        return bb, pf

    bb, pf = split(y, g)
    for r in range(m):
        p[r] = phi[r]
    converged = False
    while True:
        if _worst_violation(y, ly, g, scale) <= 0.5 * tolerance:
            if since_refresh == 0:
                converged = True
                break
            products = refresh(y, g, products)  # confirm on the true gradient
            since_refresh = 0
            bb, pf = split(y, g)
            continue
        if products >= max_products or stop[0] != 0:
            break
        if bb <= pf:
            # conjugate gradient step on the free contacts, or an expansion step
            pkp, gp = _along(end_a, end_b, normal, inverse_mass, scale, p, u, kp, g)
            products += 1
            since_refresh += 1
            if not pkp > 0.0:
                break  # no curvature along p (a singular K and a rounding-sized p)
            alpha_cg = gp / pkp
            alpha_f = math.inf
            for r in range(m):
                if p[r] > 0.0:
                    alpha_f = min(alpha_f, (y[r] - ly[r]) / p[r])
            if alpha_cg <= alpha_f:
                _move(y, g, p, kp, alpha_cg)
                bb, pf = split(y, g)
                gamma = 0.0
                for r in range(m):
                    gamma += phi[r] * kp[r]
                gamma /= pkp
                for r in range(m):
                    p[r] = phi[r] - gamma * p[r]
            else:
                # expansion: to the bound along p, then a projected gradient step
                _move(y, g, p, kp, alpha_f)
                bb, pf = split(y, g)
                for r in range(m):
                    y[r] = max(y[r] - step_length * phi[r], ly[r])
                products = refresh(y, g, products)
                since_refresh = 0
                bb, pf = split(y, g)
                for r in range(m):
                    p[r] = phi[r]
        else:
            # proportioning: free the contacts whose bounds hold them wrongly
            dkd, gd = _along(end_a, end_b, normal, inverse_mass, scale, beta, u, kp, g)
            products += 1
            since_refresh += 1
            if not dkd > 0.0:
                break
            _move(y, g, beta, kp, gd / dkd)
            bb, pf = split(y, g)
            for r in range(m):
                p[r] = phi[r]
        if since_refresh >= REFRESH_EVERY:
            # the true gradient replaces the recurrence's; the search direction is kept
            products = refresh(y, g, products)
            since_refresh = 0
            bb, pf = split(y, g)
    for r in range(m):
        x[r] = max(y[r] / scale[r], lower[r])
    return products, converged
