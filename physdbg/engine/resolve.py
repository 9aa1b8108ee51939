"""Contact resolution: the seed's impulse and wall reflection, with restitution — the one resolver.

Sphere–sphere (the seed)::

    n = (p_a - p_b) / |p_a - p_b|
    j = -(1 + c) ((v_a - v_b)·n) / (1/m_a + 1/m_b)
    v_a' = v_a + j n / m_a        v_b' = v_b - j n / m_b

with inverse masses w = 1/m (0 = immovable, so a post takes any impulse unmoved).

Sphere–wall: the seed's reflection R_r = R_i - 2N(R_i·N) with restitution c,
v' = v - (1 + c)(v·n) n (c = 1 is exactly the seed's mirror): the same impulse with the
wall as an immovable partner (w_b = 0).

Restitution of a contact combines the two coefficients by the scene's
``restitution_rule``: ``min`` (default: a pair is as bouncy as its less bouncy member),
``max``, ``product`` or ``mean``.

:func:`resolve_contact` is the only code that resolves a contact: the time-ordered loop
(timeline.py) and the index-ordered policy (world.py) both call it. A contact that
involves no held contact takes the seed's impulse alone; one that rests, is rapid, or
touches a sphere with held contacts is solved with the held contacts it reaches
(resting/).
"""

from __future__ import annotations

import math

import numpy as np

from ..events import HOW_AT_ONE_INSTANT, HOW_IMPULSE, HOW_RAPID, HOW_RESTING, HOW_WITH_HELD
from .colliders import (contact_feature, contact_gap, contact_normal, partner_moves, partner_normal_motion,
                        partner_restitution, partner_sphere, partner_surface, surface_gap)
from .jit import borrowing, kernel
from .kernel_args import (
    M_ANCHOR_IS_FLOW,
    M_PATH_FOLLOWS_ACC,
    M_RAPID_RULE,
    M_RAPID_TIME,
    M_REST_FRACTION,
    M_REST_STEP_FACTOR,
    M_RESTITUTION_RULE,
    M_RUN_TIME,
    M_STEP_END,
    P_A,
    P_INVERSE_MASS,
    P_LAST_CONTACT,
    P_RADIUS,
    P_SIGMA,
    P_V,
    P_X,
    forces,
    motion_of,
    paths,
    solve_tolerances,
)
from .motion import KICK_AT_STEP_START, advance_particle, kick
from .resting import (
    AT_ONE_INSTANT,
    HELD,
    STEP_RELEASED,
    begin_solve,
    contacts_of,
    held_add,
    held_find,
    held_remove,
    pinned_by,
    pressed_closing,
    push_along,
    rapid,
    rapid_holds,
    relative_normal,
    release_loose,
    rest_window,
    rests,
    solve_contacts,
    touch,
    velocity_scale,
)

RESTITUTION_RULES = ("min", "max", "product", "mean")

# what resolve_contact did
SKIPPED = 0
RESOLVED = 1
OUT_OF_WORK = 2
NEEDS_HELD = 3  # judge_contact: to be finished by finish_with_held

@borrowing
def combine(rule, e_a, e_b):
    """The restitution of a contact: rule is an index into RESTITUTION_RULES."""
    if rule == 0:
        return min(e_a, e_b)
    if rule == 1:
        return max(e_a, e_b)
    if rule == 2:
        return e_a * e_b
    return 0.5 * (e_a + e_b)


def combine_restitution(rule: str, e_a: float, e_b: float) -> float:
    """The restitution of a contact between two materials (see module doc), by rule name."""
    if rule not in RESTITUTION_RULES:
        raise ValueError(f"unknown restitution rule {rule!r}")
    return float(combine(RESTITUTION_RULES.index(rule), e_a, e_b))


@borrowing
def seed_impulse(closing, restitution, inverse_mass_sum):
    """The seed's impulse j = (1 + c)·closing / (w_a + w_b) (N·s, >= 0 for closing >= 0);
    a wall is a partner with w_b = 0, which makes it the reflection."""
    return (1.0 + restitution) * closing / inverse_mass_sum


