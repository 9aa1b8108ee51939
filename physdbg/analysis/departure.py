"""Where a run of another engine departs from physdbg's exact run of the same scene, and why.

``physdbg check-run`` records physdbg's run of the scene with the foreign run's own time
steps; ``compare`` then finds the **first departure** (the first frame where a body is off
by more than the tolerance) and judges **every step on its own**: physdbg takes one exact
step from the foreign run's state at the step's start (so a difference made earlier is not
blamed again), and where the foreign step ends elsewhere, the two are compared.

A foreign run has no contact records, so its contacts are read off its trajectory: a
**kick** is a step in which a body's velocity changed by more than the scene's forces
explain (KICK_FRACTION of its speed). physdbg's contacts in the step are matched with the
kicks of the same bodies (in the step or the next), and judged:

* no kick and the body went through the wall or sphere: **tunnelling**;
* a kick at another time than physdbg's exact time of impact: **bounce-time** (the depth
  the body had reached when it was kicked says that the engine tested where steps end);
* a kick that leaves the contact at another normal speed than the restitution gives:
  **contact-energy** (an effective restitution below 0 is an impulse of the wrong sign,
  above 1 an energy gain);
* contacts of one step that share a body (a chain, as in a cradle) are judged as a group:
  momentum kept and no energy gained but other velocities is **collision-order**;
* a kick where physdbg has no contact: **extra-contact**; physdbg's contact with neither a
  kick nor a crossing: **missed-contact**;
* contacts of one step at one instant that share a sphere, taken in another order than
  physdbg's (which one goes first is not the model's to say): a **tie**, found by taking
  physdbg's step again with the tied spheres numbered so that it takes them in the run's
  order. A tie that parts the runs is not blamed: the reference goes on from physdbg's step
  taken in the run's order (``_continue_reference``), and the comparison with it;
* a step with neither that still ends elsewhere: **drift**; the foreign engine's
  **integrator** is named from its free steps (which velocity moved the body: the step's
  first, its last, or their mean).

Every judgement is made from positions and velocities alone, so it works for any engine
whose run can be written in the foreign-run format (docs/foreign-runs.md).

Why one module of this size: the judgements are methods of one ``_Comparison`` because
they share its state — both runs' arrays, the kicks and which of them a contact already
took, the local steps taken from the run's state — and they form a decision tree (a
missed contact, then tunnelling or a late bounce, then energy). The parts that stand on
their own are apart already (the impulse mistakes: restitution_mistakes.py; the growth fit:
align.py; the words for tunnelling: tunnel_words.py). Splitting the rest means turning that
shared state into a record the judges take one at a time, which is a change of its own.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import asdict, dataclass, field

import numpy as np

from ..errors import CheckRunError
from ..events import KIND_MESH, KIND_NAMES, KIND_WALL, PARTNER_IS_SPHERE, contact_words, partner_words
from .quiet import quiet_numerics
from .restitution_mistakes import (MISTAKE_SPHERES, RESTITUTION_MISTAKES, RESTITUTION_TOLERANCE,
                                   restitution_mistake, step_with_mistake)
from .tunnel_words import why_tunnelled

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


# ----------------------------------------------------------------------------- compare
def compare(foreign, reference, atol: float | None = None, rtol: float | None = None,
            verify: bool = True, set_aside: list[dict] | None = None,
            subject: str = "the run departs from physdbg's") -> CheckRunReport:
    """Compare a foreign run's recording with physdbg's recording of the same scene and
    steps (paths or open Recordings; any detail level). verify: check every state read
    against its stored hash and the frame index. set_aside: the own-rule departures
    (evidence dicts) of an earlier comparison, whose rules the reference was recorded
    without (api.check_run): said in the report and its headline. subject: how the
    headline names the departure (diff says which run departs from which)."""
    from ..record.reader import opened

    with opened(foreign, reference, verify=verify) as (rf, rr), quiet_numerics():
        return _Comparison(rf, rr, DEFAULT_ATOL if atol is None else float(atol),
                           DEFAULT_RTOL if rtol is None else float(rtol), set_aside or [], subject).run()


class _Comparison:
    def __init__(self, rf, rr, atol: float, rtol: float, set_aside: list[dict],
                 subject: str = "the run departs from physdbg's"):
        self.rf, self.rr, self.atol, self.rtol = rf, rr, atol, rtol
        self.set_aside = set_aside
        self.subject = subject  # the headline's words for who departs from whom
        self.runs = _load(rf, rr)
        h = rr.header
        self.scene = rr.scene
        self.radius, self.inv, self.walls = h.radius, h.inverse_mass, h.walls
        self.names = h.walls.partner_names()
        self.wall_names = list(h.walls.names)
        settings = rr.meta["settings"]
        self.settings = settings
        gravity = np.asarray(settings.get("gravity", (0.0, 0.0, 0.0)), dtype=float)
        self.acc = np.where((h.inverse_mass > 0)[:, None], h.gravity_scale[:, None] * gravity[None, :], 0.0)
        self.drag = float(settings.get("drag", 1.0))
        foreign = rf.meta.get("foreign") or {}
        self.estimated = foreign.get("velocities") == "estimated"
        self.departures: list[Departure] = []
        self.notes: list[str] = []
        self.judged = 0
        self.run_decay: float | None = None  # the run's own drag factor a step, when it is not the scene's
        self.ties: list[Departure] = []  # ties the reference went on from in the run's order (_tie_parts)
        self.mistake_found: str | None = None  # the impulse mistake that reproduced a chain's step (_mistaken_chain)
        self.mistake_misses = 0  # chains that no impulse mistake reproduced, while none has

    def run(self) -> CheckRunReport:
        if self.estimated:
            self.notes.append("velocities estimated from positions: bodies compared by position only")
        first = self._first_departure()
        while first is not None and len(self.ties) < MAX_TIES and self._tie_parts(first):
            first = self._first_departure()
        if len(self.ties) == MAX_TIES and first is not None:
            self.notes.append(f"physdbg's reference went on from {MAX_TIES} ties taken in the run's order and no "
                              f"further: a tie after them is named where its step departs, not followed")
        self._measure_drag()
        self._immovable_moved()
        kicked = self._kick_sizes() > self._kick_thresholds()  # (F-1, N)
        self.kicked = kicked
        self.integrator = self._integrator(kicked)
        self._non_finite()
        self.kicks = self._kicks(kicked) if first is not None else {}  # (read only when steps are judged)
        if first is not None:  # before it the runs agree, so there is nothing to judge
            self._judge_steps(max(first.step, 1))
            if not any(_involves(d, first.body) or d.kind in _RUN_WIDE for d in self.departures):
                if not self._slept(first):
                    self._no_step_departs(first)
        listed = self._fold(self.departures)
        if first is not None:
            first.cause = self._cause_of(first)
        contacts = int(self.rr.stats()["contacts"].sum()) if self.rr.frames > 1 else 0
        return CheckRunReport(str(self.rf.path), str(self.rr.path), self.rr.header.name, len(self.runs.t) - 1,
                              self.rr.header.count, self.atol, self.rtol,
                              "estimated" if self.estimated else "given", first, listed, self.integrator, self.judged,
                              contacts, self._headline(first, listed), self.notes, self.set_aside,
                              [{**d.evidence, "step": d.step} for d in self.ties])

    def _beyond(self, x, v, x_ref, v_ref) -> np.ndarray:
        """(..., N) bool: bodies off by more than the tolerance (velocities skipped when estimated)."""
        dx = np.linalg.norm(x - x_ref, axis=-1)
        off = (dx > self.atol + self.rtol * np.linalg.norm(x_ref, axis=-1)) | ~np.isfinite(dx)
        if not self.estimated:
            dv = np.linalg.norm(v - v_ref, axis=-1)
            off |= (dv > self.atol + self.rtol * np.linalg.norm(v_ref, axis=-1)) | ~np.isfinite(dv)
        return off

    # ------------------------------------------------------------------ the first departure
    def _first_departure(self) -> FirstDeparture | None:
        """The first frame where a body is off, read in chunks of about CHUNK_BODY_STEPS
        (the temporaries of a whole long run would be several times its size)."""
        r = self.runs
        chunk = max(1, CHUNK_BODY_STEPS // max(r.xf.shape[1], 1))
        for start in range(0, len(r.t), chunk):
            stop = start + chunk
            beyond = self._beyond(r.xf[start:stop], r.vf[start:stop], r.xr[start:stop], r.vr[start:stop])
            frames = np.flatnonzero(beyond.any(axis=1))
            if len(frames):
                break
        else:
            return None
        off, k = beyond[frames[0]], start + int(frames[0])
        dx = np.linalg.norm(r.xf[k] - r.xr[k], axis=1)
        dv = np.linalg.norm(r.vf[k] - r.vr[k], axis=1)
        score = np.where(off, np.nan_to_num(dx, nan=np.inf) + np.nan_to_num(dv, nan=np.inf), -1.0)
        body = int(np.argmax(score))
        return FirstDeparture(k, float(r.t[k]), body, float(dx[body]), float(dv[body]), int(off.sum()), "")

    def _cause_of(self, first: FirstDeparture) -> str:
        """The kind of the earliest local departure of the body at or before the first
        departure, the most telling kind first where several fall in that step."""
        own = [d for d in self.departures if (_involves(d, first.body) or d.kind in _RUN_WIDE) and d.step <= first.step]
        if own:
            step = min(d.step for d in own)
            return min((d for d in own if d.step == step), key=lambda d: _PRIORITY.index(d.kind)).kind
        return "drift"

    # ------------------------------------------------------------------ integrator
    def _integrator(self, kicked: np.ndarray) -> dict | None:
        """Which integrator family moved the foreign bodies in their free steps (None when
        nothing accelerates, so every family moves them alike)."""
        r = self.runs
        if len(r.t) < 2 or not np.any(self.acc):
            return None
        free = ~kicked & np.isfinite(r.xf[1:]).all(axis=2) & np.isfinite(r.xf[:-1]).all(axis=2)
        free &= (self.inv > 0)[None, :]
        disp = r.xf[1:] - r.xf[:-1]
        v0, v1 = r.vf[:-1], r.vf[1:]
        if self.estimated:  # only step 1 has a known starting velocity (the scene's)
            free[1:] = False
            v0 = r.vr[:-1]
            v1 = v0 + self.acc[None, :, :] * r.dt[1:, None, None]
        if not free.any():
            return None
        dt = r.dt[1:, None, None]
        residual = {}
        for name, _, (w0, w1) in INTEGRATOR_FITS:
            miss = np.linalg.norm(disp - (w0 * v0 + w1 * v1) * dt, axis=2)[free]
            residual[name] = float(np.sqrt(np.mean(miss ** 2)))
        ranked = sorted(residual, key=residual.get)
        best, second = ranked[0], ranked[1]
        a = float(np.max(np.linalg.norm(self.acc, axis=1)))
        step_error = 0.5 * a * float(np.median(r.dt[1:])) ** 2
        if residual[best] > 0.25 * step_error + FIT_SLACK:
            words = (f"none of the usual integrators fits its free steps (the nearest, {best}, misses by "
                     f"{residual[best]:.3g} m a step on average): forces or drag differ from the scene's")
            return {"name": None, "residual": residual, "differs": True, "sentence": words}
        ours = family_of(self.settings.get("integrator", integrator_of(None)))
        described = dict((n, w) for n, w, _ in INTEGRATOR_FITS)[best]
        differs = best != ours
        sentence = f"your engine moves bodies like {described}"
        if differs:
            sentence += (f"; the scene's integrator ({self.settings.get('integrator')}) is {ours or 'of no family here'}, "
                         f"so in free flight "
                         f"under {a:.3g} m/s² the paths part by {step_error:.3g} m a step (a·dt²/2), growing as "
                         f"they go")
        else:
            sentence += f", the same family as the scene's integrator ({self.settings.get('integrator')})"
        if residual[second] - residual[best] < 1e-3 * step_error:
            sentence += "; its free steps fit two families equally, so this is a guess"
        return {"name": best, "residual": residual, "differs": differs, "sentence": sentence,
                "physdbg": ours, "step_error": step_error}

    # ------------------------------------------------------------------ kicks
    def _kick_sizes(self) -> np.ndarray:
        """(F-1, N) |Δv − the forces' Δv| over each step (estimated velocities: between
        the step's average and the next step's, assigned to the step's end)."""
        r = self.runs
        if self.estimated:
            out = np.zeros((len(r.t) - 1, r.xf.shape[1]))
            if len(r.t) > 2:
                change = r.vf[2:] - r.vf[1:-1] - self.acc[None, :, :] * r.dt[2:, None, None]
                out[:-1] = np.linalg.norm(change, axis=2)
            return np.nan_to_num(out, nan=0.0)
        dt = r.dt[1:, None, None]
        factor = self._decay(dt)
        forces = r.vf[:-1] * (factor - 1.0) + self.acc[None, :, :] * dt
        return np.nan_to_num(np.linalg.norm(r.vf[1:] - r.vf[:-1] - forces, axis=2), nan=0.0)

    def _change_beyond_forces(self, s: int, b: int) -> float:
        """|Δv − the forces' Δv| (m/s) of body b over step s, as _kick_sizes reads it."""
        r = self.runs
        if self.estimated:
            if s + 1 >= len(r.t):
                return 0.0
            change = r.vf[s + 1, b] - r.vf[s, b] - self.acc[b] * r.dt[s + 1]
        else:
            change = r.vf[s, b] - r.vf[s - 1, b] - (r.vf[s - 1, b] * (self._decay(r.dt[s]) - 1.0) + self.acc[b] * r.dt[s])
        return float(np.nan_to_num(np.linalg.norm(change), nan=0.0))

    def _decay(self, dt):
        """Drag's factor on the velocity over steps of dt (s): the scene's d^dt, or, once
        the run was found to apply drag its own way (_measure_drag), the run's, so that
        its drag is not taken for a contact in every step."""
        if self.run_decay is not None:
            return self.run_decay + 0.0 * dt
        return self.drag ** dt if 0.0 < self.drag < 1.0 else 1.0 + 0.0 * dt

    def _measure_drag(self) -> None:
        """The run's velocity decay per step in free flight, against the scene's drag
        v·d^dt (the seed: "incorporate time so drag changes if the frame rate varies"):
        a run that multiplies by d every step (drag-per-step) or not at all (drag-ignored)
        is named once, with the decay it shows, and its kicks are then measured with it."""
        self.run_decay = None
        r = self.runs
        if self.estimated or not 0.0 < self.drag < 1.0 or len(r.t) < 2:
            return
        v0, v1, dt = r.vf[:-1], r.vf[1:], r.dt[1:, None]
        speed2 = np.einsum("fij,fij->fi", v0, v0)
        moving = (self.inv > 0)[None, :] & np.isfinite(speed2) & (speed2 > 0) & np.isfinite(v1).all(axis=2)
        if not moving.any():
            return
        ratio = np.einsum("fij,fij->fi", v1 - self.acc[None, :, :] * dt[:, :, None], v0) / np.where(moving, speed2, 1)
        measured = ratio[moving]
        wanted = np.broadcast_to(self.drag ** dt, ratio.shape)[moving]
        mistakes = (("drag-per-step", np.full(measured.shape, self.drag)), ("drag-ignored", np.ones(measured.shape)))
        fits = {name: float(np.median(np.abs(measured - predicted))) for name, predicted in mistakes}
        if float(np.median(np.abs(measured - wanted))) <= 1e-9:
            return
        name = min(fits, key=fits.get)
        if fits[name] > 1e-9:
            return  # neither mistake: the integrator or the forces (drift, named later)
        self.run_decay = self.drag if name == "drag-per-step" else 1.0
        step = float(np.median(r.dt[1:]))
        k = int(np.flatnonzero(moving.any(axis=1))[0]) + 1
        body = int(np.flatnonzero(moving[k - 1])[0])
        if name == "drag-per-step":
            text = (f"your run multiplies the velocity by {float(np.median(measured)):.6g} every step, the drag "
                    f"d = {self.drag:g} itself; the seed's drag is v·d^t, so a step of {step:.4g} s takes "
                    f"d^dt = {self.drag ** step:.6g}. Drag per step makes the motion depend on the frame rate: "
                    f"at {1 / step:.3g} steps a second the speed falls to {self.drag ** (1 / step):.3g} of itself in "
                    f"one second instead of {self.drag:g}")
            advice = "multiply by d**dt (the time of the step), not by d: v = v * drag ** dt"
        else:
            text = (f"your run keeps the velocity in free flight (a decay of {float(np.median(measured)):.6g} a "
                    f"step) where the scene's drag d = {self.drag:g} takes d^dt = {self.drag ** step:.6g} a step")
            advice = "apply the scene's drag every step: v = v * drag ** dt"
        self.departures.append(Departure(name, k, body, text, advice,
                                         evidence={"measured": float(np.median(measured)), "drag": self.drag,
                                                   "expected": float(self.drag ** step), "dt": step}))

    def _immovable_moved(self) -> None:
        """An immovable sphere (inverse mass 0) that the run moves: named at the step it
        starts to move, with the sphere that hit it there in physdbg's run."""
        r = self.runs
        fixed = np.flatnonzero(self.inv == 0)
        if not len(fixed) or len(r.t) < 2:
            return
        moved = np.linalg.norm(r.xf[:, fixed] - r.xf[:1, fixed], axis=2) > self.atol
        moved |= np.linalg.norm(r.vf[:, fixed], axis=2) > self.atol
        frames, which = np.nonzero(moved)
        if not len(frames):
            return
        k, body = max(int(frames[0]), 1), int(fixed[which[0]])
        speed = float(np.linalg.norm(r.vf[k, body]))
        hit = None
        local = self._local_step(k)
        if local is not None:
            hit = next((c.other if c.a == body else c.a for c in local[2]
                        if PARTNER_IS_SPHERE[c.kind] and body in (c.a, c.other)), None)
        self.departures.append(Departure(
            "immovable-moved", k, body,
            f"sphere {body} is immovable (inverse mass 0 in the scene), yet your run moves it from step {k} on "
            f"({speed:.3g} m/s at its end" + (f", after sphere {hit} hit it" if hit is not None else "") + ")",
            "an immovable body takes no impulse: scale each impulse by the body's inverse mass (0 for an immovable "
            "one), never by a mass of 1 or by 1/m with m = 0", other=hit,
            evidence={"speed": speed, "hit_by": hit}))

    def _kick_thresholds(self) -> np.ndarray:
        r = self.runs
        speed = np.nan_to_num(np.linalg.norm(r.vf[:-1], axis=2))
        return KICK_FRACTION * (speed + np.linalg.norm(self.acc, axis=1)[None, :] * r.dt[1:, None]) + 1e-12

    def _kicks(self, kicked: np.ndarray) -> dict[tuple[int, int], Kick]:
        """{(step, body): the Kick of that body in that step}."""
        r = self.runs
        steps, bodies = np.nonzero(kicked)
        out = {}
        for s0, i in zip(steps.tolist(), bodies.tolist(), strict=True):
            s = s0 + 1
            tau = self._kick_time(s, i)
            out[(s, i)] = Kick(s, i, tau, float(r.t[s - 1] + tau))
        return out

    def _kick_time(self, s: int, i: int) -> float:
        """When in step s body i was kicked (s after the step began): the instant that
        splits the step's displacement between the velocity before and after the kick."""
        r = self.runs
        dt = float(r.dt[s])
        if self.estimated:
            return dt  # the change shows between two step averages: at the frame between them
        fit = (self.integrator or {}).get("name") or "exact"
        a, v0, v1 = self.acc[i], r.vf[s - 1, i], r.vf[s, i]
        disp = r.xf[s, i] - r.xf[s - 1, i]
        if fit == "exact":  # x1 − x0 = v0·τ + aτ²/2 + (v1 − a(dt − τ))(dt − τ) + a(dt − τ)²/2, solved for τ
            along = v0 - v1 + a * dt
            lever = disp - v1 * dt + 0.5 * a * dt * dt
        else:  # a straight path: the velocity after the forces' update, then the kicked one
            _, w1 = dict((n, w) for n, _, w in INTEGRATOR_FITS)[fit]
            along = v0 + w1 * a * dt - v1
            lever = disp - v1 * dt
        size = float(along @ along)
        if not size > 0 or not math.isfinite(size):
            return dt
        return float(np.clip((lever @ along) / size, 0.0, dt))

    # ------------------------------------------------------------------ step by step
    def _local_step(self, s: int, start: tuple[np.ndarray, np.ndarray] | None = None,
                    order: np.ndarray | None = None, **settings):
        """physdbg's exact step s from the foreign state at its start (or ``start``, (x, v)
        (N, 3) each): (x, v, contacts as dicts), with the scene's settings or, given, some of
        them replaced (ordering="index"). order (N,): the world numbers sphere order[k] as k
        (to take a tie in another order); what it returns is in the scene's numbering."""
        import dataclasses

        from ..engine import World
        from ..errors import WorldStuck
        from ..engine.state import State
        from ..events import Contacts
        from ..observe import ListObserver

        r, st = self.runs, self.scene.state
        if start is not None:
            x0, v0 = start
        else:
            x0, v0 = r.xf[s - 1], r.vf[s - 1]
            if self.estimated:  # the velocity at the step's start: the step's average less half the forces' change
                v0 = r.vf[s] - 0.5 * self.acc * float(r.dt[s])
        k = np.arange(st.count) if order is None else np.asarray(order)
        if order is None:  # (the common case: no copies of the constants)
            state = State(np.array(x0), np.array(v0), st.inverse_mass, st.radius, st.restitution, st.gravity_scale)
        else:
            state = State(np.ascontiguousarray(x0[k]), np.ascontiguousarray(v0[k]), st.inverse_mass[k], st.radius[k],
                          st.restitution[k], st.gravity_scale[k])
        seen = ListObserver()
        world = World(state, self.scene.walls, dataclasses.replace(self.scene.settings, **settings) if settings
                      else self.scene.settings, seen)
        world.time = float(r.t[s - 1])
        try:
            world.step(float(r.dt[s]))
        except WorldStuck:
            return None
        if order is None:
            x, v = state.positions, state.velocities
        else:  # back to the scene's numbering
            x, v = np.empty_like(state.positions), np.empty_like(state.velocities)
            x[k], v[k] = state.positions, state.velocities
        out = []
        batches = seen.of_type(Contacts)
        c = batches[0] if batches else None
        resting = c.resting if c is not None else None
        for j in range(len(c) if c is not None else 0):
            kind, a, other = int(c.kind[j]), int(k[c.a[j]]), int(c.other[j])
            other = int(k[other]) if PARTNER_IS_SPHERE[kind] else other
            out.append(StepContact(s, j, kind, a, other, float(c.time_in_step[j]),
                                   float(r.t[s - 1] + c.time_in_step[j]), c.normal[j].copy(),
                                   float(c.restitution[j]), bool(resting[j]), abs(float(c.closing_speed[j])),
                                   c.point[j] + c.normal[j] * self.radius[a]))
        return x, v, out

    def _judge_steps(self, start: int) -> None:
        """Each step from ``start`` on where the foreign run ends elsewhere than physdbg's
        step from the same state."""
        r, kicks = self.runs, self.kicks
        drift: dict[int, list[int]] = {}  # body -> steps that drift with no contact
        for s in range(start, len(r.t)):
            if not (np.isfinite(r.xf[s - 1]).all() and np.isfinite(r.vf[s - 1]).all()):
                break  # the non-finite departure says it
            local = self._local_step(s)
            if local is None:
                continue
            x, v, contacts = local
            off = self._beyond(r.xf[s], r.vf[s], x, v)
            if not off.any() or any(explains(self, s, contacts, off) for explains in STEP_EXPLANATIONS):
                for c in contacts:
                    for b in self._bodies(c):
                        for k in (s, s + 1) if off.any() else (s,):
                            if (k, b) in kicks:
                                kicks[(k, b)].matched = True
                continue
            slow = {b: c for c in contacts if c.resting or self._slow(c, s) for b in self._bodies(c)}
            resting = set(slow)
            for b in resting:
                for k in (s, s + 1):
                    if (k, b) in kicks:
                        kicks[(k, b)].matched = True
            moving = [c for c in contacts if not (c.resting or self._slow(c, s))]
            touched = set()
            for group in _chains(moving):
                bodies = {b for c in group for b in self._bodies(c)}
                touched |= bodies
                if not any(off[b] for b in bodies):
                    for b in bodies:
                        if (s, b) in kicks:
                            kicks[(s, b)].matched = True
                    continue
                self.judged += len(group)
                if len(group) == 1:
                    self._judge_one(group[0])
                else:
                    self._judge_chain(s, group, v)
            for b in np.flatnonzero(off).tolist():
                if (b in resting and b not in touched and self.inv[b] > 0
                        and (slow[b].resting or self._resting_speed(slow[b], s))):
                    self._resting(slow[b], b, x)  # (not the aftermath of a kick judged before)
                if b in touched or b in resting:
                    continue
                kick = kicks.get((s, b))
                if kick is not None and not kick.matched:
                    kick.matched = True
                    self._extra(kick)
                elif kick is None and self.inv[b] > 0 and np.isfinite(r.xf[s, b]).all() and np.isfinite(r.vf[s, b]).all():
                    drift.setdefault(b, []).append(s)  # (a body that turned NaN is the non-finite departure)
        self._drift(drift)

    def _no_step_departs(self, first: FirstDeparture) -> None:
        """Every step, taken from the run's own state, ends where physdbg's does, yet the
        runs part: chaos when the gap between them grows at a finite-time Lyapunov exponent
        (align.Growth.judge_chaos: steady exponential growth over e-folds while spheres
        collide), else unexplained."""
        from .align import fit_growth

        r = self.runs
        frames = np.arange(first.step, len(r.t))
        gaps = np.linalg.norm(r.xf[frames] - r.xr[frames], axis=2)
        gaps = np.where(np.isfinite(gaps).all(axis=1), gaps.max(axis=1), np.inf)
        movable = self.inv > 0
        radius = float(self.radius[movable].min()) if movable.any() else float(self.radius.min())
        growth = fit_growth(frames, r.t[frames], gaps, radius, first.step, float(r.t[first.step]),
                            float(r.dt[first.step]))
        collisions = self.rr.stats(first.step)["collisions"] if self.rr.frames > first.step else np.zeros(0)
        growth.judge_chaos(bool(np.any(collisions > 0)))
        steps = "every step, taken from your run's own state at its start, ends where physdbg's exact step does"
        if growth.chaotic:
            self.departures.append(Departure(
                "chaos", first.step, first.body,
                f"{steps} (within the tolerance), and the runs part because differences below it grow: "
                f"{growth.sentence()}",
                "nothing your engine does in a step differs from physdbg's beyond the tolerance: to compare a chaotic "
                "scene for longer, give it the scene's step lengths exactly, or compare with a looser --atol",
                evidence={"lyapunov": growth.rate, "efolds": growth.efolds}))
        else:
            self.departures.append(Departure(
                "unexplained", first.step, first.body,
                f"{steps} (within the tolerance), yet the runs part, and not as chaos does ({growth.sentence()}): "
                f"physdbg cannot say why",
                "small differences in every step add up: check that the run's steps are the scene's (dt = "
                f"{float(np.median(r.dt[1:])):.6g} s), and its forces and drag, to the last digit",
                evidence={"growth": growth.as_dict()}))

    def _slept(self, first: FirstDeparture) -> bool:
        """Every step ends where the run's does, yet the runs part where physdbg's sleeping
        rule froze a sphere (at rest in the reference, with spheres asleep in that step)
        that the run keeps moving: named own-rule, as OWN_RULES are (SLEEPING_RULE;
        check-run then compares against physdbg without sleeping)."""
        speed = float(self.settings.get("sleep_speed") or 0.0)
        r, k, b = self.runs, first.step, first.body
        if speed <= 0 or k < 1 or np.any(r.vr[k, b]) or not np.any(r.vf[k, b]):
            return False
        asleep = self.rr.stats(k, k + 1)["asleep"] if self.rr.frames > k else np.zeros(0)
        if not (len(asleep) and asleep[0] > 0):
            return False
        since = k
        while since > 1 and not np.any(r.vr[since - 1, b]):
            since -= 1
        code, setting, value, name = SLEEPING_RULE
        moving = float(np.linalg.norm(r.vf[k, b]))
        did = (f"put sphere {b} to sleep (frozen from step {since}, once slower than sleep_speed = {speed:g} m/s for "
               f"sleep_time = {float(self.settings.get('sleep_time') or 0.0):g} s), where your run keeps it moving "
               f"({moving:.3g} m/s at step {k})")
        flag = f"-s {setting}={value:g}"
        self.departures.append(Departure(
            "own-rule", k, b,
            f"physdbg's {name} {did}; every step taken from your run's state ends where your run's does: the seed's "
            f"model has no sleeping, so this is physdbg's modelling, not a mistake of your engine",
            f"nothing to change in your engine; compare with {flag} to check the rest of the run against physdbg "
            f"without sleeping (check-run does this itself)",
            evidence={"rule": code, "setting": setting, "value": value, "name": name, "contacts": [], "said": did}))
        return True

    def _own_rule(self, s: int, contacts: list[StepContact], off: np.ndarray) -> bool:
        """The run's step s is physdbg's step taken without one of its own modelling rules
        (OWN_RULES): named own-rule, with what the rule did to which contact. Tried where a
        step with contacts ends elsewhere, for each rule the reference has on."""
        if not contacts:
            return False
        r = self.runs
        for code, setting, value, name in OWN_RULES:
            if self.settings.get(setting, value) == value:
                continue
            alternative = self._local_step(s, **{setting: value})
            if alternative is None or self._beyond(r.xf[s], r.vf[s], alternative[0], alternative[1]).any():
                continue
            changed = _changed_contacts(contacts, alternative[2])
            did = self._rule_did(code, *changed[0], contacts) if changed else f"changed the contacts of step {s}"
            if len(changed) > 1:
                did += f", and {len(changed) - 1} more contact{'s' if len(changed) > 2 else ''} of the step"
            body = int(np.flatnonzero(off)[0])
            flag = f"-s {setting}={value:g}"
            pairs = [[c.a, c.other, c.kind] for c, _ in changed]
            self.departures.append(Departure(
                "own-rule", s, changed[0][0].a if changed else body,
                f"physdbg's {name} {did}; without the rule ({flag}) physdbg's step {s}, taken from your run's "
                f"state, ends where your run's does: the seed's model has no such rule, so this is physdbg's "
                f"modelling, not a mistake of your engine",
                f"nothing to change in your engine for this step; compare with {flag} to check the rest of the run "
                f"against physdbg without the rule (check-run does this itself)",
                other=changed[0][0].other if changed and PARTNER_IS_SPHERE[changed[0][0].kind] else None,
                evidence={"rule": code, "setting": setting, "value": value, "name": name, "contacts": pairs,
                          "said": did}))
            return True
        return False

    def _ties_in(self, contacts: list[StepContact], dt: float) -> list[list[StepContact]]:
        """The step's ties: groups of contacts at one instant (within SAME_INSTANT of the
        step) that share a sphere, in physdbg's order."""
        from ..engine.resolve import SAME_INSTANT

        groups: list[list[StepContact]] = []
        for c in contacts:
            if groups and abs(c.tau - groups[-1][0].tau) <= SAME_INSTANT * dt:
                groups[-1].append(c)
            else:
                groups.append([c])
        return [g for g in groups if len(g) > 1 and any(
            set(self._bodies(c)) & set(self._bodies(d)) for i, c in enumerate(g) for d in g[i + 1:])]

    def _tie_orders(self, s: int, contacts: list[StepContact]):
        """Each (tie, order, the local step) of step s taken from the run's state with a tie's
        spheres numbered in another order (``_local_step``'s order)."""
        import itertools

        n = self.scene.state.count
        for tie in self._ties_in(contacts, float(self.runs.dt[s])):
            spheres = sorted({b for c in tie for b in self._bodies(c)})
            renumbered = (itertools.permutations(spheres) if len(spheres) <= TIE_SPHERES
                          else [tuple(reversed(spheres))])
            for numbering in renumbered:
                if list(numbering) == spheres:
                    continue
                order = np.arange(n)
                order[spheres] = numbering
                step = self._local_step(s, order=order, space_order="given")
                if step is not None:
                    yield tie, order, step

    def _tie(self, s: int, contacts: list[StepContact], off: np.ndarray) -> bool:
        """The run's step s is physdbg's step with contacts at one instant taken in another
        order (a tie: ``_ties_in``): named tie, with both orders. Tried where a step of
        several contacts ends elsewhere."""
        if len(contacts) < 2:
            return False
        from ..engine.resolve import SAME_INSTANT

        r = self.runs
        for tie, order, (x, v, taken) in self._tie_orders(s, contacts):
            if self._beyond(r.xf[s], r.vf[s], x, v).any():
                continue
            instant = [c for c in taken if abs(c.tau - tie[0].tau) <= SAME_INSTANT * float(r.dt[s])]
            ours = [self._listed(c) for c in tie]
            theirs = [self._listed(c) for c in instant] or ours
            if theirs == ours:
                continue  # the same order, and yet the run's step: not a tie's doing
            tied = " and ".join(self._sequence([c]) for c in dict.fromkeys(map(tuple, ours)))
            said = (f"in step {s} the contacts {tied} happen at one instant (t = {tie[0].time:.6g} s) and your "
                    f"run takes {self._sequence(theirs[:1])} first")
            self.departures.append(Departure(
                "tie", s, tie[0].a,
                f"{said}: physdbg takes {self._sequence(ours)}; your run {self._sequence(theirs)}. Taken in your run's "
                f"order, physdbg's step {s} from your run's state ends where your run's does. Which of two contacts at one instant "
                f"goes first is not the model's to say (each is the earliest), so this is a tie, not a mistake",
                "nothing to change in your engine: either order is right. (Runs that take ties in one order compare "
                "bit for bit; physdbg takes them in the order its tests found them.)",
                other=tie[0].other if PARTNER_IS_SPHERE[tie[0].kind] else None,
                evidence={"time": tie[0].time, "physdbg_order": ours, "run_order": theirs,
                          "numbering": order.tolist(), "said": said}))
            return True
        return False

    def _tie_parts(self, first: FirstDeparture) -> bool:
        """Where the runs first part at a tie (``_tie``), the reference goes on from physdbg's
        step taken in the run's order (``_continue_reference``): True when it did."""
        s = first.step
        local = self._local_step(s) if s >= 1 else None
        if local is None:
            return False
        x, v, contacts = local
        off = self._beyond(self.runs.xf[s], self.runs.vf[s], x, v)
        if not off.any():
            return False  # the step itself ends where physdbg's does: no tie parted them
        found = len(self.departures)
        if not self._tie(s, contacts, off):
            return False
        tie = self.departures.pop(found)
        self.ties.append(tie)
        self._continue_reference(s, np.asarray(tie.evidence["numbering"]))
        return True

    def _continue_reference(self, s: int, order: np.ndarray) -> None:
        """Replace physdbg's reference from frame s on: its step s from its own state,
        taken in ``order`` (a tie in the run's order), then every later step from there, in
        one world as a run takes them."""
        import dataclasses

        from ..engine import World
        from ..engine.state import State
        from ..errors import WorldStuck  # (a NaN or infinity is one too: NonFiniteState)

        r, st = self.runs, self.scene.state
        step = self._local_step(s, (r.xr[s - 1], r.vr[s - 1]), order, space_order="given")
        if step is None:
            r.xr[s:], r.vr[s:] = np.nan, np.nan
            return
        r.xr[s], r.vr[s] = step[0], step[1]
        state = State(step[0].copy(), step[1].copy(), st.inverse_mass, st.radius, st.restitution, st.gravity_scale)
        world = World(state, self.scene.walls, dataclasses.replace(self.scene.settings))
        world.time = float(r.t[s])
        for k in range(s + 1, len(r.t)):
            try:
                world.step(float(r.dt[k]))
            except WorldStuck:
                r.xr[k:], r.vr[k:] = np.nan, np.nan
                return
            r.xr[k], r.vr[k] = state.positions, state.velocities

    def _rule_did(self, code: str, c: StepContact, other: StepContact | None, contacts: list[StepContact]) -> str:
        """What rule ``code`` did to contact c of a step (other: the same contact without the
        rule), in words: "made the contact 2–3 in step 22 elastic (16 µs after ...)"."""
        what = f"the contact {self._pair_words(c)} in step {c.step}"
        if code == "rapid-contact":
            earlier = [d for d in contacts if d.index < c.index and set(self._bodies(d)) & set(self._bodies(c))]
            when = ""
            if earlier:
                d = earlier[-1]
                when = (f" ({(c.tau - d.tau) * 1e6:.3g} µs after {self._pair_words(d)}, within "
                        f"rapid_contact_time = {self.settings.get('rapid_contact_time'):g} s)")
            if c.resting:
                return f"held {what}{when}"
            e = "elastic" if c.restitution == 1.0 else f"e = {c.restitution:g}"
            want = f" instead of e = {other.restitution:g}" if other is not None else ""
            return f"made {what} {e}{want}{when}"
        return f"held {what} as resting" if c.resting else f"changed {what}"

    def _index_ordered(self, s: int, contacts: list[StepContact], off: np.ndarray) -> bool:
        """The run's step s is physdbg's step taken with ordering = index (the contacts
        predicted at the step's start resolved in index order, none looked for after): named
        index-order. Tried where a step of several contacts ends elsewhere."""
        if len(contacts) < 2 or self.settings.get("ordering", "time") == "index":
            return False
        r = self.runs
        alternative = self._local_step(s, ordering="index")
        if alternative is None or self._beyond(r.xf[s], r.vf[s], alternative[0], alternative[1]).any():
            return False
        body = int(np.flatnonzero(off)[0])
        dt = float(r.dt[s])
        order = ", then ".join(f"{self._pair_words(c)} at {c.tau / dt:.2f}·dt" for c in contacts[:6])
        indexed = [c for c in (alternative[2] or [])]
        self.departures.append(Departure(
            "index-order", s, body,
            f"physdbg resolves {order}{' …' if len(contacts) > 6 else ''}; your run ends step {s} exactly where "
            f"physdbg does when it resolves only the contacts predicted at the step's start, in index order "
            f"(ordering = index: {len(indexed)} contact{'s' if len(indexed) != 1 else ''}), so a contact that an "
            f"earlier one creates within the step is never looked for",
            "resolve contacts one at a time in time order (earliest time of impact first), and look again for new "
            "contacts after each: a chain of touching spheres passes its impulse along only that way",
            evidence={"physdbg_order": [[c.a, c.other, c.kind] for c in contacts],
                      "index_order": [[c.a, c.other, c.kind] for c in indexed]}))
        return True

    def _resting(self, c: StepContact, b: int, x: np.ndarray) -> None:
        """Sphere b ends step c.step elsewhere than physdbg's step, whose only contact of b
        is resting or slow (_slow: not judged one by one, as engines hold such contacts
        their own ways): named resting, with where the run left b. x: physdbg's positions
        (N, 3) at the step's end."""
        r = self.runs
        s = c.step
        b_c = dataclasses.replace(c, a=b, other=c.a if b == c.other else c.other) if PARTNER_IS_SPHERE[c.kind] else c
        apart = float(np.linalg.norm(r.xf[s, b] - x[b]))
        gap = self._gap(b_c, b, r.xf[s, b], s, float(r.dt[s]))
        inside = f", {-gap * 1000:.3g} mm inside {self._what(b_c)}" if gap < -self.atol else ""
        slow = (f"a slow contact with {self._what(b_c)} (closing at {c.closing:.3g} m/s, slower than the forces "
                f"give in {RESTING_SPEED_STEPS:g} steps), which it {'holds' if c.resting else 'resolves'}"
                if self._resting_speed(c, s) else
                f"a contact with {self._what(b_c)} (closing at {c.closing:.3g} m/s) that it holds (its resting or "
                f"rapid-contact rule)")
        self._add("resting", s, b_c,
                  f"sphere {b}: physdbg's step {s}, taken from your run's state, has {slow}; your run ends "
                  f"the step with sphere {b} {apart * 1000:.3g} mm from where physdbg's does{inside}",
                  "slow and resting contacts are held in different ways by different engines, and are not judged "
                  "one by one; a body that sinks into what it rests on needs a contact that acts at zero closing "
                  "speed (an overlap tested where each step ends, or a held resting contact)",
                  {"time": c.time, "apart": apart, "gap": gap, "held": bool(c.resting)})

    def _mistaken_chain(self, s: int, contacts: list[StepContact], off: np.ndarray) -> bool:
        """The run's step s is physdbg's step from the run's state with every sphere pair's
        impulse made with one of RESTITUTION_MISTAKES, each contact once a step
        (restitution_mistakes.step_with_mistake): named that mistake. Tried where a chain of
        moving contacts (one step's contacts sharing spheres) ends elsewhere, in scenes of up
        to MISTAKE_SPHERES spheres: there the speeds around each contact are not in the run's
        frames, so the mistake that reproduces the step is named rather than the chain's
        symptoms (a single contact's effective restitution is read off it: _judge_energy)."""
        moving = [c for c in contacts if not (c.resting or self._slow(c, s))]
        chains = [g for g in _chains(moving) if len(g) > 1 and any(PARTNER_IS_SPHERE[c.kind] for c in g)]
        if not chains or self.scene.state.count > MISTAKE_SPHERES or self.mistake_misses >= MISTAKE_MISSES:
            return False
        r = self.runs
        right = np.asarray(self.scene.state.restitution, dtype=float)
        # the mistake found in an earlier step first; after MISTAKE_MISSES chains that none
        # reproduced, the run makes none of them and they are not tried again
        for code, predicted, words, advice in sorted(RESTITUTION_MISTAKES, key=lambda m: m[0] != self.mistake_found):
            if all(abs(predicted(float(e)) - e) <= 2 * RESTITUTION_TOLERANCE for e in right):
                continue  # the same as the scene's own restitution here (e² for e = 1)
            # each contact once a step (an engine's guard), and, for a mistake that parts the
            # pair (an effective restitution of 0 or more), also without the guard
            guards = (True, False) if min(predicted(float(e)) for e in right) >= 0 else (True,)
            for once in guards:
                stepped = step_with_mistake(self.scene, r.xf[s - 1], r.vf[s - 1], float(r.t[s - 1]),
                                            float(r.dt[s]), predicted, once)
                if stepped is not None and not self._beyond(r.xf[s], r.vf[s], *stepped).any():
                    break
            else:
                continue
            chain = chains[0]
            first = next(c for c in chain if PARTNER_IS_SPHERE[c.kind])
            want = float(first.restitution)
            dt = float(r.dt[s])
            order = ", then ".join(f"{self._pair_words(c)} at {c.tau / dt:.2f}·dt" for c in chain[:6])
            bodies = sorted({b for g in chains for c in g for b in self._bodies(c)})
            self._add(code, s, first,
                      f"in the chain {order}{' …' if len(chain) > 6 else ''}, your run's step {s} is physdbg's step "
                      f"from your run's state with each sphere's restitution replaced by the mistake's effective "
                      f"restitution ({predicted(want):.3g} for {self._pair_words(first)}, where physdbg applies "
                      f"e = {want:g}){', each contact once' if once else ''}: {predicted(want):.3g} = {words}", advice,
                      {"restitution": predicted(want), "expected": want, "bodies": bodies,
                       "physdbg_order": [[c.a, c.other, c.kind] for c in chain], "reproduced": True})
            self.mistake_found = code
            return True
        self.mistake_misses += self.mistake_found is None
        return False

    def _slow(self, c: StepContact, s: int) -> bool:
        """Not judged one by one: a contact closing slower than the forces' speed over
        RESTING_SPEED_STEPS steps (a resting contact, whose handling differs between engines
        by design), or one at the very start of a step right after the foreign run kicked
        the body (the aftermath of that kick, already judged)."""
        if c.tau <= TIME_TOLERANCE * float(self.runs.dt[s]) and any(
                getattr(self.kicks.get((k, b)), "matched", None) for b in self._bodies(c) for k in (s - 1, s)):
            return True
        return self._resting_speed(c, s)

    def _resting_speed(self, c: StepContact, s: int) -> bool:
        """Contact c closes slower than the speed the forces give its spheres in
        RESTING_SPEED_STEPS steps (a resting contact)."""
        a = max(float(np.linalg.norm(self.acc[b])) for b in self._bodies(c))
        return a > 0 and c.closing < RESTING_SPEED_STEPS * a * float(self.runs.dt[s])

    @staticmethod
    def _bodies(c: StepContact) -> tuple[int, ...]:
        return bodies_of(c.kind, c.a, c.other)

    def _kick_for(self, c: StepContact) -> Kick | None:
        """The foreign kick of contact c: on its sphere (or the other sphere of a pair), in
        its step or the next."""
        for s in (c.step, c.step + 1):
            for b in self._bodies(c):
                k = self.kicks.get((s, b))
                if k is not None and not k.matched and self.inv[b] > 0:
                    return k
        return None

    def _judge_one(self, c: StepContact) -> None:
        r, kicks = self.runs, self.kicks
        if self._runaway(c):
            return
        kick = self._kick_for(c)
        s, dt = c.step, float(r.dt[c.step])
        if kick is None:
            crossing = self._crossing(c)
            if crossing is not None:
                self._tunnelled(c, crossing)
            elif not any(self.kicked[s - 1, b] for b in self._bodies(c) if self.inv[b] > 0):
                # (a change the forces do not explain that another contact took is a change all
                # the same: then nothing the frames show is missing, and nothing is said)
                change = max(self._change_beyond_forces(s, b) for b in self._bodies(c) if self.inv[b] > 0)
                self._add("missed-contact", s, c, f"{self._subject(c)}: physdbg, stepping from the same state, "
                                                  f"touches {self._what(c)} at t = {c.time:.6g} s "
                                                  f"({c.tau / dt:.2f}·dt); your run shows no change of velocity "
                                                  f"in that step beyond the forces' ({change:.3g} m/s)",
                          "look for contacts along each step's whole path; a contact within the step that your "
                          "engine did not see changes everything after it",
                          {"time": c.time, "velocity_change": change})
            return
        for b in self._bodies(c):
            k = kicks.get((kick.step, b))
            if k is not None:
                k.matched = True
        # how well a kick's instant is known: TIME_TOLERANCE, plus the part of the step's velocity
        # change that the forces make, since when the engine applied them is not known
        i, k = kick.body, kick.step + (1 if self.estimated else 0)  # estimated: between two averages
        change = float(np.linalg.norm(r.vf[min(k, len(r.t) - 1), i] - r.vf[k - 1, i]))
        slack = float(np.linalg.norm(self.acc[i])) * dt / change if change > 0 else 0.0
        if self._skipped_rest(c):
            self._judge_energy(c, kick, quiet_if_late=True)
            return
        late = abs(kick.time - c.time) > (TIME_TOLERANCE + slack) * dt
        if late:
            self._late(c, kick)
        self._judge_energy(c, kick, quiet_if_late=late)

    def _runaway(self, c: StepContact) -> bool:
        """The contact's bodies leave its step still approaching, at RUNAWAY times their
        speed or more, or with NaN or infinite velocities: what an impulse of the wrong sign
        does in an engine that looks again at once (the pair, pushed together at (2 + e)
        times its closing speed, meets again at the same instant, and again, until the
        numbers overflow). Named impulse-loop, with the meetings it takes to reach the
        run's speed; True when named."""
        r = self.runs
        s, bodies = c.step, self._bodies(c)
        if any(self.inv[b] == 0 for b in bodies) and len(bodies) == 1:
            return False
        dt = float(r.dt[s])
        start = max(float(np.linalg.norm(r.vf[s - 1, b])) for b in bodies) + float(np.linalg.norm(self.acc[bodies[0]])) * dt
        after = r.vf[s, c.a] - (r.vf[s, c.other] if PARTNER_IS_SPHERE[c.kind] else 0.0)
        normal_after = float(after @ c.normal)
        blown = not math.isfinite(normal_after)
        if not blown and not (normal_after < 0 and -normal_after >= RUNAWAY * max(start, c.closing, 1e-12)):
            return False
        e, closing = c.restitution, max(c.closing, 1e-300)
        factor = 2.0 + e
        if blown:
            outcome = "with NaN or infinite velocities"
            meetings = math.log(sys.float_info.max / closing) / math.log(factor)
            reached = f"passes the largest float after about {meetings:.0f} meetings"
        else:
            outcome = f"still approaching at {-normal_after:.3g} m/s"
            meetings = math.log(-normal_after / closing) / math.log(factor)
            reached = f"gets there after about {meetings:.0f} meetings"
        self._add("impulse-loop", s, c,
                  f"{self._both(c)}: they met at {closing:.3g} m/s at {c.tau / dt:.2f}·dt into step {s} and "
                  f"left the step {outcome}. An impulse of the wrong sign does this in an engine that looks for the "
                  f"next contact at once: it pushes the pair together at (2 + e) = {factor:.3g} times their closing "
                  f"speed, so they meet again at the same instant, and again: their speed {reached}",
                  "the impulse points the wrong way: j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b) pushes a along n (from b "
                  "towards a) and b against it. A bound on the contacts of a step (physdbg's max_contacts_per_step) "
                  "turns such a loop into an error instead of NaN",
                  {"closing_speed": closing, "factor": factor, "meetings": meetings,
                   "speed_after": None if blown else -normal_after})
        for k in (s, s + 1):
            for b in bodies:
                if (k, b) in self.kicks:
                    self.kicks[(k, b)].matched = True
        return True

    def _skipped_rest(self, c: StepContact) -> bool:
        """The run left sphere a where it touched for the rest of the step: its position at
        the step's end is physdbg's centre at the touch (the seed moves a body on after a
        bounce for the time the step has left)."""
        r = self.runs
        s, a = c.step, c.a
        dt = float(r.dt[s])
        if c.tau >= (1.0 - TIME_TOLERANCE) * dt or self.inv[a] == 0:
            return False
        centre = c.centre
        if np.linalg.norm(r.xf[s, a] - centre) > self.atol + self.rtol * float(np.linalg.norm(centre)):
            return False
        left = dt - c.tau
        self._add("skipped-rest", s, c,
                  f"{self._subject(c)} touched {self._what(c)} at {c.tau / dt:.2f}·dt into step {s} and stayed "
                  f"there for the rest of the step ({left:.3g} s, {left / dt:.2f}·dt); physdbg moves it on with its "
                  f"new velocity, to {float(np.linalg.norm(r.xf[s, a] - self._end_of(s)[a])):.3g} m from where your "
                  f"run left it",
                  "after resolving a contact at time τ into the step, move the body on with its new velocity for the "
                  "time left (dt − τ), and look for further contacts in that time", {"tau": c.tau, "left": left})
        return True

    def _end_of(self, s: int) -> np.ndarray:
        """physdbg's positions (N, 3) at the end of step s taken from the run's own start."""
        local = self._local_step(s)
        return local[0] if local is not None else np.full_like(self.runs.xf[s], np.nan)

    def _late(self, c: StepContact, kick: Kick) -> None:
        r = self.runs
        s, a = kick.step, kick.body
        dt = float(r.dt[c.step])
        x = r.xf[s - 1, a] + (r.xf[s, a] - r.xf[s - 1, a]) * (kick.tau / float(r.dt[s]))
        depth = -self._gap(c, a, x, s, kick.tau)
        shift = kick.time - c.time
        fraction = kick.tau / float(r.dt[s])
        where = (f"at the end of step {s}" if fraction >= 1 - TIME_TOLERANCE else
                 f"at the start of step {s}" if fraction <= TIME_TOLERANCE else f"{fraction:.2f}·dt into step {s}")
        text = (f"{self._subject(c)} bounced off {self._what(c)} at t = {kick.time:.6g} s ({where}), "
                f"{abs(shift) * 1000:.3g} ms ({abs(shift) / dt:.2f}·dt) {'after' if shift > 0 else 'before'} the "
                f"exact time of impact t = {c.time:.6g} s")
        if depth > 0:
            text += f", when it was already {depth * 1000:.3g} mm inside"
            advice = ("your engine tests for contact where each step ends (discrete detection) and bounces there, "
                      "late and from inside: find the time of impact within the step (solve |x + v·t − c| = r for "
                      "t, the swept test) and bounce at that instant")
        elif shift < 0:
            advice = ("the bounce came before the bodies touched: check the contact distance (the sum of the radii) "
                      "and that contacts are tested where the body is, not ahead of it")
        else:
            advice = ("the bounce came after the touch but before an overlap showed: find the time of impact "
                      "within the step (the swept test) instead of testing at sampled instants")
        self._add("bounce-time", c.step, c, text, advice, {"physdbg_time": c.time, "time": kick.time,
                                                                "shift": shift, "depth": max(depth, 0.0)})

    def _judge_energy(self, c: StepContact, kick: Kick, quiet_if_late: bool) -> None:
        """Compare the contact's outgoing normal speed with the restitution's. After a late
        bounce, only a clear error is reported (below 0 or above 1): the speeds of a body
        bounced from inside are not the exact contact's."""
        r = self.runs
        s = kick.step
        tau, dt = kick.tau, float(r.dt[s])
        n = c.normal
        # a soft contact (MuJoCo's) spreads its impulse over steps: the contact lasts while the
        # kicks go on, and its outcome is the velocity after the last of them
        end = s

        def normal_speed(k):
            v = r.vf[k, c.a] - (r.vf[k, c.other] if PARTNER_IS_SPHERE[c.kind] else 0.0)
            return float(v @ n)

        def pushing_apart(k):  # step k's kick pushes the bodies apart while they touch or approach
            gap = self._gap(c, c.a, r.xf[k - 1, c.a], k, 0.0)
            return normal_speed(k) > normal_speed(k - 1) and (gap <= 0.0 or normal_speed(k - 1) < 0.0)

        while (not self.estimated and pushing_apart(s) and end + 1 < len(r.t)
               and any((end + 1, b) in self.kicks for b in self._bodies(c)) and pushing_apart(end + 1)):
            end += 1
            for b in self._bodies(c):
                if (end, b) in self.kicks:
                    self.kicks[(end, b)].matched = True

        def readings(i, last=None):
            """(velocity just before, just after) the contact, as each way of applying the
            forces around it would have them; which one the engine used is not known.
            last: the step whose end is "after" (default: the contact's last step)."""
            last = end if last is None else last
            length = float(r.t[last] - r.t[s - 1])
            if self.estimated:  # the kick is at the step's end, between its average and the next step's
                if last + 1 >= len(r.t):
                    return []
                return [(r.vf[s, i] + 0.5 * self.acc[i] * dt,
                         r.vf[last + 1, i] - 0.5 * self.acc[i] * float(r.dt[last + 1]))]
            v0, v1, a = r.vf[s - 1, i], r.vf[last, i], self.acc[i]
            return [(v0 + a * tau, v1 - a * (length - tau)), (v0 + a * dt, v1 - a * (length - dt)),
                    (v0, v1 - a * length)]

        want = c.restitution

        def effective(last=None):
            """(|e − want|, e, normal speed before, after) of each reading of the contact."""
            out = []
            pair = PARTNER_IS_SPHERE[c.kind]
            for (before_a, after_a), other in zip(readings(c.a, last),
                                                  readings(c.other, last) if pair else [(0.0, 0.0)] * 3):
                before, after = (before_a - other[0]) @ n, (after_a - other[1]) @ n
                if math.isfinite(before) and math.isfinite(after) and before < 0:
                    out.append((abs(-after / before - want), -after / before, before, after))
            return out

        options = effective()
        if not options:
            return
        _, e, before, after = min(options)  # the reading kindest to the run: report only what none explains
        mistake = restitution_mistake(e, want)
        if mistake is None and end > s:  # a mistake shows whole in the contact's own step, before what it leads to
            first = effective(s)
            if first and restitution_mistake(min(first)[1], want) is not None:
                _, e, before, after = min(first)
                mistake = restitution_mistake(e, want)
        # the direction of the push, over the contact's own step (a wrong normal impulse
        # that leaves the bodies approaching makes more contacts in the steps after)
        if self._judge_tangent(c, lambda i: readings(i, s)) and mistake is None:
            return
        if abs(e - want) <= RESTITUTION_TOLERANCE + 1e-3 * want or (quiet_if_late and 0.0 <= e <= 1.0):
            return
        if mistake is not None:
            code, words, advice = mistake
            self._add(code, c.step, c,
                      f"{self._both(c)}: "
                      + (f"they met at {abs(before):.3g} m/s and {'still approach' if after < 0 else 'part'}"
                         if PARTNER_IS_SPHERE[c.kind] else
                         f"it met {self._what(c)} at {abs(before):.3g} m/s and "
                         f"{'still approaches it' if after < 0 else 'leaves'}")
                      + f" at {abs(after):.3g} m/s after the contact, an "
                      f"effective restitution of {e:.3g} where physdbg applies e = {want:g}: {words}", advice,
                      {"restitution": e, "expected": want, "speed_in": abs(before), "speed_out": abs(after)})
            return
        if e < -1.0:
            text = (f"{self._both(c)}: after the contact they still approach, at {abs(after):.3g} m/s where they "
                    f"met at {abs(before):.3g} m/s (an effective restitution of {e:.2f}; the scene's is {want:g}): "
                    f"energy gained")
            advice = ("the impulse points the wrong way: j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b) pushes a along n "
                      "(from b towards a) and b against it; check its sign and the normal's direction")
        elif e < 0:
            text = (f"{self._both(c)}: after the contact they still approach, at {abs(after):.3g} m/s where they "
                    f"met at {abs(before):.3g} m/s (an effective restitution of {e:.2f}; the scene's is {want:g}): "
                    f"the impulse points the right way but is too small to part them")
            advice = ("j = −(1 + e)·(v_rel·n)/(1/m_a + 1/m_b) must take away the whole closing speed (the 1) and "
                      "give back e of it reversed: check both terms of (1 + e) and the masses")
        else:
            gained = e > 1.0
            verdict = ("energy gained at the contact" if gained else
                       "more energy kept than that restitution allows" if e > want else
                       "more energy lost than that restitution takes")
            text = (f"{self._subject(c)}: the contact with {self._what(c)} sent it off at {abs(after):.3g} m/s for "
                    f"{abs(before):.3g} m/s coming in, an effective restitution of {e:.3g} where physdbg applies "
                    f"{want:g}: {verdict}")
            advice = ("restitution above 1 adds energy: check the impulse and the restitution of both bodies"
                      if gained else
                      "check the restitution your engine was given and how it combines two bodies' (physdbg's "
                      f"rule here: restitution_rule = {self.settings.get('restitution_rule', 'min')})")
        self._add("contact-energy", c.step, c, text, advice,
                  {"restitution": e, "expected": want, "speed_in": abs(before), "speed_out": abs(after)})

    def _judge_tangent(self, c: StepContact, readings) -> bool:
        """A frictionless contact pushes along its normal only, so each sphere keeps its
        velocity across the normal (its tangential part). A run that changes it either
        reflected the whole velocity (tangent-reversed: the seed's R = Ri − 2N(Ri·N) turns
        only the normal part) or pushed along another direction (wrong-normal). True when
        one was named."""
        n = c.normal
        for i in self._bodies(c):
            if self.inv[i] == 0:
                continue
            best = None
            for before, after in readings(i):
                t0, t1 = before - (before @ n) * n, after - (after @ n) * n
                change = float(np.linalg.norm(t1 - t0))
                if math.isfinite(change) and (best is None or change < best[0]):
                    best = (change, before, after, t0, t1)
            if best is None:
                continue
            change, before, after, t0, t1 = best
            scale = float(np.linalg.norm(before)) + float(np.linalg.norm(self.acc[i])) * float(self.runs.dt[c.step])
            if change <= RESTITUTION_TOLERANCE * scale + self.atol:
                continue
            c_i = dataclasses.replace(c, a=i, other=c.other if i == c.a else c.a) if PARTNER_IS_SPHERE[c.kind] else c
            size0, size1 = float(np.linalg.norm(t0)), float(np.linalg.norm(t1))
            if size0 > 0 and size1 > 0 and float(t0 @ t1) < -0.9 * size0 * size1:
                self._add("tangent-reversed", c.step, c_i,
                          f"{self._subject(c_i)}: the contact with {self._what(c_i)} reversed its velocity along the "
                          f"surface too, from {size0:.3g} m/s to {size1:.3g} m/s the other way; a frictionless "
                          f"contact keeps that part and turns only the part along the normal",
                          "reflect only the normal part: v − (1 + e)(v·n)n (the seed's R = Ri − 2N(Ri·N) for e = "
                          "1), not −e·v", {"tangential_before": size0, "tangential_after": -size1})
            else:
                kick = after - before
                along = abs(float(kick @ n)) / max(float(np.linalg.norm(kick)), 1e-300)
                angle = math.degrees(math.acos(min(1.0, along)))
                self._add("wrong-normal", c.step, c_i,
                          f"{self._subject(c_i)}: the contact with {self._what(c_i)} pushed it {angle:.3g}° away from "
                          f"the normal at the touch, changing its velocity across the normal by {change:.3g} m/s "
                          f"(a frictionless contact changes only the part along the normal)",
                          "push along the normal at the time of impact: for two spheres the line of centres, "
                          "n = (x_a − x_b)/|x_a − x_b| at the touch, not the direction of their velocities",
                          {"angle_degrees": angle, "tangential_change": change})
            return True
        return False

    def _judge_chain(self, s: int, group: list[StepContact], v_local: np.ndarray) -> None:
        """Contacts of one step that share bodies: the group's outcome as a whole."""
        r = self.runs
        bodies = sorted({b for c in group for b in self._bodies(c) if self.inv[b] > 0})
        for b in bodies:
            for k in (s, s + 1):
                if (k, b) in self.kicks:
                    self.kicks[(k, b)].matched = True
        idx = np.array(bodies)
        vf, vr = r.vf[s, idx], v_local[idx]
        gap = np.linalg.norm(vf - vr, axis=1)
        if not np.any(gap > self.atol + self.rtol * np.linalg.norm(vr, axis=1)):
            return  # the chain's outcome is physdbg's; what differs is where the bodies are (drift)
        # what the run's own frames say of the chain: momentum and energy at the step's end
        # against its start carried over the step by the forces and drag alone, over the
        # chain's spheres and every other sphere the run kicked in the step (where the run's
        # contacts took momentum)
        members = np.array(sorted(set(bodies) | set(self._changed_near(s, bodies))))
        mass = 1.0 / self.inv[members]
        dt = float(r.dt[s])
        start = r.vf[s - 1, members] * float(self._decay(dt)) + self.acc[members] * dt
        end = r.vf[s, members]
        momentum_0, momentum_1 = (mass[:, None] * start).sum(axis=0), (mass[:, None] * end).sum(axis=0)
        energy_0, energy_1 = (0.5 * float(mass @ (start * start).sum(axis=1)),
                              0.5 * float(mass @ (end * end).sum(axis=1)))
        energy_r = 0.5 * float((1.0 / self.inv[idx]) @ (vr * vr).sum(axis=1))
        # slack for how the forces and drag were applied around the contacts (not known)
        forces = float(np.sum(mass * (np.linalg.norm(self.acc[members], axis=1) * dt
                                      + np.linalg.norm(r.vf[s - 1, members], axis=1) * abs(1.0 - self._decay(dt)))))
        scale = max(float(np.sum(mass * np.linalg.norm(end, axis=1))), float(np.sum(mass * np.linalg.norm(start, axis=1))),
                    1e-300)
        momentum_off = float(np.linalg.norm(momentum_1 - momentum_0))
        walls = self._may_touch_a_wall(s, members)  # a wall or a mesh takes momentum: not compared then
        kept = walls or momentum_off <= 1e-3 * scale + forces
        speed = max(float(np.max(np.linalg.norm(end, axis=1))), float(np.max(np.linalg.norm(start, axis=1))))
        energy_slack = 1e-3 * max(energy_0, 1e-300) + forces * (speed + forces / float(mass.min()))
        gained = energy_1 > energy_0 + energy_slack
        order = ", then ".join(f"{self._pair_words(c)} at {c.tau / dt:.2f}·dt" for c in group[:6])
        worst = int(idx[int(np.argmax(gap))])
        spheres = ", ".join(map(str, members.tolist()[:12])) + (" …" if len(members) > 12 else "")
        evidence = {"bodies": bodies, "momentum_bodies": members.tolist(),
                    "physdbg_order": [[c.a, c.other, c.kind] for c in group],
                    "energy_before": energy_0, "energy": energy_1, "physdbg_energy": energy_r,
                    "momentum_before": momentum_0.tolist(), "momentum": momentum_1.tolist(),
                    "momentum_off": momentum_off, "momentum_kept": kept, "forces_slack": forces, "walls": walls}
        first = group[0]
        if gained:
            self._add("contact-energy", s, first,
                      f"in the chain {order}, your run's spheres {spheres} leave step {s} with {energy_1:.4g} J of "
                      f"kinetic energy where they had {energy_0:.4g} J (the step's start, carried by the forces and "
                      f"drag alone): energy gained (physdbg's leave with {energy_r:.4g} J)",
                      "check each impulse's sign and that restitution is at most 1", evidence)
        elif kept:
            self._add("collision-order", s, first,
                      f"physdbg resolves {order}; your run gives sphere {worst} a velocity {gap.max():.3g} m/s "
                      f"away, with " + (
                          "no energy gained; with a wall within reach, momentum is not compared, so this is the same "
                          "contacts in another order (or all at once), or an impulse a wall does not explain"
                          if walls else
                          "momentum kept and no energy gained: the same contacts in another order (or all at once)"),
                      "resolve contacts one at a time in the order they happen (earliest time of impact first), "
                      "looking again for new contacts after each: a chain of touching spheres passes its impulse "
                      "along only in that order", evidence)
        else:
            self._add("contact-energy", s, first,
                      f"in the chain {order}, momentum is not kept: your run's spheres {spheres} change their total "
                      f"momentum by {momentum_off:.3g} N·s in step {s} (from {float(np.linalg.norm(momentum_0)):.4g} "
                      f"to {float(np.linalg.norm(momentum_1)):.4g} N·s), where the forces and drag account for at most "
                      f"{forces:.3g} N·s",
                      "apply each impulse to both bodies, equal and opposite, scaled by their inverse masses",
                      evidence)

    def _changed_near(self, s: int, chain: list[int]) -> list[int]:
        """Spheres outside ``chain`` whose velocity the run changed in step s beyond the
        forces (and the tolerance) and that came within reach of a chain sphere (the sum of
        the radii plus both spheres' travel in the step): where the run's chain may have
        taken momentum that physdbg's did not."""
        r = self.runs
        travel = np.linalg.norm(r.xf[s] - r.xf[s - 1], axis=1)
        near = []
        for b in np.flatnonzero(self.inv > 0).tolist():
            if b in chain or not (self._change_beyond_forces(s, b)
                                  > self.atol + self.rtol * float(np.linalg.norm(r.vf[s, b]))):
                continue
            for k in (s - 1, s):
                gaps = (np.linalg.norm(r.xf[k, chain] - r.xf[k, b], axis=1) - self.radius[chain] - self.radius[b]
                        - travel[chain] - travel[b])
                if np.any(np.nan_to_num(gaps, nan=-1.0) <= self.atol):
                    near.append(b)
                    break
        return near

    def _may_touch_a_wall(self, s: int, members: np.ndarray) -> bool:
        """Whether any of spheres ``members`` may have touched a wall or a mesh in step s of
        the run: a plane within its radius plus the step's travel at the step's start or end
        (a scene with meshes: always, not measured here)."""
        if len(self.walls.meshes.corners):
            return True
        if not len(self.walls):
            return False
        r = self.runs
        from ..engine.colliders.plane import gaps

        reach = np.linalg.norm(r.xf[s, members] - r.xf[s - 1, members], axis=1)
        for k in (s - 1, s):
            g = gaps(np.ascontiguousarray(r.xf[k, members], dtype=np.float64), self.radius[members], self.walls)
            if np.any(np.nan_to_num(g, nan=-1.0) <= reach[:, None] + self.atol):
                return True
        return False

    def _extra(self, kick: Kick) -> None:
        r = self.runs
        s, i = kick.step, kick.body
        size = float(np.linalg.norm(r.vf[s, i] - r.vf[s - 1, i]))
        self._add("extra-contact", s, _Lone(i),
                  f"sphere {i} changed velocity by {size:.3g} m/s at t ≈ {kick.time:.6g} s; physdbg, stepping "
                  f"from the same state, touches nothing in that step",
                  "a contact physdbg does not see: a test that fires too early or against the wrong body, or a "
                  "body that was already inside another (look at the step before)", {"change": size})

    def _drift(self, drift: dict[int, list[int]]) -> None:
        """Free steps that end elsewhere: one departure for all bodies, with the counts."""
        if not drift or self.run_decay is not None:  # the run's own drag, named already, is why
            return
        integrator = self.integrator or {}
        b = min(drift, key=lambda i: (drift[i][0], i))
        steps = sorted({k for ks in drift.values() for k in ks})
        who = f"sphere {b} drifts" if len(drift) == 1 else f"{len(drift)} spheres (sphere {b} first) drift"
        text = (f"{who} in free flight ({len(steps)} step{'s' if len(steps) != 1 else ''} with no contact "
                f"end{'s' if len(steps) == 1 else ''} elsewhere than physdbg's from the "
                f"same start)")
        if integrator.get("differs") and integrator.get("name"):
            text += ": the integrator"
            advice = (f"integrate as the scene says (integrator = {self.settings.get('integrator')}), or set the "
                      f"scene's integrator to your engine's to compare the contacts alone")
        else:
            advice = (f"check gravity ({self.settings.get('gravity')} m/s²), drag ({self.drag:g}) and the gravity "
                      f"scale against the scene's")
        self.departures.append(Departure("drift", steps[0], b, text, advice,
                                         evidence={"steps": len(steps), "bodies": sorted(drift)}))

    # ------------------------------------------------------------------ crossings
    def _crossings_in(self, s: int):
        if not hasattr(self, "_checker"):
            from .tunnel import StepChecker

            settings = dict(self.settings)
            settings["integrator"] = integrator_of((self.integrator or {}).get("name"))
            self._checker = StepChecker(self.radius, self.inv, self.rr.header.gravity_scale, self.walls, settings)
        r = self.runs
        if not (np.isfinite(r.xf[s]).all() and np.isfinite(r.xf[s - 1]).all()):
            return []
        return self._checker.check(r.xf[s - 1], r.vf[s - 1], r.xf[s], float(r.dt[s]), None, float(r.t[s - 1]))

    def _crossing(self, c: StepContact):
        """The foreign crossing of contact c's bodies in its step or the next, or None."""
        for s in (c.step, c.step + 1):
            if s >= len(self.runs.t):
                break
            for x in self._crossings_in(s):
                if x.kind == c.kind and {x.a, x.other} == ({c.a, c.other} if PARTNER_IS_SPHERE[c.kind]
                                                              else {x.a, c.other}) and x.a in self._bodies(c):
                    return s, x
        return None

    def _tunnelled(self, c: StepContact, crossing) -> None:
        r = self.runs
        s, x = crossing
        a, dt = c.a, float(r.dt[c.step])
        speed = float(np.linalg.norm(r.vf[s - 1, a]))
        if PARTNER_IS_SPHERE[c.kind]:
            room = 2 * float(self.radius[a] + self.radius[c.other])
            what = f"more than the two spheres' diameters ({room:.3g} m)"
        elif c.kind == KIND_WALL:
            room = float(self.walls.thickness[c.other]) + 2 * float(self.radius[a])
            what = f"more than the wall's thickness plus the sphere's diameter ({room:.3g} m)"
        elif c.kind == KIND_MESH:
            room = 2 * float(self.radius[a])
            what = f"more than the sphere's diameter ({room:.3g} m: a mesh's triangle has no thickness)"
        else:
            raise _no_geometry(c.kind)
        text = (f"{self._subject(c)} went through {self._what(c)} with no contact; physdbg's swept test, from the "
                f"same state, finds the touch at t = {c.time:.6g} s ({c.tau / dt:.2f}·dt) and bounces it back")
        advice = why_tunnelled(self.settings, [], foreign=True).advice
        carried = speed * float(r.dt[s])
        inside = -self._gap(c, a, r.xf[s - 1, a], s, 0.0)
        if inside > self.settings.get("contact_tolerance", 0.0) and PARTNER_IS_SPHERE[c.kind]:
            text += f"; it was already {inside * 1000:.3g} mm inside at the step's start"
            advice = ("it started the step inside the other sphere, after a contact resolved late or with the wrong "
                      "impulse: fix that first (see the departure before this one)")
        elif carried > room:
            text += f". At {speed:.3g} m/s a step of {float(r.dt[s]):.3g} s carries it {carried:.3g} m, {what}"
            advice += f" (steps under {room / max(speed, 1e-300):.3g} s here)"
        self._add("tunnelling", s, c, text, advice, {"physdbg_time": c.time, "speed": speed, "depth": x.depth})

    def _non_finite(self) -> None:
        r = self.runs
        bad = ~(np.isfinite(r.xf).all(axis=2) & np.isfinite(r.vf).all(axis=2))
        frames, bodies = np.nonzero(bad)
        if len(frames):
            k, i = int(frames[0]), int(bodies[0])
            self._add("non-finite", k, _Lone(i),
                      f"sphere {i}'s {'position' if not np.isfinite(r.xf[k, i]).all() else 'velocity'} is NaN or "
                      f"infinite from t = {r.t[k]:.6g} s ({_body_count(int(bad[k].sum()))} then)",
                      "look at the step before: a division by a zero distance (two centres at one point) or a "
                      "zero mass is the usual start", {"frame": k})

    # ------------------------------------------------------------------ words
    def _gap(self, c: StepContact, a: int, x: np.ndarray, s: int, tau: float) -> float:
        """Distance from contact (m; negative inside) of body a at x, the other body where
        the foreign run had it at that instant."""
        r = self.runs
        if c.kind == KIND_WALL:
            from ..engine.colliders.plane import gaps

            return float(gaps(np.asarray(x, dtype=np.float64).reshape(1, 3), self.radius[a:a + 1], self.walls)[0, c.other])
        if c.kind == KIND_MESH:
            from ..engine.mesh.closest import closest_on_triangle

            meshes = self.walls.meshes
            corners = meshes.corners[c.other]
            if meshes.moving[meshes.mesh_of[c.other]]:  # a kinematic mesh, where it was then
                corners = meshes.placed(float(r.t[s - 1]) + tau)[0][c.other]
            q = np.array(closest_on_triangle(*(float(v) for v in x), *corners.ravel())[:3])
            return float(np.linalg.norm(x - q)) - float(self.radius[a])
        if not PARTNER_IS_SPHERE[c.kind]:
            raise _no_geometry(c.kind)
        b = c.other if a == c.a else c.a
        xb = r.xf[s - 1, b] + (r.xf[s, b] - r.xf[s - 1, b]) * (tau / float(r.dt[s]))
        return float(np.linalg.norm(x - xb)) - float(self.radius[a] + self.radius[b])

    def _what(self, c: StepContact) -> str:
        return partner_words(c.kind, c.other, self.names)

    def _subject(self, c: StepContact) -> str:
        return f"sphere {c.a}"

    def _both(self, c: StepContact) -> str:
        return f"spheres {c.a} and {c.other}" if PARTNER_IS_SPHERE[c.kind] else f"sphere {c.a}"

    @staticmethod
    def _listed(c: StepContact) -> list[int]:
        """A contact as [a, other, kind], a pair of spheres lower index first (as it is
        either way round)."""
        if PARTNER_IS_SPHERE[c.kind]:
            return [min(c.a, c.other), max(c.a, c.other), c.kind]
        return [c.a, c.other, c.kind]

    def _sequence(self, contacts) -> str:
        """Contacts given as [a, other, kind], in words and in order: "0–1, then 1–2"."""
        listed = ", then ".join(contact_words(kind, a, other, self.names) for a, other, kind in contacts[:4])
        return listed + (" …" if len(contacts) > 4 else "")

    def _pair_words(self, c: StepContact) -> str:
        return contact_words(c.kind, c.a, c.other, self.names)

    def _add(self, kind: str, step: int, c: StepContact | _Lone, text: str, advice: str,
             evidence: dict | None = None) -> None:
        other = c.other if c.kind is not None and PARTNER_IS_SPHERE[c.kind] else None
        wall = self.wall_names[c.other] if c.kind == KIND_WALL else None
        self.departures.append(Departure(kind, step, c.a, text, advice, other, wall, evidence or {}))

    @staticmethod
    def _fold(departures: list[Departure]) -> list[Departure]:
        """The first departure of each kind on each body (and other), with a count of the
        rest, in step order, the most telling first within a step; at most MAX_LISTED."""
        departures = sorted(departures, key=lambda d: (d.step, _PRIORITY.index(d.kind), d.body))
        firsts: dict[tuple, Departure] = {}
        for d in departures:
            # a way of stepping (index order, drag) is one departure, whatever bodies it meets
            key = (d.kind,) if d.kind in _RUN_WIDE else (d.kind, d.body, d.other, d.wall)
            if key in firsts:
                firsts[key].more += 1
            else:
                firsts[key] = d
        return list(firsts.values())[:MAX_LISTED]

    def _headline(self, first: FirstDeparture | None, listed: list[Departure]) -> str:
        aside = "; ".join(f"physdbg's {a['name']} {a['said']} — `-s {a['setting']}={a['value']:g}` compares "
                          f"without it" for a in self.set_aside)
        ties = ""
        if self.ties:
            more = len(self.ties) - 1
            ties = (f"{self.ties[0].evidence['said']}, and physdbg went on from that step taken in your run's order"
                    + (f" (and so at {more} more tie{'s' if more > 1 else ''})" if more else ""))
        if first is None and (self.set_aside or self.ties):
            flags = " ".join(f"-s {a['setting']}={a['value']:g}" for a in self.set_aside)
            without = (f" without its own rule{'s' if len(self.set_aside) > 1 else ''} ({flags})" if self.set_aside
                       else "")
            return (f"same as the seed's model: every body stays within atol={self.atol:g}, rtol={self.rtol:g} of "
                    f"physdbg's exact run{without} for all {len(self.runs.t) - 1} steps; "
                    + "; ".join(part for part in (aside, ties) if part))
        if first is None:
            return (f"no departure: every body stays within atol={self.atol:g}, rtol={self.rtol:g} of physdbg's "
                    f"exact run for all {len(self.runs.t) - 1} steps")
        cause = cause_of(first, listed)
        if first.cause == "drift" and self.integrator is not None and self.integrator["differs"]:
            why = "integrator: " + self.integrator["sentence"]
        elif cause is not None:
            why = f"{_KIND_WORDS[cause.kind]}: {cause.text}"
        else:
            why = "the states drift apart with no contact to blame (forces, drag or integration differ)"
        out = f"{self.subject} in step {first.step}, sphere {first.body}: {why}"
        contact = next((d for d in listed if d.kind not in ("drift", first.cause)), None)
        if contact is not None and first.cause == "drift":
            out += f". The first contact that goes wrong: step {contact.step}, {_KIND_WORDS[contact.kind]}"
        if self.set_aside:
            out += f" (compared against physdbg without its own rule: {aside})"
        if self.ties:
            out += f" (before it, {ties})"
        return out


