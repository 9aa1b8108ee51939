"""The resting and rapid-contact rules: when a contact is held (resting/'s rules 1
and 2, package doc), each decided in one function, and the rounding a judged closing
speed is allowed. Pure arithmetic on one contact: no store, no solve."""

from __future__ import annotations

from ..jit import borrowing


@borrowing
def rests(closing: float, rel_acc: float, dt: float, step_factor: float, fraction: float) -> bool:
    """The resting rule (rule 1 above), the one place it is decided.

    closing: approach speed along the normal (m/s, >= 0); rel_acc: relative acceleration
    along the normal (m/s², < 0 when it presses the contact); dt: the step (s);
    step_factor: the integrator's f; fraction: Settings.rest_fraction.
    """
    return rel_acc < 0.0 and closing <= -rel_acc * rest_window(dt, step_factor, fraction)


@borrowing
def rest_window(dt: float, step_factor: float, fraction: float) -> float:
    """The resting window (s), the one place it is written: a pressed contact closing no
    faster than |a_n| times it rests (rule 1, ``rests``), and a held contact resists
    separation with at most the impulse its pressing force gives in it (``stick``, the
    held solves). dt: the step (s); step_factor: the integrator's f; fraction:
    Settings.rest_fraction."""
    return dt * (step_factor + fraction)


@borrowing
def rapid(now: float, last_a: float, last_b: float, restitution: float, window: float) -> bool:
    """The TC rule (rule 2 above), the one place it is decided.

    now: the contact's time (s since the run began); last_a, last_b: the previous contact
    of each sphere (-inf if none; last_b = -inf for a wall); restitution: the contact's
    c; window: Settings.rapid_contact_time (s, 0 = off).
    """
    return window > 0.0 and restitution < 1.0 and (now - last_a < window or now - last_b < window)


# What the rapid rule does with a pressed rapid contact (Settings.rapid_contact_rule):
# "hold" holds it at any speed; "tc" holds it only when it closes no faster than its press
# adds in the window, and makes a faster one elastic (the TC model's own answer).
RAPID_RULES = ("hold", "tc")
RAPID_HOLD = 0
RAPID_TC = 1


@borrowing
def rapid_holds(closing: float, rel_acc: float, window: float, rule: int) -> bool:
    """Whether a rapid contact (rule 2 above) is held, the one place it is decided.

    closing: approach speed along the normal (m/s, > 0); rel_acc: relative acceleration
    along the normal (m/s², < 0 when something presses the contact); window:
    Settings.rapid_contact_time (s); rule: RAPID_HOLD or RAPID_TC (an index into RAPID_RULES).
    A contact nothing presses is never held (it is elastic). Under RAPID_TC a pressed one
    is held only if closing <= |a_n|·window: a pair the press would bring back within the
    window. Elastic, such a pair would bounce for ever, each bounce shorter than the window
    (a ball on a floor bouncing every T < window closes at |a_n|·T/2); faster ones, the
    impacts a pile passes on, stay elastic and are not held, so the held clusters stay small.
    """
    if not rel_acc < 0.0:
        return False
    return rule == RAPID_HOLD or closing <= -rel_acc * window


# Separation speeds below this fraction of |a_n|·dt are rounding, not separation.
ROUNDING_FRACTION = 1e-9
# Closing speeds within this many rounding errors (units in the last place) of the two
# spheres' velocities are rounding, not approach.
ROUNDING_ULPS = 16.0
EPSILON = 2.220446049250313e-16  # float64's machine epsilon (np.finfo(float).eps)


@borrowing
def velocity_scale(v, i, j) -> float:
    """The size of spheres i's and j's velocities (j = -1: a wall), m/s: the sum of their
    largest components, the scale a relative normal speed is rounded at."""
    scale = max(abs(v[i, 0]), abs(v[i, 1]), abs(v[i, 2]))
    if j >= 0:
        scale += max(abs(v[j, 0]), abs(v[j, 1]), abs(v[j, 2]))
    return scale


@borrowing
def pressed_closing(closing: float, rel_acc: float, dt: float, scale: float) -> float:
    """The closing speed to judge a contact by (m/s): 0 for a rounding-sized one.

    Rounding-sized is either of:

    * within ROUNDING_ULPS rounding errors of the velocities (``scale``, velocity_scale).
      An impulse that small cannot change them: each component absorbs it, so the pair
      would be found approaching at once, again, for ever (a pile once spent its whole
      contact budget, 8 477 contacts at one instant, on one pair closing at 4e-106 m/s
      between spheres moving at 1e-13 m/s). The resolver passes scale = 0 (the rule
      off) where a contact judged no approach is predicted again at once (Euler paths
      change with the anchor): the narrow phase would find it again, approaching by the
      same rounding, for ever — an Euler stack with discrete detection did, where the
      seed's impulse of 1e-17 m/s moves velocities of 0.16 m/s by an ulp and separates
      the pair;
    * a separation below ROUNDING_FRACTION·|a_n|·dt while an acceleration presses the
      two together. A swept test finds such a contact at the instant the pair stops
      separating, but its time rounds to the anchor, where the velocity still points
      (by ~1e-16 m/s) away: taken as separating, the contact would be dropped and, with
      nothing re-predicted, the sphere would fall through what it rests on for the rest
      of the step.
    """
    if abs(closing) <= ROUNDING_ULPS * EPSILON * scale:
        return 0.0
    if rel_acc < 0.0 and closing < 0.0 and -closing <= -rel_acc * dt * ROUNDING_FRACTION:
        return 0.0
    return closing