@kernel
def resolve_contact(kind, ia, other, toi, particles, method, geometry, h, contacts, counters, contacts_slot,
                    rapid_slot, changed, work_budget):
    """Resolve the predicted contact (kind, ia, other) at time ``toi`` in the step.

    Advances the spheres to the contact, judges it (approaching? resting? rapid?),
    applies the seed's impulse or the simultaneous solve with held contacts, writes one
    contact row (events.CONTACT_ROW, ``contacts[counters[contacts_slot]]``) and lists in ``changed``
    (count first) the spheres whose paths changed. particles, method: the groups of
    kernel_args (LoopParticles, LoopMethod; method.path_follows_acc: the path acceleration
    is the contact-solved acceleration, every integrator but semi-implicit); geometry:
    colliders.geometry_of; h: the held store. Returns SKIPPED (not approaching: nothing resolved), RESOLVED, or
    OUT_OF_WORK (the held-contact solve ran out of its budget). On periodic axes the
    contact point is on a's surface next to a's centre, whichever image of b it met.

    In two stages: :func:`judge_contact`, which resolves by itself every contact that
    involves no held contact (it allocates nothing, so the time-ordered loop runs it
    without reference counting, jit.py), and :func:`finish_with_held` for the rest.
    """
    status, closing, used, how, is_rapid = judge_contact(kind, ia, other, toi, particles, method, geometry, h,
                                                         contacts, counters, contacts_slot, rapid_slot, changed)
    if status != NEEDS_HELD:
        return status
    return finish_with_held(kind, ia, other, toi, particles, method, geometry, h, contacts, counters, contacts_slot,
                            rapid_slot, changed, work_budget, closing, used, how, is_rapid)


@borrowing
def judge_contact(kind, ia, other, toi, particles, method, geometry, h, contacts, counters, contacts_slot, rapid_slot,
                  changed):
    """The first stage of :func:`resolve_contact` (its arguments but the budget): advance,
    judge, begin the contact's row and, for a contact that involves no held contact,
    apply the seed's impulse and finish the row. Returns (status, closing speed (m/s),
    restitution used, how (HOW_*), rapid): status SKIPPED, RESOLVED, or NEEDS_HELD — the
    row is begun (time, normal, point, velocities before) and :func:`finish_with_held`
    must solve it with the held contacts it reaches."""
    x, v, a = particles[P_X], particles[P_V], particles[P_A]
    sigma = particles[P_SIGMA]
    _step_end, integrator, drag, k = motion_of(method)
    ib = partner_sphere(kind, other)
    moved_a = sigma[ia] < toi  # (an anchor already at the contact's time keeps its path)
    moved_b = ib >= 0 and sigma[ib] < toi
    advance_particle(x, v, a, sigma, ia, toi, integrator, drag, k)
    if ib >= 0:
        advance_particle(x, v, a, sigma, ib, toi, integrator, drag, k)
    return _judge_at(kind, ia, other, toi, moved_a, moved_b, particles, method, geometry, h, contacts, counters,
                     contacts_slot, rapid_slot, changed)


@borrowing
def _judge_at(kind, ia, other, toi, moved_a, moved_b, particles, method, geometry, h, contacts, counters,
              contacts_slot, rapid_slot, changed):
    """judge_contact once the spheres' anchors are at the contact (moved_a, moved_b: whether
    advancing them there moved them)."""
    x, v, _a, _acc, radius, inverse_mass, _restitution, sigma, last_contact = particles
    anchor_is_flow = method[M_ANCHOR_IS_FLOW]
    ib = partner_sphere(kind, other)
    changed[0] = 0
    nx, ny, nz, closing, rel_acc, e, wsum, driven, u0, u1, u2 = _approach(kind, ia, other, particles, method,
                                                                         geometry)
    if not _approaches(closing, rel_acc, wsum):
        # Euler (and dragged Verlet) paths change with the anchor, so a sphere whose anchor
        # moved is predicted again; one whose anchor was already there keeps its path, and
        # predicting it again would only find this same contact again, forever
        if not anchor_is_flow:
            if moved_a:
                changed[0] += 1
                changed[changed[0]] = ia
            if moved_b:
                changed[0] += 1
                changed[changed[0]] = ib
        return SKIPPED, closing, 0.0, HOW_IMPULSE, False
    now = method[M_RUN_TIME] + toi
    press = rel_acc - _crease_press(h, ia, nx, ny, nz, inverse_mass[ia]) if ib < 0 else rel_acc
    held, used, is_rapid = _judged_how(closing, rel_acc, press, e, now, ia, ib, last_contact, method)
    _begin_row(contacts[counters[contacts_slot]], kind, ia, other, toi, nx, ny, nz, driven, u0, u1, u2, x, v, radius,
               sigma, geometry)
    last_contact[ia] = now
    if ib >= 0:
        last_contact[ib] = now
    if held != HOW_IMPULSE or h.deg[ia] != 0 or (ib >= 0 and h.deg[ib] != 0):
        return NEEDS_HELD, closing, used, held, is_rapid
    # the seed's impulse, alone
    j = seed_impulse(closing, used, wsum)
    push_along(v, inverse_mass, ia, ib, nx, ny, nz, j)
    changed[0] = 2 if ib >= 0 else 1
    changed[1] = ia
    changed[2] = ib
    _finish_row(kind, ia, other, ib, v, j, used, closing, held, is_rapid, contacts, counters, contacts_slot,
                rapid_slot)
    if driven:
        row = contacts[counters[contacts_slot] - 1]
        for c in range(3):
            row.velocity_b_after[c] = row.velocity_b_before[c]
    return RESOLVED, closing, used, held, is_rapid