_RUN_WIDE = ("own-rule", "index-order", "drag-per-step", "drag-ignored", "drift", "chaos", "unexplained")
# check-run's causes, one table: each kind of departure, in the order of telling (the most
# telling first within a step: _fold), with its words and the judgements (the methods of
# _Comparison themselves) that name it. The restitution mistakes are RESTITUTION_MISTAKES' codes,
# which _judge_energy names through restitution_mistake. A test holds every method here
# to the kinds it names (tests/test_departure.py).
_MISTAKE_JUDGES = (_Comparison._judge_energy, _Comparison._mistaken_chain)  # a restitution mistake's judges
DEPARTURE_KINDS = {
    "impulse-loop": ("an impulse of the wrong sign, met again and again", (_Comparison._runaway,)),
    "non-finite": ("NaN or infinity", (_Comparison._non_finite,)),
    "immovable-moved": ("an immovable body moved", (_Comparison._immovable_moved,)),
    "drag-per-step": ("drag applied per step, not per second", (_Comparison._measure_drag,)),
    "drag-ignored": ("no drag", (_Comparison._measure_drag,)),
    "tunnelling": ("tunnelling", (_Comparison._tunnelled,)),
    "impulse-sign": ("an impulse of the wrong sign", _MISTAKE_JUDGES),
    "impulse-doubled": ("an impulse applied twice", _MISTAKE_JUDGES),
    "restitution-sign": ("restitution with the wrong sign", _MISTAKE_JUDGES),
    "one-missing": ("the 1 of (1 + e) missing from the impulse", _MISTAKE_JUDGES),
    "restitution-squared": ("restitution applied twice", _MISTAKE_JUDGES),
    "contact-energy": ("energy at a contact", (_Comparison._judge_energy, _Comparison._judge_chain)),
    "tangent-reversed": ("a reflection of the whole velocity", (_Comparison._judge_tangent,)),
    "wrong-normal": ("an impulse along the wrong normal", (_Comparison._judge_tangent,)),
    "own-rule": ("physdbg's own modelling rule, not the engine", (_Comparison._own_rule, _Comparison._slept)),
    "tie": ("contacts at one instant taken in another order (a tie, not a mistake)", (_Comparison._tie,)),
    "index-order": ("contacts resolved in index order", (_Comparison._index_ordered,)),
    "collision-order": ("contacts resolved out of order", (_Comparison._judge_chain,)),
    "skipped-rest": ("a bounce that skips the rest of the step", (_Comparison._skipped_rest,)),
    "bounce-time": ("bounced at the wrong time", (_Comparison._late,)),
    "resting": ("a slow or resting contact, held another way", (_Comparison._resting,)),
    "missed-contact": ("a contact missed", (_Comparison._judge_one,)),
    "extra-contact": ("a contact physdbg does not have", (_Comparison._extra,)),
    "drift": ("drift in free flight", (_Comparison._drift,)),
    "chaos": ("chaos: differences below the tolerance grew", (_Comparison._no_step_departs,)),
    "unexplained": ("unexplained", (_Comparison._no_step_departs,)),
}
# what may explain a whole step where the run ends elsewhere than physdbg's step from the
# same state, tried in this order before its contacts are judged one by one (or chain by
# chain): physdbg's own modelling rule, a tie, index order, an impulse mistake along a chain
STEP_EXPLANATIONS = (_Comparison._own_rule, _Comparison._tie, _Comparison._index_ordered,
                     _Comparison._mistaken_chain)
_PRIORITY = tuple(DEPARTURE_KINDS)
_KIND_WORDS = {kind: words for kind, (words, _) in DEPARTURE_KINDS.items()}


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


__all__ = ["CheckRunError", "CheckRunReport", "Departure", "FirstDeparture", "cause_of", "compare"]
