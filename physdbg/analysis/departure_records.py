"""check-run's records and numbers: the tolerances and rules its judgements use, a
contact of physdbg's local step (StepContact), a kick read off the run (Kick), a departure
and the first one (Departure, FirstDeparture), the report (CheckRunReport), both runs as
arrays (_Runs, loaded by _load) and the small functions over them (docs/check-run.md).
Apart from the judgements (departure.py and its judge modules), which all read these."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..errors import CheckRunError
from ..events import KIND_NAMES, PARTNER_IS_SPHERE


DEFAULT_ATOL = 1e-6  # m and m/s: a body departs when |Δx| or |Δv| exceeds atol + rtol·|reference|
DEFAULT_RTOL = 1e-6
KICK_FRACTION = 0.02  # a velocity change beyond this share of (speed + |a|·dt) that forces do not explain
TIME_TOLERANCE = 0.02  # of dt: a kick this close to physdbg's time of impact is on time (a kick's instant is
# read off two frames, so it is known only to about this)
RESTING_SPEED_STEPS = 2.0  # a contact closing slower than the speed the forces give in this many steps is resting
RUNAWAY = 100.0  # a pair leaving a contact still approaching at this many times its speed has run away
# frames × bodies compared at once: 4 arrays of this many 3-vectors (96 B a body-step) and
# the temporaries of the whole-run checks (kicks, integrator, drag: about as much again)
MAX_BODY_STEPS = 12_000_000
CHUNK_BODY_STEPS = 1 << 20  # frames × bodies a whole-run check reads at a time, where it can go in parts
MAX_LISTED = 12  # departures listed; more of a kind are counted on its first
FIT_SLACK = 1e-9  # m: an integrator's free-step residual this small counts as exact

# physdbg's own modelling rules, which a right engine of the seed's model does not have:
# (code, the setting that turns the rule off, its value then, the rule's name in words). Where
# a step departs and physdbg's step without the rule ends where the run's does, the rule is
# the difference, not the engine (check-run then compares against physdbg without it).
OWN_RULES = (
    ("rapid-contact", "rapid_contact_time", 0.0, "rapid-contact rule"),
    ("resting", "rest_fraction", 0.0, "resting-contact rule"),
)
# Sleeping is one too, found otherwise: a step taken from the run's state starts with every
# sphere awake (a sphere falls asleep only after sleep_time of slow steps), so where the
# reference froze a sphere that the run keeps moving, every step ends where the run's does
# and the runs still part (_slept).
SLEEPING_RULE = ("sleeping", "sleep_speed", 0.0, "sleeping rule")

# A tie: contacts at one instant, within this fraction of the step of each other (resolve.SAME_INSTANT,
# physdbg's own), that share a sphere. Orders tried: every numbering of the tied spheres up to
# TIE_SPHERES of them (4! = 24 local steps at most), past that the reversed one alone. After
# MAX_TIES ties that part the runs, the reference is not continued again (each continuation
# steps physdbg through the rest of the run).
TIE_SPHERES = 4
MAX_TIES = 20
MISTAKE_MISSES = 3  # chains no impulse mistake reproduced before check-run stops trying them (_mistaken_chain)

# integrator families, as each moves a body through a step with no contact:
# (name, words, the velocity it moves by, as weights of (v at the start, v at the end))
INTEGRATOR_FITS = (
    ("explicit-euler", "explicit Euler (x += v·dt with the velocity of the step's start, then v += a·dt)", (1.0, 0.0)),
    ("semi-implicit-euler", "semi-implicit Euler (v += a·dt first, then x += v·dt with the new velocity)", (0.0, 1.0)),
    ("exact", "the exact path for a constant force (x += v·dt + a·dt²/2, as physdbg's exact and verlet integrators)",
     (0.5, 0.5)),
)


def family_of(integrator: str) -> str | None:
    """The family (INTEGRATOR_FITS) of physdbg's integrator of this name: the one whose
    weights are its free flight's (motion.FREE_FLIGHT_WEIGHTS); None for a name physdbg
    does not have."""
    from ..engine.motion import FREE_FLIGHT_WEIGHTS, INTEGRATOR_NAMES

    if integrator not in INTEGRATOR_NAMES:
        return None
    weights = FREE_FLIGHT_WEIGHTS[INTEGRATOR_NAMES.index(integrator)]
    return next((name for name, _, fit in INTEGRATOR_FITS if fit == weights), None)


def integrator_of(family: str | None) -> str:
    """physdbg's integrator that moves like a family (the last of INTEGRATOR_NAMES with its
    weights: exact before verlet); physdbg's default integrator for none."""
    from ..engine.motion import INTEGRATOR_NAMES
    from ..engine.state import Settings

    matches = [name for name in INTEGRATOR_NAMES if family is not None and family_of(name) == family]
    return matches[-1] if matches else Settings.integrator