@borrowing
def _approach(kind, ia, other, particles, method, geometry):
    """How contact (kind, ia, other) closes, its spheres' anchors at the contact: its normal
    (nx, ny, nz, from the partner towards ia), the closing speed to judge it by (m/s, the
    rounding rule of pressed_closing applied), the relative normal acceleration (m/s²,
    < 0 when pressed), the restitution by the scene's rule, the sum of the inverse masses,
    and whether the partner's surface is driven (a kinematic mesh's) with its velocity at
    the contact (u0, u1, u2; m/s). Both measured from a moving surface's own motion."""
    x, v, _a, acc, radius, inverse_mass, restitution, sigma, _last_contact = particles
    ib = partner_sphere(kind, other)
    nx, ny, nz = contact_normal(kind, x, sigma, ia, other, geometry)
    closing = -relative_normal(v, ia, ib, nx, ny, nz)
    # a kinematic mesh's surface moves: the closing speed and the press are relative to it
    u0, u1, u2, driven = partner_surface(kind, x, sigma, radius, ia, other, nx, ny, nz, geometry)
    surface_speed, surface_acc = partner_normal_motion(kind, x, v, sigma, radius, ia, other, nx, ny, nz, geometry)
    rel_acc = relative_normal(acc, ia, ib, nx, ny, nz)
    if driven:
        closing += surface_speed
        rel_acc -= surface_acc
    e = combine(method[M_RESTITUTION_RULE], restitution[ia], partner_restitution(kind, other, restitution, geometry))
    wsum = inverse_mass[ia] + inverse_mass[ib] if ib >= 0 else inverse_mass[ia]
    # (the velocities' rounding counts only on paths that are the flow: there a contact
    # judged no approach is not predicted again, while on Euler paths it is, at once, by a
    # narrow phase that knows nothing of rounding: see pressed_closing)
    closing = pressed_closing(closing, rel_acc, method[M_STEP_END],
                              velocity_scale(v, ia, ib) if method[M_ANCHOR_IS_FLOW] else 0.0)
    return nx, ny, nz, closing, rel_acc, e, wsum, driven, u0, u1, u2


@borrowing
def _approaches(closing, rel_acc, wsum) -> bool:
    """Whether a judged contact (_approach) is one to resolve: it closes, or touches while
    pressed, and something in it can move."""
    return not (closing < 0.0 or (closing == 0.0 and not rel_acc < 0.0) or wsum == 0.0)


@borrowing
def _judged_how(closing, rel_acc, press, e, now, ia, ib, last_contact, method):
    """How an approaching contact is resolved: (how: HOW_RESTING or HOW_RAPID if a rule
    holds it, else HOW_IMPULSE; the restitution used; whether the rapid-contact rule saw it
    come within its window of a previous contact). press: the relative normal
    acceleration the resting rule judges it by (m/s²; rel_acc but in a crease:
    _crease_press); now: the contact's time (s since the run began); last_contact (N,):
    each sphere's previous contact (s)."""
    resting = rests(closing, press, method[M_STEP_END], method[M_REST_STEP_FACTOR], method[M_REST_FRACTION])
    is_rapid = not resting and rapid(now, last_contact[ia], last_contact[ib] if ib >= 0 else -math.inf, e,
                                     method[M_RAPID_TIME])
    # a rapid contact that something presses is held like a resting one (under the "tc"
    # rule only a slow one); one that is not held is elastic (the original TC model): a
    # free cluster cannot collapse, and nothing that never rests (a gas, a break shot)
    # loses energy to the rule
    held = HOW_RESTING if resting else (
        HOW_RAPID if is_rapid and rapid_holds(closing, rel_acc, method[M_RAPID_TIME], method[M_RAPID_RULE])
        else HOW_IMPULSE)
    used = 0.0 if held != HOW_IMPULSE else (1.0 if is_rapid else e)
    return held, used, is_rapid


