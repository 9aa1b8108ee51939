"""The held-contact solves: every contact that involves held contacts solved at once with
the held contacts it reaches (package doc), as worklists (projected Gauss–Seidel), dense
pivoting for a small cluster and conjugate gradients for a large one (bound_qp.py); the
release of contacts the solve leaves loose.

Why one module of this size: the solves share the held store's layout and call each
other compiled (a worklist falls back to the dense or the conjugate-gradient solve of a
cluster); the rules are rules.py and the store store.py."""

from __future__ import annotations

import math

import numpy as np

from ..bound_qp import solve_bound_qp
from ..colliders.kinds import partner_sphere
from ..jit import borrowing, kernel
from ..motion import advance_particle
from .store import (HELD, PINNED, PINNED_CONTACTS, SOLVE_ID, STEP_RELEASED, STEP_WHOLE_SOLVES, STEP_WORK, STOP,
                    contacts_of, held_remove)


# ----------------------------------------------------------------------------- solves
# A held contact separating slower than this many solve tolerances is residue of the
# solve (which stops waking neighbours below one tolerance), not separation.
SEPARATION_FACTOR = 1000.0

@borrowing
def begin_solve(h) -> int:
    """A new solve id (visits and impulses of earlier solves no longer count)."""
    # ids go up in fours: a contact's ``seen`` holds solve (impulse jv is this solve's),
    # -(solve + 2) (on the worklist) or -(solve + 3) (listed by contacts_of), and no
    # marker of one solve may equal a marker of the next
    h.count[SOLVE_ID] += 4
    h.touched[0] = 0
    return h.count[SOLVE_ID]


@borrowing
def touch(h, p, x, v, a, sigma, when, integrator, drag, k, solve) -> None:
    """Bring sphere p's anchor to time ``when`` once per solve, and list it as visited."""
    if h.mark[p] == solve:
        return
    h.mark[p] = solve
    advance_particle(x, v, a, sigma, p, when, integrator, drag, k)
    h.touched[0] += 1
    h.touched[h.touched[0]] = p
    for d in range(3):
        h.before[p, d] = v[p, d]


@borrowing
def relative_normal(values, i, j, nx, ny, nz) -> float:
    """(values_i - values_j)·n (j = -1: a wall, values_j = 0): the relative normal velocity
    or acceleration. The one formula: the resolver's closing speed and the solves' residuals
    must agree to the last bit, or a contact judged approaching by one is found satisfied
    by the other and comes back for ever."""
    if j < 0:
        return values[i, 0] * nx + values[i, 1] * ny + values[i, 2] * nz
    return (values[i, 0] - values[j, 0]) * nx + (values[i, 1] - values[j, 1]) * ny + (values[i, 2] - values[j, 2]) * nz


@borrowing
def _relative(values, h, c, is_velocity) -> float:
    """Held contact c's relative normal velocity (is_velocity) or acceleration, measured
    from its partner's surface (HeldContacts.surface: 0 but for a moving mesh's)."""
    return relative_normal(values, h.a[c], partner_sphere(h.kind[c], h.other[c]), h.normal[c, 0],
                           h.normal[c, 1], h.normal[c, 2]) - h.surface[c, 0 if is_velocity else 1]


@borrowing
def push_along(values, inverse_mass, i, j, nx, ny, nz, amount) -> None:
    """values_i += amount·w_i·n, values_j -= amount·w_j·n (j = -1: a wall): how an impulse
    (on velocities) or a contact force per unit mass (on accelerations) acts. The one place."""
    wi = amount * inverse_mass[i]
    values[i, 0] += wi * nx
    values[i, 1] += wi * ny
    values[i, 2] += wi * nz
    if j >= 0:
        wj = amount * inverse_mass[j]
        values[j, 0] -= wj * nx
        values[j, 1] -= wj * ny
        values[j, 2] -= wj * nz