@dataclass(eq=False)
class StepContact:
    """One contact of physdbg's exact step from the run's state (``_Comparison._local_step``):
    step (1 = the first); index: its place in the step's order; kind: collider kind
    (events.KIND_*); a: the sphere; other: the other sphere, wall or triangle; tau: s into
    the step; time: s; normal (3,): from the partner towards a; restitution; resting: held
    by a resting or rapid rule; closing: closing speed, m/s (>= 0); centre (3,): a's centre
    at the touch, m. (Compared by identity: two contacts are never "equal".)"""

    step: int
    index: int
    kind: int
    a: int
    other: int
    tau: float
    time: float
    normal: np.ndarray
    restitution: float
    resting: bool
    closing: float
    centre: np.ndarray


@dataclass(eq=False)
class Kick:
    """A step in which a body's velocity changed by more than the forces explain, read off
    the foreign run (``_Comparison._kicks``): step, body, tau (s into the step), time (s);
    matched: a contact of physdbg's has claimed it."""

    step: int
    body: int
    tau: float
    time: float
    matched: bool = False


@dataclass(frozen=True)
class _Lone:
    """What a departure of one body alone is about (no contact: no kind, no partner)."""

    a: int
    kind: None = None
    other: None = None


def _no_geometry(kind: int) -> CheckRunError:
    return CheckRunError(f"check-run has no geometry for a contact with a {KIND_NAMES[kind]} (collider kind {kind}): "
                         f"analysis/departure.py's _gap and _tunnelled need a branch for it")


@dataclass
class Departure:
    """One way the foreign run departs. kind: tunnelling | bounce-time | contact-energy |
    collision-order | missed-contact | extra-contact | drift | non-finite; step: the
    step (1 = the first); body: the sphere; other: the other sphere (pairs) or None; wall:
    the wall's name or None; text: what happened; advice: what to change; evidence: the
    numbers; more: how many later departures of the same kind on the same bodies."""

    kind: str
    step: int
    body: int
    text: str
    advice: str
    other: int | None = None
    wall: str | None = None
    evidence: dict = field(default_factory=dict)
    more: int = 0

    # the record every report prints (report.Record); the JSON keeps the fields above
    code = property(lambda self: self.kind)
    bodies = property(lambda self: (self.body,) if self.other is None else (self.body, self.other))
    summary = property(lambda self: self.text)
    detail = property(lambda self: self.evidence)


@dataclass
class FirstDeparture:
    """The first frame where some body differs beyond the tolerance: step, time (s), body
    (the most different), position (m) and velocity (m/s) gaps of that body, bodies (how
    many differ), cause: the departure that explains it (kind), or "drift"."""

    step: int
    time: float
    body: int
    position: float
    velocity: float
    bodies: int
    cause: str


@dataclass
class CheckRunReport:
    """What ``check-run`` (or ``diff`` of a foreign run against physdbg's) found.

    exit_code: 0 when no body departs beyond the tolerance, 1 otherwise."""

    run: str
    reference: str
    scene: str
    steps: int
    bodies: int
    atol: float
    rtol: float
    velocities: str
    first: FirstDeparture | None
    departures: list[Departure]
    integrator: dict | None
    judged_contacts: int
    reference_contacts: int
    headline: str
    notes: list[str] = field(default_factory=list)
    set_aside: list[dict] = field(default_factory=list)  # physdbg's own rules the reference was run without
    ties: list[dict] = field(default_factory=list)  # ties the reference went on from in the run's order

    @property
    def exit_code(self) -> int:
        return 0 if self.first is None else 1

    def as_dict(self) -> dict:
        out = asdict(self)
        out["exit_code"] = self.exit_code
        return out


# ----------------------------------------------------------------------------- loading
@dataclass
class _Runs:
    """Both runs as arrays: x*, v* (F, N, 3); t (F,), dt (F,) with dt[0] = 0."""

    xf: np.ndarray
    vf: np.ndarray
    xr: np.ndarray
    vr: np.ndarray
    t: np.ndarray
    dt: np.ndarray