@borrowing
def _crease_press(h, ia, nx, ny, nz, w) -> float:
    """What sphere ia's held contacts with immovable partners add to its acceleration along
    n (m/s², > 0 where they push it away from the new contact's partner); w: its inverse
    mass. A new contact with something immovable is judged for rest (rules.rests) by the
    press without it: the free press.

    Why: a ball held on one face of a crease meets the other face pressed only by what is
    left of gravity once the first face's force is counted (in ramp's 152° valley, 1.1 of
    its 9.5 m/s² along the normal), so it closes too fast to rest, bounces, lifts off the
    first face, and rocks across the crease for hundreds of steps, five contacts a step,
    where a ball in the crease should hold both faces. Judged by the free press, the second
    face rests too, and the held solve shares the weight between the two. (Walls at right
    angles add nothing along each other's normals: a box's pile is judged as before.)"""
    total = 0.0
    for s in range(h.deg[ia]):
        c = h.slots[ia, s]
        if h.a[c] == ia and partner_sphere(h.kind[c], h.other[c]) < 0 and h.lam[c] > 0.0:
            total += h.lam[c] * w * (h.normal[c, 0] * nx + h.normal[c, 1] * ny + h.normal[c, 2] * nz)
    return max(total, 0.0)


@borrowing
def _begin_row(row, kind, ia, other, toi, nx, ny, nz, driven, u0, u1, u2, x, v, radius, sigma, geometry) -> None:
    """Begin a contact's row: its time, feature, normal, point and velocities before (a
    moving surface's own as the partner's; NaN for anything else immovable)."""
    ib = partner_sphere(kind, other)
    row.time_in_step = toi
    row.feature = contact_feature(kind, x, sigma, ia, other, geometry)
    row.normal[0] = nx
    row.normal[1] = ny
    row.normal[2] = nz
    for c in range(3):
        row.point[c] = x[ia, c] - row.normal[c] * radius[ia]
        row.velocity_a_before[c] = v[ia, c]
        row.velocity_b_before[c] = v[ib, c] if ib >= 0 else math.nan
    if driven:  # an immovable partner's velocity is NaN, a moving surface's its own
        row.velocity_b_before[0] = u0
        row.velocity_b_before[1] = u1
        row.velocity_b_before[2] = u2


@kernel
def finish_with_held(kind, ia, other, toi, particles, method, geometry, h, contacts, counters, contacts_slot,
                     rapid_slot, changed, work_budget, closing, used, how, is_rapid):
    """The second stage of :func:`resolve_contact`, for a contact judge_contact found
    involves held contacts (its status NEEDS_HELD, and closing, used, how, is_rapid as it
    returned them): solve it with the held contacts it reaches and finish its row.
    Returns RESOLVED or OUT_OF_WORK."""
    v = particles[P_V]
    ib = partner_sphere(kind, other)
    row = contacts[counters[contacts_slot]]
    kinds = np.full(1, kind, np.int64)
    others = np.full(1, other, np.int64)
    normals = np.empty((1, 3))
    for c in range(3):
        normals[0, c] = row.normal[c]
    targets = np.full(1, used * closing)
    holds = np.full(1, how != HOW_IMPULSE)
    impulses = np.zeros(1)
    ok = _solve_with_held(kinds, others, 1, ia, ib, toi, normals, targets, holds, particles, method, geometry, h,
                          changed, work_budget, impulses)
    _finish_row(kind, ia, other, ib, v, impulses[0], used, closing, how if how != HOW_IMPULSE else HOW_WITH_HELD,
                is_rapid, contacts, counters, contacts_slot, rapid_slot)
    if ib < 0 and not math.isnan(row.velocity_b_before[0]):  # a moving surface keeps its velocity
        for c in range(3):
            row.velocity_b_after[c] = row.velocity_b_before[c]
    return RESOLVED if ok else OUT_OF_WORK


# The most contacts of one sphere solved together at one instant (resolve_at_one_instant;
# resting.AT_ONE_INSTANT, 4: a ball meeting the crease of a V meets two triangles, a box's
# corner three planes) and how many candidates the loops gather for it (a fan of triangles
# meeting at a vertex gives several with one normal, of which only one is kept).
AT_ONE_INSTANT_CANDIDATES = 8
# Two swept times of one instant may differ in their last bits: contacts whose times lie
# within this fraction of the step of each other are at one instant.
SAME_INSTANT = 1e-12
# Normals this close to parallel (|n_1·n_2| above 1 - PARALLEL) are one contact met twice
# (an edge or corner shared by triangles): only the first is kept.
PARALLEL = 1e-9