@kernel
def solve_contacts(h, values, is_velocity, seeds, n_seeds, x, v, a, sigma, inverse_mass, when, integrator, drag,
                   k, tolerance, budget, stick) -> bool:
    """Solve the held contacts reachable from ``seeds[:n_seeds]`` (arguments as in
    :func:`_gauss_seidel`): exactly on the small cluster the change reaches
    (:func:`_solve_cluster`), then a Gauss–Seidel pass over that cluster that confirms it.
    Where the cluster grows beyond MAX_DIRECT: Gauss–Seidel from the seeds for at most
    LOCAL_SWEEP_WORK updates, and if the change has not died out by then, the whole
    connected cluster by conjugate gradients (:func:`_solve_connected`, bound_qp.py),
    confirmed by a Gauss–Seidel pass over it.

    Why three: projected Gauss–Seidel converges linearly, at a rate set by the cluster's
    conditioning; to the solve tolerance (about 1e-11 of a typical closing speed) a
    cluster of a dozen contacts takes 50–150 sweeps, and a dense pile takes thousands of
    such solves per step. A direct solve of a small cluster costs about one sweep's work
    per contact and leaves the confirming pass nothing to do; but its cost grows as m³
    (with a refactorisation per pivoting round), and conjugate gradients, at 15–60
    products K·d of about a sweep each, cost less on large clusters. Where the line
    falls depends on the scene: in rain-500's jammed steps MAX_DIRECT = 48 ran about 3×
    faster than 192, but in box-rain 10k it left a step stopped by the swept-test budget
    (docs/benchmarks.md); 192 is kept.
    """
    m = _solve_cluster(h, values, is_velocity, seeds, n_seeds, x, v, a, sigma, inverse_mass, when, integrator, drag,
                       k, tolerance, budget, stick)
    if m > 0:
        return _gauss_seidel(h, values, is_velocity, h.queue[:m].copy(), m, x, v, a, sigma, inverse_mass, when,
                             integrator, drag, k, tolerance, budget, stick)
    if m < 0:  # nothing violated: one pass confirms it
        return _gauss_seidel(h, values, is_velocity, seeds, n_seeds, x, v, a, sigma, inverse_mass, when, integrator,
                             drag, k, tolerance, budget, stick)
    # too large to solve directly: Gauss–Seidel while the change stays local, and where it
    # does not, the whole connected cluster by conjugate gradients (bound_qp.py)
    local = min(budget, h.count[STEP_WORK] + max(LOCAL_SWEEP_WORK, 8 * n_seeds))
    if _gauss_seidel(h, values, is_velocity, seeds, n_seeds, x, v, a, sigma, inverse_mass, when, integrator, drag,
                     k, tolerance, local, stick):
        return True
    if h.count[STEP_WORK] >= budget or h.count[STOP] != 0:
        return False
    m = _solve_connected(h, values, is_velocity, seeds, n_seeds, x, v, a, sigma, inverse_mass, when, integrator,
                         drag, k, tolerance, budget, stick)
    # confirmed from the contacts it changed and the seeds (a contact is queued once)
    confirm = np.empty(m + n_seeds, np.int64)
    confirm[:m] = h.queue[:m]
    confirm[m:] = seeds[:n_seeds]
    return _gauss_seidel(h, values, is_velocity, confirm, m + n_seeds, x, v, a, sigma, inverse_mass, when,
                         integrator, drag, k, tolerance, budget, stick)


# The Gauss–Seidel updates a solve too large to solve directly may spend before the whole
# connected cluster is solved by conjugate gradients instead (in rain-500, a change that
# stays local takes at most a few hundred updates; one into a jammed pile 16 000–130 000).
LOCAL_SWEEP_WORK = 1024


