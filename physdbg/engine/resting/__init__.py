"""Resting and rapid contacts: the rules that hold spheres together, the store of held
contacts and the compiled solves (rules.py, store.py, solves.py; this package names
what the rest of the engine uses).

An impulse solver alone cannot hold a ball on a floor: with restitution c < 1 it bounces
ever lower (infinitely many bounces in finite time) and with a step-sized approach
speed (Euler) it jitters forever. A dense pile is worse: three or more spheres in touch
exchange ever smaller impulses ever faster (*inelastic collapse*, McNamara & Young 1992),
and one sphere squeezed between two takes infinitely many events with any c < 1 — even
c = 0. Two rules turn such contacts into *held* contacts, solved all at once:

1. **Resting** (`rests`): a contact is resting where something presses it: its relative
   acceleration along the normal pushes the two together (a_n < 0: gravity, or a held
   neighbour), and it closes no faster than that acceleration adds in a fraction of a
   step, |a_n|·dt·(rest_fraction + f), with f the integrator's rest factor (motion.py:
   1.5 for the two Euler integrators, whose straight paths arrive with about one step of
   acceleration; 0 otherwise). A contact nothing presses never rests: an e = 1 gas keeps
   its energy at any speed.
2. **Rapid** (`rapid`, the TC model of Luding & McNamara, Granular Matter 1, 113 (1998)):
   a contact with c < 1 that comes within ``rapid_contact_time`` of either sphere's
   previous contact is, if something presses it (a_n < 0), treated as resting; if
   nothing presses it, it is elastic (c = 1, the original TC model: a free cluster
   cannot collapse, and a break shot or a gas loses no energy to the rule). 0 turns the
   rule off; with c = 1 it never acts. ``rapid_contact_rule`` = "tc" holds a pressed one
   only when it closes no faster than |a_n|·``rapid_contact_time`` and keeps a faster one
   elastic too (`rapid_holds`): fast contacts never join the held clusters, which stay
   small, so a dense pile does not churn, but neither do its fast contacts lose energy.

A resting contact, or a pressed rapid one, is resolved with restitution 0 and *held*:

* held contacts are not swept-tested (they touch by definition);
* against a moving surface (a kinematic mesh's) every relative normal velocity and
  acceleration is measured from the surface's own (HeldContacts.surface), so a sphere
  rests on a moving mesh as on a fixed one; a sphere a moving surface presses against
  something immovable from the opposite side is pinned (``pinned_by``) and ends the run;
* every contact that involves a sphere with held contacts is solved *simultaneously*
  with the held contacts it reaches: a projected Gauss–Seidel solve of the velocities
  (each held contact ends with (v_a - v_b)·n >= 0, the new contact with its restitution
  target, impulses >= 0), then of the accelerations ((a_a - a_b)·n >= 0, lambda >= 0,
  complementary), walls and immovable spheres taking no share. The solves are worklists:
  a contact is revisited only when a neighbour's update moved its spheres, so a ball
  landing on a settled pile costs the contacts its weight reaches, not the whole pile.
  A small cluster is solved exactly (dense pivoting); where the change spreads through a
  large jammed one, the whole connected cluster is solved by conjugate gradients
  (bound_qp.py) and Gauss–Seidel only confirms it (solve_contacts);
* a held contact is released when it separates (velocity), when the solve gives it
  lambda = 0 while the accelerations pull it apart, or when its gap exceeds the contact
  tolerance at the start of a step.

Hence a settled pile costs no event per step: one warm-started solve that finds the
lambdas of the last step still right, and every sphere stays exactly where it is.

The held contacts live in :class:`HeldContacts` arrays (store.py); each sphere lists its
own (``slots``), so finding one is a scan of at most a dozen entries.
"""


from __future__ import annotations
from .rules import (  # noqa: F401
    EPSILON,
    RAPID_HOLD,
    RAPID_RULES,
    RAPID_TC,
    ROUNDING_FRACTION,
    ROUNDING_ULPS,
    pressed_closing,
    rapid,
    rapid_holds,
    rest_window,
    rests,
    velocity_scale,
)
from .store import (  # noqa: F401
    AT_ONE_INSTANT,
    HELD,
    PINNED,
    PINNED_CONTACTS,
    SOLVE_ID,
    STEP_RELEASED,
    STEP_WHOLE_SOLVES,
    STEP_WORK,
    HeldContacts,
    contacts_of,
    grow_held,
    held_add,
    held_find,
    held_remove,
    held_room,
    new_held,
    renumber_held,
)
from .solves import (  # noqa: F401
    LOCAL_SWEEP_WORK,
    MAX_DIRECT,
    MAX_GROWTH,
    MAX_PIVOTS,
    SEPARATION_FACTOR,
    begin_solve,
    pinned_by,
    push_along,
    relative_normal,
    release_loose,
    solve_contacts,
    touch,
)