@kernel
def resolve_at_one_instant(kinds, others, n, ia, toi, particles, method, geometry, h, contacts, counters,
                           contacts_slot, rapid_slot, changed, work_budget, resolved):
    """Resolve sphere ia's contacts with immovable partners (walls, meshes' triangles) that
    its swept tests put at one instant: kinds, others (n,) int64, the first the contact
    the queue popped (at ``toi``, s into the step), the others within SAME_INSTANT of it.
    Other arguments as :func:`resolve_contact`; resolved (n,) int64 is set to 1 for each
    contact resolved here, 0 for each left (it is predicted again with ia's new path).

    Contacts met at one instant are solved *together*, so that no order decides the
    outcome: a ball dropped onto the crease of a symmetric V leaves it straight up, as it
    would from a V of any numbering. Each contact is judged at the instant, before any
    impulse (closing speed, restitution, the resting and rapid rules, all against the
    sphere's previous contact, not against one another); those that approach, but one of
    each group of parallel normals (a shared edge met through two triangles), and at most
    AT_ONE_INSTANT, in order of kind then partner, are solved in one projected solve with
    the held contacts they reach, each to its own restitution target (resting/). Each
    keeps its own row; an impulse solved so says HOW_AT_ONE_INSTANT. Where fewer than two
    approach, or where the order cannot decide (every pair of normals perpendicular, so
    that each impulse leaves the others' closing speeds as they were, and the rapid-contact
    rule cannot hold one only for coming after another: the rule off, every restitution 1,
    no member pressed, or the sphere's previous contact already within the rule's window,
    as in a pile against a box's walls), the popped contact is resolved alone, exactly as
    resolve_contact does, and the others in turn.
    Returns resolve_contact's statuses."""
    x, v, a = particles[P_X], particles[P_V], particles[P_A]
    sigma, last_contact = particles[P_SIGMA], particles[P_LAST_CONTACT]
    _step_end, integrator, drag, k = motion_of(method)
    moved = sigma[ia] < toi
    advance_particle(x, v, a, sigma, ia, toi, integrator, drag, k)
    order = np.argsort(kinds[:n] * (np.int64(1) << 40) + others[:n], kind="mergesort")
    members = np.empty(n, np.int64)  # indices into kinds, others
    normals = np.empty((n, 3))
    closings = np.empty(n)
    rel_accs = np.empty(n)
    restitutions = np.empty(n)
    surfaces = np.empty((n, 3))  # a driven partner's surface velocity (NaN: not driven)
    m = 0
    coupled = False  # two members neither parallel nor perpendicular
    elastic = True  # every member's restitution 1 (the rapid-contact rule cannot act)
    held_by_rule = False  # a member the rapid-contact rule would hold, were it rapid
    for s in range(n):
        resolved[s] = 0
    for s in range(n):
        q = order[s]
        nx, ny, nz, closing, rel_acc, e, wsum, driven, u0, u1, u2 = _approach(kinds[q], ia, others[q], particles,
                                                                             method, geometry)
        if not _approaches(closing, rel_acc, wsum) or m == AT_ONE_INSTANT:
            continue
        repeated = False
        for r in range(m):
            facing = abs(nx * normals[r, 0] + ny * normals[r, 1] + nz * normals[r, 2])
            if facing > 1.0 - PARALLEL:
                repeated = True
            elif facing > PARALLEL:
                coupled = True
        if repeated:
            continue
        members[m] = q
        normals[m, 0] = nx
        normals[m, 1] = ny
        normals[m, 2] = nz
        closings[m] = closing
        rel_accs[m] = rel_acc
        restitutions[m] = e
        surfaces[m, 0] = u0 if driven else math.nan
        surfaces[m, 1] = u1
        surfaces[m, 2] = u2
        elastic = elastic and e >= 1.0
        held_by_rule = held_by_rule or (rel_acc < 0.0 and rapid_holds(closing, rel_acc, method[M_RAPID_TIME],
                                                                        method[M_RAPID_RULE]))
        m += 1
    # perpendicular contacts are independent: in turn they give what together would (to the
    # bit where the normals are the axes, as a box's walls), unless the rapid-contact rule
    # would hold the second only because the first came right before it: a pressed contact
    # with a restitution below 1, of a sphere whose previous contact is outside the rule's
    # window. (One already within it, as in a pile, is judged rapid in either order, and an
    # unpressed rapid contact is elastic in either: in turn, as always.)
    window = method[M_RAPID_TIME]
    fresh = window > 0.0 and not method[M_RUN_TIME] + toi - last_contact[ia] < window
    if m >= 2 and not coupled and (elastic or not fresh or not held_by_rule):
        m = 0
    if m < 2:  # nothing to solve together: the popped contact alone
        resolved[0] = 1
        status, closing, used, how, is_rapid = _judge_at(kinds[0], ia, others[0], toi, moved, False, particles,
                                                         method, geometry, h, contacts, counters, contacts_slot,
                                                         rapid_slot, changed)
        if status != NEEDS_HELD:
            return status
        return finish_with_held(kinds[0], ia, others[0], toi, particles, method, geometry, h, contacts, counters,
                                contacts_slot, rapid_slot, changed, work_budget, closing, used, how, is_rapid)
    now = method[M_RUN_TIME] + toi
    hows = np.empty(m, np.int64)
    useds = np.empty(m)
    rapids = np.zeros(m, np.bool_)
    targets = np.empty(m)
    holds = np.zeros(m, np.bool_)
    group_kinds = np.empty(m, np.int64)
    group_others = np.empty(m, np.int64)
    first_row = counters[contacts_slot]
    for r in range(m):
        q = members[r]
        resolved[q] = 1
        group_kinds[r] = kinds[q]
        group_others[r] = others[q]
        nx, ny, nz = normals[r, 0], normals[r, 1], normals[r, 2]
        press = rel_accs[r] - _crease_press(h, ia, nx, ny, nz, particles[P_INVERSE_MASS][ia])
        how, used, is_rapid = _judged_how(closings[r], rel_accs[r], press, restitutions[r], now, ia, -1, last_contact,
                                          method)
        hows[r] = how
        useds[r] = used
        rapids[r] = is_rapid
        targets[r] = useds[r] * closings[r]
        holds[r] = hows[r] != HOW_IMPULSE
        driven = not math.isnan(surfaces[r, 0])
        _begin_row(contacts[first_row + r], kinds[q], ia, others[q], toi, nx, ny, nz, driven, surfaces[r, 0],
                   surfaces[r, 1], surfaces[r, 2], x, v, particles[P_RADIUS], sigma, geometry)
    last_contact[ia] = now
    impulses = np.zeros(m)
    ok = _solve_with_held(group_kinds, group_others, m, ia, -1, toi, normals, targets, holds, particles, method,
                          geometry, h, changed, work_budget, impulses)
    for r in range(m):
        row = contacts[counters[contacts_slot]]
        _finish_row(group_kinds[r], ia, group_others[r], -1, v, impulses[r], useds[r], closings[r],
                    hows[r] if holds[r] else HOW_AT_ONE_INSTANT, rapids[r], contacts, counters, contacts_slot,
                    rapid_slot)
        if not math.isnan(row.velocity_b_before[0]):  # a moving surface keeps its velocity
            for c in range(3):
                row.velocity_b_after[c] = row.velocity_b_before[c]
    return RESOLVED if ok else OUT_OF_WORK


