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

Where each part lives: the judgements are methods of one ``_Comparison``, because they
share its state (both runs' arrays, the kicks and which of them a contact already took,
the local steps taken from the run's state) and form one decision tree, whose root is
here (``run``, ``_judge_steps``) beside its tables (DEPARTURE_KINDS, STEP_EXPLANATIONS).
The judges are grouped in modules a reader can take one at a time, each a mixin of
``_Comparison``: departure_flight.py (the whole run and its free flight: the integrator,
drag, the kicks, physdbg's local step), departure_steps.py (what explains a whole step:
an own rule, a tie, index order, an impulse mistake along a chain; chaos), and
departure_contacts.py (one contact or chain: missed, tunnelled, late, energy, tangent,
loop, order, extra, drift). The records and numbers they all read are
departure_records.py; the impulse mistakes are restitution_mistakes.py, the growth fit
align.py, the words for tunnelling tunnel_words.py.
"""

from __future__ import annotations

import numpy as np

from ..errors import CheckRunError
from ..events import KIND_WALL, PARTNER_IS_SPHERE, contact_words, partner_words
from .departure_contacts import ContactJudges
from .departure_flight import FlightJudges
from .departure_records import (CHUNK_BODY_STEPS, CheckRunReport, DEFAULT_ATOL, DEFAULT_RTOL, Departure,
                                FirstDeparture, MAX_LISTED, MAX_TIES, StepContact, _Lone, _RUN_WIDE, _chains,
                                _involves, _load, cause_of)
from .departure_records import OWN_RULES, bodies_of, family_of, integrator_of, too_long  # noqa: F401 (re-exported)
from .departure_steps import StepJudges
from .quiet import quiet_numerics
from .restitution_mistakes import RESTITUTION_MISTAKES  # noqa: F401 (re-exported: its codes are DEPARTURE_KINDS')


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


class _Comparison(ContactJudges, StepJudges, FlightJudges):
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


__all__ = ["CheckRunError", "CheckRunReport", "Departure", "FirstDeparture", "cause_of", "compare"]