@kernel
def _solve_connected(h, values, is_velocity, seeds, n_seeds, x, v, a, sigma, inverse_mass, when, integrator, drag,
                     k, tolerance, budget, stick) -> int:
    """Solve every held contact connected to ``seeds[:n_seeds]`` (through movable spheres)
    by MPRGP (bound_qp.py), from the multipliers the solve has reached so far; a contact
    takes the answer where it moves its relative value by more than ``tolerance``. Leaves
    the ids of the contacts it changed in ``h.queue[:m]`` (for the confirming Gauss–Seidel
    pass) and returns m. Each product K·d counts a cluster's contacts of work."""
    solve = h.count[SOLVE_ID]
    inside = -(solve + 1)
    members = h.queue
    m = 0
    for s in range(n_seeds):
        c = seeds[s]
        if h.seen[c] != inside:
            _join(h, c, is_velocity, solve)
            members[m] = c
            m += 1
    head = 0
    while head < m:
        c = members[head]
        head += 1
        for e in range(2):
            p = _end(h, c, e)
            if p < 0:
                continue
            touch(h, p, x, v, a, sigma, when, integrator, drag, k, solve)
            if inverse_mass[p] == 0.0:
                continue  # an immovable sphere passes nothing on
            for t in range(h.deg[p]):
                d = h.slots[p, t]
                if h.seen[d] != inside:
                    _join(h, d, is_velocity, solve)
                    members[m] = d
                    m += 1
    # the problem's arrays: contacts with a movable sphere, their spheres numbered locally
    place = h.place  # -1 everywhere between solves
    spheres = np.empty(2 * m, np.int64)
    n_spheres = 0
    rows = np.empty(m, np.int64)
    end_a = np.empty(m, np.int64)
    end_b = np.empty(m, np.int64)
    n = 0
    for r in range(m):
        c = members[r]
        for e in range(2):
            p = _movable_end(h, c, e, inverse_mass)
            local = -1
            if p >= 0:
                if place[p] < 0:
                    place[p] = n_spheres
                    spheres[n_spheres] = p
                    n_spheres += 1
                local = place[p]
            if e == 0:
                end_a[n] = local
            else:
                end_b[n] = local
        if end_a[n] >= 0 or end_b[n] >= 0:
            rows[n] = r
            n += 1
    weight = np.empty(n_spheres)
    for s in range(n_spheres):
        weight[s] = inverse_mass[spheres[s]]
    normal = np.empty((n, 3))
    start = np.empty(n)
    lower = np.empty(n)
    grad = np.empty(n)
    for q in range(n):
        c = members[rows[q]]
        current, low, target = _bounds(h, c, is_velocity, stick, solve, True)
        start[q] = current
        lower[q] = low
        grad[q] = _relative(values, h, c, is_velocity) - target
        for d in range(3):
            normal[q, d] = h.normal[c, d]
    room = max((budget - h.count[STEP_WORK]) // max(n, 1), 0)
    answer = start.copy()
    used, _ = solve_bound_qp(end_a, end_b, normal, weight, answer, lower, grad, tolerance, room,
                             h.count[STOP:STOP + 1])
    h.count[STEP_WHOLE_SOLVES] += 1
    h.count[STEP_WORK] += used * n
    # a contact takes its new multiplier only where the change moves its relative value by
    # more than the tolerance (the rule by which Gauss–Seidel wakes a neighbour): the rest
    # of the cluster keeps its velocities to the bit, so its spheres keep their paths and
    # need no new predictions (box-rain 10k, with every change applied: 557 580 queue
    # entries and the swept-test budget spent in its last step)
    applied = np.empty(n, np.int64)
    k_applied = 0
    for q in range(n):
        c = members[rows[q]]
        delta = answer[q] - start[q]
        wsum = (weight[end_a[q]] if end_a[q] >= 0 else 0.0) + (weight[end_b[q]] if end_b[q] >= 0 else 0.0)
        if abs(delta) * wsum <= tolerance:
            continue
        push_along(values, inverse_mass, h.a[c], partner_sphere(h.kind[c], h.other[c]), h.normal[c, 0],
                   h.normal[c, 1], h.normal[c, 2], delta)
        if is_velocity:
            h.jv[c] = answer[q]
        else:
            h.lam[c] = answer[q]
        applied[k_applied] = c
        k_applied += 1
    for s in range(n_spheres):
        place[spheres[s]] = -1
    _leave_cluster(h, members, m, solve)
    members[:k_applied] = applied[:k_applied]
    return k_applied


# The largest cluster solved directly (contacts): its factorisation costs about m·b²/2 per
# pivoting round (b: the band of its factor, which widens with m); beyond it Gauss–Seidel,
# then the connected solve by conjugate gradients.
MAX_DIRECT = 192
# Pivoting rounds of one direct solve before it gives way to Gauss–Seidel.
MAX_PIVOTS = 24
# Cluster growth rounds (each adds the contacts a solve left violated next to it).
MAX_GROWTH = 12


@borrowing
def _bounds(h, c, is_velocity, stick, solve, joined):
    """(current multiplier, its lower bound, target) of contact c in this solve; joined:
    c is already part of it (else a velocity solve's impulse counts from 0)."""
    if is_velocity:
        current = h.jv[c] if joined or h.seen[c] == solve else 0.0
        return current, -h.lam[c] * stick, h.target[c]
    return h.lam[c], 0.0, 0.0


@kernel
def _solve_cluster(h, values, is_velocity, seeds, n_seeds, x, v, a, sigma, inverse_mass, when, integrator, drag,
                   k, tolerance, budget, stick) -> int:
    """The direct solve. The cluster starts from the seeds that are violated (a
    Gauss–Seidel update of one would exceed ``tolerance``) and every held contact of their
    spheres; its linear complementarity problem is solved exactly (:func:`_direct`), and
    the neighbouring contacts the solution leaves violated join it, with theirs, until
    none is.

    Leaves the cluster's ids in ``h.queue[:m]`` and returns m; -1: no seed is violated
    (nothing to solve); 0: the cluster outgrew MAX_DIRECT (or MAX_GROWTH rounds, the work
    budget, or pivoting failed) — everything it changed is undone, bit for bit, and the
    caller solves by Gauss–Seidel from the seeds. (Undone because a cluster solved with a
    violated boundary held fixed can push hard against it, which Gauss–Seidel then
    spends far longer spreading than it would have spent from the start.)
    """
    solve = h.count[SOLVE_ID]
    inside = -(solve + 1)  # seen code: in the cluster
    members = h.queue
    m = 0
    for s in range(n_seeds):
        c = seeds[s]
        if h.seen[c] != inside and _violated(h, values, c, is_velocity, x, v, a, sigma, inverse_mass, when,
                                             integrator, drag, k, tolerance, stick, solve):
            if m == MAX_DIRECT:
                _leave_cluster(h, members, m, solve)
                return 0
            _join(h, c, is_velocity, solve)
            members[m] = c
            m += 1
    if m == 0:
        return -1
    # what the direct solves change, to undo it: each member's multiplier and its spheres'
    # values as they were when it joined (restored in reverse, so the first save wins)
    undo_x = np.empty(MAX_DIRECT)
    undo_p = np.empty(2 * MAX_DIRECT, np.int64)
    undo_v = np.empty((2 * MAX_DIRECT, 3))
    saved = 0
    first = 0
    for _ in range(MAX_GROWTH):
        # with every held contact of the new members' spheres (they share the change)
        grown, fits = _add_neighbours(h, values, members, first, m, False, is_velocity, x, v, a, sigma,
                                      inverse_mass, when, integrator, drag, k, tolerance, stick, solve)
        m = grown
        if not fits or h.count[STEP_WORK] + m >= budget or h.count[STOP] != 0:
            return _give_up(h, values, members, m, saved, undo_x, undo_p, undo_v, is_velocity, solve)
        for r in range(first, m):
            c = members[r]
            touch(h, h.a[c], x, v, a, sigma, when, integrator, drag, k, solve)
            if partner_sphere(h.kind[c], h.other[c]) >= 0:
                touch(h, h.other[c], x, v, a, sigma, when, integrator, drag, k, solve)
        for r in range(saved, m):
            c = members[r]
            undo_x[r] = h.jv[c] if is_velocity else h.lam[c]
            for e in range(2):
                p = _end(h, c, e)
                undo_p[2 * r + e] = p
                if p >= 0:
                    for d in range(3):
                        undo_v[2 * r + e, d] = values[p, d]
        saved = m
        h.count[STEP_WORK] += m
        if not _direct(h, values, is_velocity, members, m, inverse_mass, stick, solve, tolerance):
            return _give_up(h, values, members, m, saved, undo_x, undo_p, undo_v, is_velocity, solve)
        grown, fits = _add_neighbours(h, values, members, 0, m, True, is_velocity, x, v, a, sigma, inverse_mass,
                                      when, integrator, drag, k, tolerance, stick, solve)
        if not fits:
            return _give_up(h, values, members, grown, saved, undo_x, undo_p, undo_v, is_velocity, solve)
        if grown == m:
            _leave_cluster(h, members, m, solve)
            return m
        first = m
        m = grown
    return _give_up(h, values, members, m, saved, undo_x, undo_p, undo_v, is_velocity, solve)


@borrowing
def _give_up(h, values, members, m, saved, undo_x, undo_p, undo_v, is_velocity, solve) -> int:
    """Undo every direct solve of this cluster (``saved`` members were saved) and leave it; returns 0."""
    for r in range(2 * saved - 1, -1, -1):
        p = undo_p[r]
        if p >= 0:
            for d in range(3):
                values[p, d] = undo_v[r, d]
    for r in range(saved):
        if is_velocity:
            h.jv[members[r]] = undo_x[r]
        else:
            h.lam[members[r]] = undo_x[r]
    _leave_cluster(h, members, m, solve)
    return 0


@borrowing
def _end(h, c, e) -> int:
    """The sphere at end e of contact c: 0 its first sphere, 1 its other (-1 for a wall)."""
    if e == 0:
        return h.a[c]
    return partner_sphere(h.kind[c], h.other[c])


@borrowing
def _add_neighbours(h, values, members, first, m, violated_only, is_velocity, x, v, a, sigma, inverse_mass, when,
                    integrator, drag, k, tolerance, stick, solve):
    """Add to the cluster ``members[:m]`` the held contacts of the spheres of
    ``members[first:m]`` — every one, or (violated_only) those a Gauss–Seidel update would
    move by more than ``tolerance``; returns the new count and whether all fitted in
    MAX_DIRECT."""
    inside = -(solve + 1)
    count = m
    for r in range(first, m):
        c = members[r]
        for e in range(2):
            p = _movable_end(h, c, e, inverse_mass)  # an immovable sphere passes nothing on
            if p < 0:
                continue
            for t in range(h.deg[p]):
                d = h.slots[p, t]
                if h.seen[d] == inside or (violated_only and not _violated(
                        h, values, d, is_velocity, x, v, a, sigma, inverse_mass, when, integrator, drag, k,
                        tolerance, stick, solve)):
                    continue
                if count == MAX_DIRECT:
                    return count, False
                _join(h, d, is_velocity, solve)
                members[count] = d
                count += 1
    return count, True


@borrowing
def _movable_end(h, c, e, inverse_mass) -> int:
    """The sphere at end e of contact c if it can move (a sphere with inverse mass > 0), else -1."""
    p = _end(h, c, e)
    return p if p >= 0 and inverse_mass[p] > 0.0 else -1


@borrowing
def _join(h, c, is_velocity, solve) -> None:
    """Contact c joins the cluster (direct or connected): a velocity solve's impulse counts
    from 0 unless this solve already used it (seen == solve) or queued it (seen ==
    -(solve + 2), which only a Gauss–Seidel pass before a connected solve leaves)."""
    if is_velocity and h.seen[c] != solve and h.seen[c] != -(solve + 2):
        h.jv[c] = 0.0
    h.seen[c] = -(solve + 1)


@borrowing
def _violated(h, values, c, is_velocity, x, v, a, sigma, inverse_mass, when, integrator, drag, k, tolerance, stick,
              solve) -> bool:
    """Whether a Gauss–Seidel update of contact c would exceed ``tolerance`` (its spheres
    are brought to ``when`` first)."""
    i = h.a[c]
    j = partner_sphere(h.kind[c], h.other[c])
    wsum = inverse_mass[i] + (inverse_mass[j] if j >= 0 else 0.0)
    if wsum == 0.0:
        return False
    touch(h, i, x, v, a, sigma, when, integrator, drag, k, solve)
    if j >= 0:
        touch(h, j, x, v, a, sigma, when, integrator, drag, k, solve)
    current, lower, target = _bounds(h, c, is_velocity, stick, solve, False)
    new = max(current + (target - _relative(values, h, c, is_velocity)) / wsum, lower)
    return abs(new - current) * wsum > tolerance


@borrowing
def _leave_cluster(h, members, m, solve) -> None:
    """Members' seen codes back to 'used in this solve' (their jv counts)."""
    for r in range(m):
        h.seen[members[r]] = solve


@kernel
def _direct(h, values, is_velocity, members, m, inverse_mass, stick, solve, tolerance) -> bool:
    """Solve the complementarity problem of contacts ``members[:m]`` exactly, the others fixed.

    Unknowns x (impulses jv, or multipliers lam) with x >= lower; the relative normal
    value rel(x) = rel0 + K (x - x0), K = J W Jᵀ (m, m), must end >= target, and equal to
    it wherever x > lower. Block principal pivoting (Júdice & Pires 1994, with Murty's
    one-at-a-time rule as the fallback) over a Cholesky factor of K on the active set; a
    ridge of 1e-13·max diag K keeps redundant contacts (a sphere touching more than three
    others) solvable at a cost of about 1e-13 of an impulse. Applies the result and
    returns True, or returns False with nothing changed.
    """
    x0 = np.empty(m)
    lower = np.empty(m)
    rhs = np.empty(m)
    wsum = np.empty(m)
    for r in range(m):
        c = members[r]
        # (a velocity solve's jv was reset to 0 when the contact joined this solve)
        cur, lo, tgt = _bounds(h, c, is_velocity, stick, solve, True)
        x0[r] = cur
        lower[r] = lo
        # rel(x) = target  <=>  K x = target - rel0 + K x0
        rhs[r] = tgt - _relative(values, h, c, is_velocity)
        i = h.a[c]
        j = partner_sphere(h.kind[c], h.other[c])
        wsum[r] = inverse_mass[i] + (inverse_mass[j] if j >= 0 else 0.0)
    big, row_start, cols = _contact_matrix(h, members, m, inverse_mass)
    for r in range(m):
        rhs[r] += _dot_row(big, r, x0, row_start, cols)
    ridge = 0.0
    for r in range(m):
        ridge = max(ridge, big[r, r])
    ridge *= 1e-13
    active = np.empty(m, np.bool_)
    for r in range(m):
        active[r] = x0[r] > lower[r] or rhs[r] - _dot_row(big, r, x0, row_start, cols) > 0.0
    xs = np.empty(m)
    chol = np.empty((m, m))
    idx = np.empty(m, np.int64)
    nonzero = np.empty(m, np.int64)
    best = m + 1
    chances = 3
    for _ in range(MAX_PIVOTS):
        # x: lower off the active set, K_AA x_A = rhs_A - K_AĀ lower_Ā on it
        n_act = 0
        for r in range(m):
            if active[r]:
                idx[n_act] = r
                n_act += 1
            else:
                xs[r] = lower[r]
        if n_act > 0:
            for u in range(n_act):
                r = idx[u]
                b = rhs[r]
                for z in range(row_start[r], row_start[r + 1]):
                    q = cols[z]
                    if not active[q]:
                        b -= big[r, q] * lower[q]
                xs[r] = b
            if not _cholesky_solve(big, idx, n_act, ridge, chol, xs, nonzero):
                return False
        # infeasible: active below its bound, or inactive left violated
        bad = 0
        last_bad = -1
        for r in range(m):
            if _infeasible(big, row_start, cols, rhs, xs, lower, active, wsum, r, tolerance):
                bad += 1
                last_bad = r
        if bad == 0:
            for r in range(m):
                c = members[r]
                new = max(xs[r], lower[r])
                delta = new - x0[r]
                if delta != 0.0:
                    i = h.a[c]
                    j = partner_sphere(h.kind[c], h.other[c])
                    push_along(values, inverse_mass, i, j, h.normal[c, 0], h.normal[c, 1], h.normal[c, 2], delta)
                if is_velocity:
                    h.jv[c] = new
                else:
                    h.lam[c] = new
            return True
        if bad < best:
            best = bad
            chances = 3
        elif chances > 0:
            chances -= 1
        else:
            active[last_bad] = not active[last_bad]
            continue
        for r in range(m):
            if _infeasible(big, row_start, cols, rhs, xs, lower, active, wsum, r, tolerance):
                active[r] = not active[r]
    return False


@borrowing
def _infeasible(big, row_start, cols, rhs, xs, lower, active, wsum, r, tolerance) -> bool:
    """Whether contact r breaks the solution by more than half the tolerance: an active one
    below its bound, or an inactive one left approaching (rel(x) - target = K x - rhs < 0)."""
    if active[r]:
        return (lower[r] - xs[r]) * wsum[r] > 0.5 * tolerance
    return _dot_row(big, r, xs, row_start, cols) - rhs[r] < -0.5 * tolerance


@borrowing
def _dot_row(big, r, xs, row_start, cols) -> float:
    """Row r of K times xs, over the row's nonzeros (cols[row_start[r]:row_start[r + 1]],
    in column order: the same sum, to the bit, as over the whole row, since a +0 entry
    adds nothing to a sum that starts at +0)."""
    acc = 0.0
    for z in range(row_start[r], row_start[r + 1]):
        q = cols[z]
        acc += big[r, q] * xs[q]
    return acc


@kernel
def _contact_matrix(h, members, m, inverse_mass):
    """K = J W Jᵀ of contacts ``members[:m]`` (m, m) dense, and where it can be nonzero by
    row: (row_start (m + 1,), cols) in column order (an entry whose two normals happen to
    be perpendicular is listed and is 0).

    Two contacts meet in K only through a sphere they share, so each member's row is built
    from the members of its two spheres (listed once per solve, the spheres numbered in
    ``h.place`` and given back) instead of a scan of all m: the entries, and the order of
    the two terms of a diagonal entry (first sphere, then other), are as in a scan.
    """
    place = h.place  # -1 everywhere between solves
    spheres = np.empty(2 * m, np.int64)
    n_spheres = 0
    start = np.zeros(2 * m + 1, np.int64)
    for r in range(m):
        for e in range(2):
            p = _movable_end(h, members[r], e, inverse_mass)
            if p < 0:
                continue
            if place[p] < 0:
                place[p] = n_spheres
                spheres[n_spheres] = p
                n_spheres += 1
            start[place[p] + 1] += 1
    # a row lists the members of its spheres, so the rows hold at most Σ (members of a sphere)²
    entries = 0
    for sp in range(n_spheres):
        entries += start[sp + 1] * start[sp + 1]
        start[sp + 1] += start[sp]
    fill = start[:n_spheres].copy()
    of_sphere = np.empty(start[n_spheres], np.int64)  # members of each sphere, in member order
    sign = np.empty(start[n_spheres])  # +1 where the sphere is the member's first, -1 its other
    for r in range(m):
        for e in range(2):
            p = _movable_end(h, members[r], e, inverse_mass)
            if p < 0:
                continue
            z = fill[place[p]]
            of_sphere[z] = r
            sign[z] = 1.0 if e == 0 else -1.0
            fill[place[p]] = z + 1
    big = np.zeros((m, m))
    row_start = np.zeros(m + 1, np.int64)
    cols = np.empty(entries, np.int64)
    z = 0
    for r in range(m):
        c = members[r]
        lo0 = hi0 = lo1 = hi1 = 0
        for e in range(2):
            p = _movable_end(h, c, e, inverse_mass)
            if p < 0:
                continue
            if e == 0:
                lo0, hi0 = start[place[p]], start[place[p] + 1]
            else:
                lo1, hi1 = start[place[p]], start[place[p] + 1]
            sr = 1.0 if e == 0 else -1.0  # the normal points at the first sphere
            for y in range(start[place[p]], start[place[p] + 1]):
                d = members[of_sphere[y]]
                big[r, of_sphere[y]] += inverse_mass[p] * sr * sign[y] * (
                    h.normal[c, 0] * h.normal[d, 0] + h.normal[c, 1] * h.normal[d, 1] + h.normal[c, 2] * h.normal[d, 2])
        # the row's nonzeros: the merge of its spheres' member lists (both in member order;
        # the member itself is in both)
        while lo0 < hi0 or lo1 < hi1:
            if lo1 == hi1 or (lo0 < hi0 and of_sphere[lo0] < of_sphere[lo1]):
                cols[z] = of_sphere[lo0]
                lo0 += 1
            elif lo0 == hi0 or of_sphere[lo1] < of_sphere[lo0]:
                cols[z] = of_sphere[lo1]
                lo1 += 1
            else:  # in both lists: r itself (the diagonal)
                cols[z] = of_sphere[lo0]
                lo0 += 1
                lo1 += 1
            z += 1
        row_start[r + 1] = z
    for sp in range(n_spheres):
        place[spheres[sp]] = -1
    return big, row_start, cols


@borrowing
def _cholesky_solve(big, idx, n, ridge, work, xs, nonzero) -> bool:
    """Solve (K_AA + ridge·I) y = xs[idx] in place (A = idx[:n]); False if not positive.

    work: (>= n, >= n) scratch; the factor L is built in it right-looking — column t of L
    into row t's upper triangle (work[t, u] = L[u, t]), the not yet factored rest of K_AA
    reduced in the lower triangle — so the update of the rest runs along rows. K is sparse
    (contacts meet only through a shared sphere) and the cluster grows outwards from its
    seeds, so L stays within a band: each column's update visits only the column's nonzeros
    (listed in ``nonzero``, (>= n,) scratch), as a sparse factorisation does. Every entry
    takes its subtractions in the same order as in the dense row-by-row (left-looking)
    form, and a skipped term is a +0 that would change nothing, so the result is the same
    to the bit.
    """
    for u in range(n):
        for w in range(u + 1):
            work[u, w] = big[idx[u], idx[w]]
    for t in range(n):
        d = work[t, t] + ridge
        if not d > 0.0:
            return False
        pivot = math.sqrt(d)
        work[t, t] = pivot
        count = 0
        for u in range(t + 1, n):
            work[t, u] = work[u, t] / pivot
            if work[t, u] != 0.0:
                nonzero[count] = u
                count += 1
        for i in range(count):
            u = nonzero[i]
            f = work[t, u]
            for j in range(i + 1):
                w = nonzero[j]
                work[u, w] -= f * work[t, w]
    # L y = b, then Lᵀ x = y, each sum taken in the same order as the row-by-row form
    for t in range(n):
        y = xs[idx[t]] / work[t, t]
        xs[idx[t]] = y
        for u in range(t + 1, n):
            if work[t, u] != 0.0:
                xs[idx[u]] -= work[t, u] * y
    for u in range(n - 1, -1, -1):
        s = xs[idx[u]]
        for t in range(u + 1, n):
            if work[u, t] != 0.0:
                s -= work[u, t] * xs[idx[t]]
        xs[idx[u]] = s / work[u, u]
    return True


@borrowing
def _gauss_seidel(h, values, is_velocity, seeds, n_seeds, x, v, a, sigma, inverse_mass, when, integrator, drag,
                  k, tolerance, budget, stick) -> bool:
    """Projected Gauss–Seidel over the held contacts reachable from ``seeds[:n_seeds]``.

    values: (N, 3) velocities (is_velocity: impulses jv, each contact ending with
    relative normal value >= its target) or accelerations (multipliers lam, target 0).
    Every update is applied; one that exceeds ``tolerance`` (in units of ``values``)
    puts the contacts of its spheres back on the worklist. Every sphere read is first brought to
    time ``when`` (touch). Returns False when the work budget (updates this step) ran out.

    stick (s): in the velocity solve, a pressed held contact also *resists separation*,
    with at most the impulse its pressing force (lam) gives in ``stick`` seconds — the
    resting window |a_n|·dt·(rest_fraction + f) of rule 1 turned round. Without it a
    cluster solve may leave one contact of a pile separating at a speed gravity undoes
    within microseconds, the next contact does the same to another, and the pile
    collapses into endless tiny events after all.
    """
    solve = h.count[SOLVE_ID]
    size = h.queue.shape[0]
    head = 0
    tail = 0
    # a contact is on the worklist at most once: "queued" is seen == -(solve + 2)
    for s in range(n_seeds):
        c = seeds[s]
        if h.seen[c] != -(solve + 2):
            if is_velocity and h.seen[c] != solve:
                h.jv[c] = 0.0
            h.seen[c] = -(solve + 2)
            h.queue[tail % size] = c
            tail += 1
    while head < tail:
        c = h.queue[head % size]
        head += 1
        h.seen[c] = solve
        if h.count[STEP_WORK] >= budget or h.count[STOP] != 0:
            return False
        h.count[STEP_WORK] += 1
        i = h.a[c]
        j = partner_sphere(h.kind[c], h.other[c])
        wsum = inverse_mass[i] + (inverse_mass[j] if j >= 0 else 0.0)
        if wsum == 0.0:
            continue
        touch(h, i, x, v, a, sigma, when, integrator, drag, k, solve)
        if j >= 0:
            touch(h, j, x, v, a, sigma, when, integrator, drag, k, solve)
        rel = _relative(values, h, c, is_velocity)
        if is_velocity:
            new = max(h.jv[c] + (h.target[c] - rel) / wsum, -h.lam[c] * stick)
            delta = new - h.jv[c]
        else:
            new = max(h.lam[c] - rel / wsum, 0.0)
            delta = new - h.lam[c]
        if delta == 0.0:
            continue
        # every update is applied, so a visited contact ends satisfied to rounding (a
        # skipped small one could leave a contact approaching that is found again at
        # once, for ever); only one above the tolerance wakes its neighbours
        if is_velocity:
            h.jv[c] = new
        else:
            h.lam[c] = new
        push_along(values, inverse_mass, i, j, h.normal[c, 0], h.normal[c, 1], h.normal[c, 2], delta)
        if abs(delta) * wsum <= tolerance:
            continue
        for end in range(2):
            p = i if end == 0 else j
            if p < 0 or inverse_mass[p] == 0.0:  # an immovable sphere passes nothing on
                continue
            for s in range(h.deg[p]):
                d = h.slots[p, s]
                if d != c and h.seen[d] != -(solve + 2):
                    if is_velocity and h.seen[d] != solve:
                        h.jv[d] = 0.0
                    h.seen[d] = -(solve + 2)
                    h.queue[tail % size] = d
                    tail += 1
    return True


@borrowing
def release_loose(h, v, acc, inverse_mass, touched_only, x, a, sigma, when, integrator, drag, k,
                  vtol, atol, stick) -> int:
    """Release held contacts that separate or that no force holds while the accelerations
    pull them apart (lam = 0, relative normal acceleration > atol).

    Separating means a relative normal velocity above what the solve leaves as residue
    (SEPARATION_FACTOR·vtol) plus, for a pressed contact, the speed its force undoes in
    ``stick`` seconds (lam·(w_a + w_b)·stick: the solve's own allowance, see
    solve_contacts) — but for a contact with something immovable whose allowance this
    solve has spent, the residue alone (_stick_spent). touched_only: only contacts of the spheres visited by the current
    solve (h.touched), including those a release visits; else every held contact. A
    released contact's force is taken back from ``acc`` (its spheres are touched first).
    Returns how many were released.

    (touched_only walks the visited spheres' own lists: a scan of every held contact per
    resolved contact made this 15 % of box-rain 10k's settled steps.)"""
    released = 0
    if not touched_only:
        c = 0
        while c < h.count[HELD]:
            if _release_if_loose(h, c, v, acc, inverse_mass, x, a, sigma, when, integrator, drag, k,
                                 vtol, atol, stick):
                released += 1  # the last contact took id c
            else:
                c += 1
        return released
    visited = 0
    while visited < h.touched[0]:  # a release may touch (and so list) a new sphere
        p = h.touched[1 + visited]
        visited += 1
        s = 0
        while s < h.deg[p]:
            if _release_if_loose(h, h.slots[p, s], v, acc, inverse_mass, x, a, sigma, when, integrator, drag, k, vtol,
                                 atol, stick):
                released += 1  # p's last listed contact took slot s
            else:
                s += 1
    return released


@borrowing
def _release_if_loose(h, c, v, acc, inverse_mass, x, a, sigma, when, integrator, drag, k, vtol, atol,
                      stick) -> bool:
    """Release held contact c if it is loose (release_loose); whether it was."""
    solve = h.count[SOLVE_ID]
    i = h.a[c]
    j = partner_sphere(h.kind[c], h.other[c])
    rel_v = _relative(v, h, c, True)
    wsum = inverse_mass[i] + (inverse_mass[j] if j >= 0 else 0.0)
    allowance = 0.0 if _stick_spent(h, c, j, solve) else h.lam[c] * wsum * stick
    separating = rel_v > SEPARATION_FACTOR * vtol + allowance
    # pulled apart, and not approaching by even a rounding error (released, such a
    # contact would be found again at once)
    pulled = h.lam[c] == 0.0 and rel_v >= 0.0 and _relative(acc, h, c, False) > atol
    if not (separating or pulled):
        return False
    # a released contact was never swept-tested while held: its spheres must be
    # predicted again, or they could pass through each other later in the step
    touch(h, i, x, v, a, sigma, when, integrator, drag, k, solve)
    h.renew[i] = solve
    if j >= 0:
        touch(h, j, x, v, a, sigma, when, integrator, drag, k, solve)
        h.renew[j] = solve
    if h.lam[c] != 0.0:
        push_along(acc, inverse_mass, i, j, h.normal[c, 0], h.normal[c, 1], h.normal[c, 2], -h.lam[c])
    held_remove(h, c)
    h.count[STEP_RELEASED] += 1
    return True


@borrowing
def _stick_spent(h, c, j, solve) -> bool:
    """Whether held contact c, with something immovable (j: its partner sphere, -1), was
    pulled by this solve's velocity stage (jv < 0: the stick, see _bounds). One that still
    separates beyond the residue was pulled as hard as the stick allows: it is leaving.

    Why released then: the sphere's other contacts drive it off (a ball held on one face
    of a crease that meets the other is pushed off the first by the second's impulse).
    Kept held, its force would go on pushing the sphere away while it separates — work
    done by a contact, which in ramp's crease fed a ball's rocking from face to face for
    ever (6–8 contacts a step; released, 0.5: docs/meshes.md "In a crease"). Between two
    spheres the allowance stays: released so, a pile's contacts are made again within
    microseconds, one after another, and the pile churns into the collapse the stick is
    there against (tests/test_audit.py's bed and README pile, tests/test_sleep.py's narrow
    pile)."""
    return j < 0 and h.seen[c] == solve and h.jv[c] < 0.0


# Two contacts of one sphere whose normals are within this of opposite (1 + n_a·n_b) leave
# it no way out sideways (pinned_by).
OPPOSED = 1e-9


@borrowing
def pinned_by(h, p) -> bool:
    """Whether sphere p is pinned: held against two immovable partners (walls, meshes) from
    opposite sides (normals within OPPOSED of opposite) whose surfaces close on it, one of
    them by a prescribed motion (HeldContacts.surface), so that no velocity meets both
    contacts and no impulse can stop the motion. Records the sphere and the two contacts
    in h.count[PINNED:] (store.py) when it is.

    Why the engine looks: the velocity solve would raise the two impulses against each
    other for ever (each update undoes the last), until the step's work budget ran out,
    step after step. A moving mesh pressing a ball against a fixed ceiling is that: the
    motion is prescribed, the ceiling immovable, and the scene has no answer."""
    for s in range(h.deg[p]):
        c = h.slots[p, s]
        if h.surface[c, 0] == 0.0 or h.a[c] != p or partner_sphere(h.kind[c], h.other[c]) >= 0:
            continue
        for t in range(h.deg[p]):
            d = h.slots[p, t]
            if d == c or h.a[d] != p or partner_sphere(h.kind[d], h.other[d]) >= 0:
                continue
            facing = (h.normal[c, 0] * h.normal[d, 0] + h.normal[c, 1] * h.normal[d, 1]
                      + h.normal[c, 2] * h.normal[d, 2])
            closing = h.surface[c, 0] + h.target[c] + h.surface[d, 0] + h.target[d]
            if 1.0 + facing <= OPPOSED and closing > 0.0:
                h.count[PINNED] = p + 1
                h.count[PINNED_CONTACTS] = h.kind[c]
                h.count[PINNED_CONTACTS + 1] = h.other[c]
                h.count[PINNED_CONTACTS + 2] = h.kind[d]
                h.count[PINNED_CONTACTS + 3] = h.other[d]
                return True
    return False