@borrowing
def _finish_row(kind, ia, other, ib, v, j, used, closing, how, is_rapid, contacts, counters, contacts_slot,
                rapid_slot):
    """Finish the contact's row (velocities after, impulse, restitution used, closing
    speed, who, how) and count it (and a rapid one)."""
    slot = counters[contacts_slot]
    row = contacts[slot]
    for c in range(3):
        row.velocity_a_after[c] = v[ia, c]
        row.velocity_b_after[c] = v[ib, c] if ib >= 0 else math.nan
    row.impulse = j
    row.restitution = used
    row.closing_speed = closing
    row.kind = kind
    row.a = ia
    row.other = other
    row.how = how
    counters[contacts_slot] = slot + 1
    if is_rapid:
        counters[rapid_slot] += 1


@kernel
def _solve_with_held(kinds, others, n, ia, ib, toi, normals, targets, holds, particles, method, geometry, h, changed,
                     work_budget, impulses):
    """The contacts (kinds, others (n,) of sphere ia, and sphere ib (-1: none) for a pair;
    normals (n, 3); targets (n,) the separation speed each must reach, m/s; holds (n,)
    whether each is held after) solved together with the held contacts they reach
    (resting/); writes each one's impulse (N·s) to impulses (n,), lists the changed
    spheres, and returns whether the work budget sufficed."""
    x, v, a, radius, sigma = paths(particles)
    acc, inverse_mass = forces(particles)
    step_end, integrator, drag, k = motion_of(method)
    vtol, atol = solve_tolerances(method)
    anchor_is_flow, path_follows_acc = method[M_ANCHOR_IS_FLOW], method[M_PATH_FOLLOWS_ACC]
    stick = rest_window(step_end, method[M_REST_STEP_FACTOR], method[M_REST_FRACTION])
    solve = begin_solve(h)
    touch(h, ia, x, v, a, sigma, toi, integrator, drag, k, solve)
    if ib >= 0:
        touch(h, ib, x, v, a, sigma, toi, integrator, drag, k, solve)
    seeds = np.empty(n, np.int64)
    for r in range(n):
        nx, ny, nz = normals[r, 0], normals[r, 1], normals[r, 2]
        c0 = held_find(h, kinds[r], ia, others[r])
        if c0 < 0:
            c0 = held_add(h, kinds[r], ia, others[r], nx, ny, nz)
        else:
            h.normal[c0, 0] = nx
            h.normal[c0, 1] = ny
            h.normal[c0, 2] = nz
        h.target[c0] = targets[r]
        h.surface[c0, 0], h.surface[c0, 1] = partner_normal_motion(kinds[r], x, v, sigma, radius, ia, others[r], nx,
                                                                   ny, nz, geometry)
        seeds[r] = c0
    if h.deg[ia] > 1 and pinned_by(h, ia):  # a motion no impulse can stop: the step ends here
        return False
    ok = solve_contacts(h, v, True, seeds, n, x, v, a, sigma, inverse_mass, toi, integrator, drag, k, vtol,
                        work_budget, stick)
    for r in range(n):
        impulses[r] = h.jv[seeds[r]]
        h.target[seeds[r]] = 0.0
    for r in range(n):
        if not holds[r]:  # (ids move as contacts are removed: found again)
            c0 = held_find(h, kinds[r], ia, others[r])
            if h.lam[c0] != 0.0:
                push_along(acc, inverse_mass, ia, ib, h.normal[c0, 0], h.normal[c0, 1], h.normal[c0, 2],
                           -h.lam[c0])
            held_remove(h, c0)
    release_loose(h, v, acc, inverse_mass, True, x, a, sigma, toi, integrator, drag, k, vtol, atol, stick)
    if ok:
        ok = _solve_accelerations(h, x, v, a, acc, inverse_mass, sigma, toi, integrator, drag, k, work_budget, vtol,
                                  atol, stick)
    # every visited sphere whose velocity or acceleration changed takes a new path (and is
    # re-predicted), as does one that lost a held contact
    n_changed = 0
    for s in range(h.touched[0]):
        p = h.touched[1 + s]
        moved = not anchor_is_flow or h.renew[p] == solve
        for d in range(3):
            if v[p, d] != h.before[p, d]:
                moved = True
        if path_follows_acc and (a[p, 0] != acc[p, 0] or a[p, 1] != acc[p, 1] or a[p, 2] != acc[p, 2]):
            a[p, 0] = acc[p, 0]
            a[p, 1] = acc[p, 1]
            a[p, 2] = acc[p, 2]
            moved = True
        if moved or p == ia or p == ib:
            n_changed += 1
            changed[n_changed] = p
    changed[0] = n_changed
    return ok