def too_long(frames: int, bodies: int) -> None:
    """Refuse a comparison of more than MAX_BODY_STEPS frames × bodies (CheckRunError),
    before any of it is read."""
    if frames * bodies > MAX_BODY_STEPS:
        raise CheckRunError(f"{frames} frames of {_body_count(bodies)} is {frames * bodies:,} body-steps; check-run "
                            f"compares at most {MAX_BODY_STEPS:,} at once (its memory grows with them): cut the "
                            f"run shorter, or use physdbg diff, which streams")


def _load(foreign, reference) -> _Runs:
    n, frames = reference.header.count, min(foreign.frames, reference.frames)
    if foreign.header.count != n:
        raise CheckRunError(f"the runs have different numbers of bodies ({foreign.header.count} and {n})")
    too_long(frames, n)
    tf, tr = foreign.frame_table(), reference.frame_table()
    mismatch = np.flatnonzero(np.abs(tf.time[:frames] - tr.time[:frames]) > 1e-9 * np.maximum(tr.dt[:frames], 1e-300))
    if len(mismatch):
        k = int(mismatch[0])
        raise CheckRunError(f"frame {k} is at t = {tf.time[k]!r} s in the run and {tr.time[k]!r} s in physdbg's: the "
                            f"reference must be recorded with the run's own steps (physdbg check-run does this)")
    xf, vf = np.empty((frames, n, 3)), np.empty((frames, n, 3))
    xr, vr = np.empty((frames, n, 3)), np.empty((frames, n, 3))
    for target_x, target_v, rec in ((xf, vf, foreign), (xr, vr, reference)):
        for s in rec.states(0, frames):
            target_x[s.frame], target_v[s.frame] = s.positions, s.velocities
    dt = np.concatenate([[0.0], np.diff(tr.time[:frames])])
    return _Runs(xf, vf, xr, vr, tr.time[:frames].copy(), dt)




_RUN_WIDE = ("own-rule", "index-order", "drag-per-step", "drag-ignored", "drift", "chaos", "unexplained")


def _changed_contacts(with_rule: list[StepContact],
                      without: list[StepContact]) -> list[tuple[StepContact, StepContact | None]]:
    """The contacts of a step that a rule changed: (the contact with the rule, the same
    pair's contact without it), matched in order by pair, whose restitution or resting
    differs; where none does, the contacts one list has and the other not (other: None).
    (Contacts that only follow from a changed one are not counted as the rule's.)"""
    left = list(without)
    changed, unmatched = [], []
    for c in with_rule:
        match = next((d for d in left if (d.kind, d.a, d.other) == (c.kind, c.a, c.other)), None)
        if match is None:
            unmatched.append((c, None))
            continue
        left.remove(match)
        if match.restitution != c.restitution or match.resting != c.resting:
            changed.append((c, match))
    return changed or unmatched


def cause_of(first: FirstDeparture, departures: list[Departure]) -> Departure | None:
    """The departure that is the first departure's cause: of its kind, about its sphere
    (or a way of stepping the whole run has), the earliest listed."""
    return next((d for d in departures if d.kind == first.cause and (_involves(d, first.body) or d.kind in _RUN_WIDE)),
                None)


def _involves(d: Departure, body: int) -> bool:
    """Whether departure d is about sphere ``body``: its own, its partner, or one of a
    chain's spheres (evidence "bodies")."""
    return body in (d.body, d.other) or body in d.evidence.get("bodies", ())


def bodies_of(kind: int, a: int, other: int) -> tuple[int, ...]:
    """The spheres of a contact (its kind, a and other): both of a pair, else a."""
    return (a, other) if PARTNER_IS_SPHERE[kind] else (a,)


def _body_count(n: int) -> str:
    return f"{n} body" if n == 1 else f"{n} bodies"


def _chains(contacts: list[StepContact]) -> list[list[StepContact]]:
    """Contacts of one step grouped by shared bodies (walls do not join groups), in order."""
    parent: dict[int, int] = {}

    def find(i: int) -> int:
        while parent.setdefault(i, i) != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for c in contacts:
        find(c.a)
        if PARTNER_IS_SPHERE[c.kind]:
            parent[find(c.a)] = find(c.other)
    groups: dict[int, list[StepContact]] = {}
    for c in contacts:
        groups.setdefault(find(c.a), []).append(c)
    return sorted(groups.values(), key=lambda g: g[0].index)