@kernel
def _solve_accelerations(h, x, v, a, acc, inverse_mass, sigma, when, integrator, drag, k, work_budget, vtol, atol,
                         stick) -> bool:
    """Solve the accelerations of the held contacts of the spheres visited so far, release
    the contacts it leaves loose, and solve again while a release changed something (a
    released contact's force leaves its spheres). Returns False when the budget ran out."""
    while True:
        touched = h.touched[1:h.touched[0] + 1].copy()
        seeds = np.empty(max(h.count[HELD], 1), np.int64)
        m = contacts_of(h, touched, touched.shape[0], seeds)
        if not solve_contacts(h, acc, False, seeds, m, x, v, a, sigma, inverse_mass, when, integrator, drag, k, atol,
                              work_budget, 0.0):
            return False
        if release_loose(h, v, acc, inverse_mass, True, x, a, sigma, when, integrator, drag, k, vtol,
                         atol, stick) == 0:
            return True


@borrowing
def _visit_all(h, v) -> None:
    """Begin a solve in which every sphere counts as visited (all anchors at the step start)."""
    solve = begin_solve(h)
    n = v.shape[0]
    for i in range(n):
        h.mark[i] = solve
        h.touched[1 + i] = i
        for d in range(3):
            h.before[i, d] = v[i, d]
    h.touched[0] = n


@kernel
def settle_held(h, particles, method, geometry, free_accel, contact_tolerance, work_budget) -> bool:
    """The forces phase of a step, for held contacts (all anchors at the step start).

    Releases contacts whose gap exceeds the contact tolerance, refreshes pair normals,
    rebuilds the accelerations from the kept multipliers (the warm start), solves them,
    releases contacts that are pulled apart, then (semi-implicit: after the velocity
    kick) removes any approach along held contacts from the velocities. The particles'
    acc (N, 3) is written, starting from free_accel (N, 3) m/s²; their a (N, 3), the path
    accelerations, is set to acc unless the integrator kicks at step start (then 0).
    particles, method: kernel_args' groups; geometry: colliders.geometry_of.
    Returns False when the work budget ran out.
    """
    x, v, a, radius, sigma = paths(particles)
    acc, inverse_mass = forces(particles)
    dt, integrator, drag, k = motion_of(method)
    vtol, atol = solve_tolerances(method)
    stick = rest_window(dt, method[M_REST_STEP_FACTOR], method[M_REST_FRACTION])
    semi_implicit = KICK_AT_STEP_START[integrator]
    n = x.shape[0]
    c = 0
    while c < h.count[HELD]:
        gap, n0, n1, n2, renewed = contact_gap(h.kind[c], x, v, a, radius, h.a[c], h.other[c], geometry)
        if renewed:
            h.normal[c, 0] = n0
            h.normal[c, 1] = n1
            h.normal[c, 2] = n2
        if gap > contact_tolerance:
            held_remove(h, c)
            h.count[STEP_RELEASED] += 1
        else:
            h.surface[c, 0], h.surface[c, 1] = partner_normal_motion(h.kind[c], x, v, sigma, radius, h.a[c],
                                                                     h.other[c], h.normal[c, 0], h.normal[c, 1],
                                                                     h.normal[c, 2], geometry)
            c += 1
    for c in range(h.count[HELD]):  # a motion no impulse can stop: the step ends here
        if h.surface[c, 0] != 0.0 and pinned_by(h, h.a[c]):
            return False
    for i in range(n):
        for d in range(3):
            acc[i, d] = free_accel[i, d]
    for c in range(h.count[HELD]):
        if h.lam[c] != 0.0:
            push_along(acc, inverse_mass, h.a[c], partner_sphere(h.kind[c], h.other[c]), h.normal[c, 0],
                       h.normal[c, 1], h.normal[c, 2], h.lam[c])
    _visit_all(h, v)
    ok = _solve_accelerations(h, x, v, a, acc, inverse_mass, sigma, 0.0, integrator, drag, k, work_budget, math.inf,
                              atol, stick)
    if semi_implicit:
        kick(v, acc, drag, dt)
    if ok and h.count[HELD] > 0:
        for c in range(h.count[HELD]):
            h.target[c] = 0.0
        _visit_all(h, v)  # a new solve: the impulses jv start from 0
        seeds = np.arange(h.count[HELD]).astype(np.int64)
        ok = solve_contacts(h, v, True, seeds, h.count[HELD], x, v, a, sigma, inverse_mass, 0.0, integrator, drag, k,
                            vtol, work_budget, stick)
        if ok and release_loose(h, v, acc, inverse_mass, False, x, a, sigma, 0.0, integrator, drag, k,
                                vtol, math.inf, stick) > 0:
            ok = _solve_accelerations(h, x, v, a, acc, inverse_mass, sigma, 0.0, integrator, drag, k, work_budget,
                                      vtol, atol, stick)
    for i in range(n):
        for d in range(3):
            a[i, d] = 0.0 if semi_implicit else acc[i, d]
    return ok


@kernel
def keep_on_moving_partners(h, x, v, a, radius, sigma, inverse_mass, geometry, contact_tolerance) -> float:
    """The step's end, for spheres held on a moving surface (a kinematic mesh's): each is
    put back on it, moved along the contact's normal by its gap. Returns the largest
    distance moved (m).

    Why: a held sphere's path over the step is its integrator's (straight, or a parabola),
    while a turning surface under it curves away or into it; the velocity and
    acceleration solves match the surface's motion along the normal at the step's start
    (HeldContacts.surface), so the gap drifts by about |ω|·|v|·dt² a step (dt³ terms for
    a surface that only translates, which rounding alone leaves at ~1e-16 m). Left, the
    drift releases the contact once it passes the contact tolerance (or sinks the sphere
    into the surface). Moved back, the sphere ends every step on the surface. Only a
    contact the surface presses (lam > 0) on its face or one found overlapping is moved
    (sigma (N,): the anchors, all at the step's end, 0), and never by
    more than the contact tolerance plus what one step of drift can explain (a larger gap
    is no drift: the contact is left to be released at the next step's start)."""
    worst = 0.0
    for c in range(h.count[HELD]):
        i = h.a[c]
        if partner_sphere(h.kind[c], h.other[c]) >= 0 or inverse_mass[i] == 0.0:
            continue
        if not partner_moves(h.kind[c], h.other[c], geometry):
            continue
        # the partner's whole surface (a mesh's nearest triangle): a sphere held on one
        # triangle that has crossed onto the next is put on the next, never drawn back
        # towards the edge between them (which would sink it into the next one's face)
        gap, n0, n1, n2, on_face = surface_gap(h.kind[c], x, v, a, radius, i, h.other[c], geometry)
        if gap == 0.0 or gap == math.inf:
            continue
        if gap > 0.0 and (h.lam[c] == 0.0 or not on_face):  # drawn back only onto a face that presses it
            continue
        if abs(gap) > contact_tolerance + DRIFT_FRACTION * radius[i]:
            continue
        x[i, 0] -= gap * n0
        x[i, 1] -= gap * n1
        x[i, 2] -= gap * n2
        worst = max(worst, abs(gap))
    return worst


# The most a held sphere's gap to a moving surface may have drifted in one step, as a
# fraction of its radius (keep_on_moving_partners): a gap beyond it is not drift.
DRIFT_FRACTION = 0.01
