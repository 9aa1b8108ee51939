"""Why two runs part in the step where they first differ: ``physdbg diff``'s step 5.

A **detector** reads one kind of evidence about the diverging step (the engines'
warnings, the exact swept test over each run's step, the sleep masks, the first
differing contact) and makes the causes of its kind. ``STEP_CAUSES`` lists them in the
order they are tried; ``step_causes`` runs the table. A detector that ``ends`` the search
(no step was taken; a bit-identical start) leaves the rest untried, and one that
``leads`` puts its cause before the others (a collision order the settings chose is the
mechanism, the settings only its reason). The first differing contact is told by one
classifier (``_contact_difference``), so exactly one of its detectors speaks.

Adding a cause: a detector function here, a row in ``STEP_CAUSES`` and a row in
``CAUSE_KINDS``, and its words in docs/diff.md (a test holds the page to this table).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..events import PARTNER_IS_SPHERE, contact_words, partner_words
from . import align
from .tunnel import StepChecker
from .tunnel_words import why_tunnelled

METHOD_SETTINGS = ("integrator", "dt", "drag", "gravity", "detection", "samples", "steps", "duration")

# every kind of cause diff names, with what it means: the one vocabulary docs/diff.md lists
CAUSE_KINDS = {
    "settings": "a setting or scene field that can change the run differs",
    "engine-version": "the runs were recorded by different engine builds",
    "structure": "the runs are not of the same bodies",
    "records": "bit-identical states, but other recorded contacts",
    "length": "one run goes on longer",
    "initial-state": "the runs differ before any step",
    "non-finite": "a run's state became NaN or infinite in the step",
    "engine-limits": "one run hit a work budget in the step and the other did not",
    "tunnelling": "a sphere crossed a body with no contact in one run",
    "outside-change": "bit-identical starts and settings, yet the step differs",
    "sleep": "a differing sphere slept in one run and not the other",
    "collision-order": "the same contacts resolved in another order",
    "tie": "contacts at one instant taken in another order (neither run wrong)",
    "missed-contact": "a contact one run resolved and the other did not (or held)",
    "contact-outcome": "the same contact with another time or impulse",
    "method-drift": "no event differs: the integration drifts apart",
    "integrator": "another engine's run: the integrator family its free steps fit",
    "foreign": "another engine's run could not be judged step by step",
}


def settings_at(meta: dict, step: int | None = None) -> dict:
    """The settings a recording's step ran under (None: its last): its recorded settings
    with the changes of its fork chain (header ``fork``: fork.fork_recording) from their
    steps on."""
    settings = dict(meta.get("settings", {}))
    for entry in (meta.get("fork") or {}).get("chain", []):
        if step is None or entry["at"] <= step:
            settings.update(entry["changes"])
    return settings


@dataclass
class Cause:
    """One reason the runs part. kind: a key of ``CAUSE_KINDS``, or, where one run is
    another engine's, a kind of analysis.departure (bounce-time, contact-energy,
    extra-contact, drift, integrator, …); text: the sentence (without its step: the
    reports say it); evidence: its numbers; step: the step it happened in (counted from
    1; in A's numbering where the runs are aligned by time), or None for a cause of the
    whole run (settings, lengths, structure); bodies: the spheres it is about; advice:
    what to change, or ""."""

    kind: str
    text: str
    evidence: dict = field(default_factory=dict)
    step: int | None = None
    bodies: tuple[int, ...] = ()
    advice: str = ""
    # the advice as a change of settings a fork of the run the cause is in can try
    # (physdbg diff --try), {} where it is not one
    try_settings: dict = field(default_factory=dict)

    # the record every report prints (report.Record); the JSON keeps the fields above
    code = property(lambda self: self.kind)
    summary = property(lambda self: self.text)
    detail = property(lambda self: self.evidence)


@dataclass
class Divergence:
    """The first step where the runs differ beyond the tolerance. step / step_b: its
    number in A / B (counted from 1; equal when aligned by step); time: s at its end;
    state: StateDifference at its end; first_event: the first differing contact of the
    step (index, and each run's contact as a dict or None), or None when none differs."""

    step: int
    step_b: int
    time: float
    state: align.StateDifference
    first_event: dict | None


@dataclass
class StepCase:
    """What every detector reads of the diverging step. differ: the diff in progress (its
    recordings, settings and decoded frames); div: the Divergence; prev_a / prev_b: each
    run's frame before the step (None when not decoded); ca / cb: each run's contacts of
    the step as dicts (None when not recorded); growth: how the gap grows afterwards."""

    differ: Any  # diff._Differ (diff imports this module, so not named here)
    div: Divergence
    prev_a: object
    prev_b: object
    ca: list[dict] | None
    cb: list[dict] | None
    growth: object

    @property
    def settings_a(self) -> dict:
        return settings_at(self.differ.ra.meta, self.div.step)

    @property
    def settings_b(self) -> dict:
        return settings_at(self.differ.rb.meta, self.div.step_b)

    @property
    def event(self) -> dict | None:
        return self.div.first_event

    def describe(self, r: dict | None, times: bool = True) -> str:
        """A contact row in words (with its time in the step)."""
        if r is None:
            return "nothing"
        who = contact_words(r["kind"], r["a"], r["other"], self.differ.names_a)
        return who + (f" (t = {r['time_in_step'] / r['dt']:.2f}·dt)" if times else "")

    def sequence(self, rows: list[dict], index: int) -> str:
        """The step's contacts in the order resolved, up to two past ``index``."""
        shown = [self.describe(r) for r in rows[:index + 2]]
        if not shown:
            return "no contacts"
        more = f", … ({len(rows)} in all)" if len(rows) > index + 2 else ""
        return ", then ".join(shown) + more

    def consequence(self) -> str:
        """How fast the first differing sphere leaves the step in each run."""
        div, d = self.div, self.differ
        if not div.state.particles:
            return ""
        p = div.state.particles[0]["particle"]
        va = np.linalg.norm(d._state(d.ra, div.step).velocities[p])
        vb = np.linalg.norm(d._state(d.rb, div.step_b).velocities[p])
        return f" From there sphere {p} leaves at {va:.2f} m/s in A and {vb:.2f} m/s in B."


Find = Callable[[StepCase, list[Cause]], list[Cause]]


@dataclass(frozen=True)
class Detector:
    """One row of STEP_CAUSES: the kinds it makes, its function (the case and the causes
    found so far -> its causes), whether finding one ends the search, and whether its
    cause goes first (after a settings cause)."""

    kinds: tuple[str, ...]
    find: Find
    ends: bool = False
    leads: bool = False


# ----------------------------------------------------------------------------- detectors
def initial_state(case: StepCase, found: list[Cause]) -> list[Cause]:
    """No step was taken: the runs did not start alike (a scene field, or a script)."""
    div, d = case.div, case.differ
    if div.step != 0 and div.step_b != 0:
        return []
    worst = div.state.particles[0] if div.state.particles else {}
    changed = [s.name for s in d.settings if s.matters and s.name.startswith(("particles", "generate"))]
    cause = Cause(
        "initial-state",
        f"at frame 0, before any step, {_count(div.state.count, 'sphere')} "
        f"{'differ' if div.state.count != 1 else 'differs'} "
        f"(sphere {worst.get('particle')} by {worst.get('position', 0.0):.3g} m and "
        f"{worst.get('velocity', 0.0):.3g} m/s)"
        + (f"; the scenes differ there ({', '.join(changed)})" if changed else
           "; no scene field differs, so a script set the starting state"),
        {"particle": worst, "fields": changed})
    if case.growth is not None and case.growth.model:
        cause.text += "; " + case.growth.sentence()
    return [cause]


def engine_warnings(case: StepCase, found: list[Cause]) -> list[Cause]:
    """A run's own warnings in the step: its state became NaN, or it hit a work budget that
    the other run did not (and left the rest of the step unresolved)."""
    d, div = case.differ, case.div
    out = []
    for label, warns, k in (("A", d.warn_a, div.step), ("B", d.warn_b, div.step_b)):
        for w in warns.get(k, []):
            if w["code"] == "non-finite":
                own = f" (its step {k})" if k != div.step else ""  # the cause's step is A's numbering
                out.append(Cause("non-finite", f"in run {label}{own}: {w['message']}", w, step=div.step))
            elif w["code"].startswith("max_"):
                other = d.warn_b if label == "A" else d.warn_a
                other_k = div.step_b if label == "A" else div.step
                if not any(x["code"] == w["code"] for x in other.get(other_k, [])):
                    out.append(Cause("engine-limits", f"run {label} hit the {w['code']} budget in step {k} "
                                                      f"and left the rest of the step unresolved; run "
                                                      f"{'B' if label == 'A' else 'A'} did not ({w['message']})", w,
                                     step=div.step))
    return out


def tunnelling(case: StepCase, found: list[Cause]) -> list[Cause]:
    """The exact swept test over each run's recorded step: a sphere that crossed a body
    with no contact in one run and not in the other."""
    d, step = case.differ, case.div.step
    if not d.by_step or case.prev_a is None:
        return []
    crossed = {}
    for label, rec, prev in (("A", d.ra, case.prev_a), ("B", d.rb, case.prev_b)):
        contacts = rec.contacts(step) if rec.detail != "state" else None
        after = d._state(rec, step)
        checker = StepChecker(rec.header.radius, rec.header.inverse_mass, rec.header.gravity_scale,
                              rec.header.walls, settings_at(rec.meta, step))
        crossed[label] = checker.check(prev.positions, prev.velocities, after.positions, after.dt, contacts,
                                       after.time - after.dt)
    out = []
    for label, other in (("A", "B"), ("B", "A")):
        theirs = {(c.kind, c.a, c.other) for c in crossed[other]}
        for c in crossed[label]:
            if (c.kind, c.a, c.other) in theirs:
                continue
            what = (f"passed into sphere {c.other}" if PARTNER_IS_SPHERE[c.kind]
                    else f"went through {partner_words(c.kind, c.other, d.names_a)}")
            rec, warns, k = (d.ra, d.warn_a, step) if label == "A" else (d.rb, d.warn_b, case.div.step_b)
            budgets = [w["code"] for w in warns.get(k, []) if w["code"] not in ("non-finite", "overlap")]
            why = why_tunnelled(settings_at(rec.meta, step), budgets, pair=PARTNER_IS_SPHERE[c.kind])
            reason = why.reason
            made = [x for x in ((case.cb if label == "A" else case.ca) or []) if _touches(x, c)]
            other_did = (f"run {other} resolved a contact there at {made[0]['time_in_step'] / made[0]['dt']:.3f}·dt"
                         if made else f"run {other} did not cross")
            out.append(Cause("tunnelling", f"in run {label} sphere {c.a} {what} with no contact ({reason}); {other_did}",
                             {"run": label, "particle": c.a, "other": c.other, "kind": c.kind}, step=step,
                             bodies=(c.a, c.other) if PARTNER_IS_SPHERE[c.kind] else (c.a,), advice=why.advice,
                             try_settings=why.settings))
    return out


def outside_change(case: StepCase, found: list[Cause]) -> list[Cause]:
    """The same settings and a bit-identical state before the step: a deterministic engine
    cannot part them, whatever the events show (unless a run hit a budget or NaN)."""
    d, div, event, step = case.differ, case.div, case.event, case.div.step
    identical_start = (d.by_step and case.prev_a is not None and not any(s.matters for s in d.settings)
                       and np.array_equal(d.ta.hashes[step - 1], d.tb.hashes[step - 1]))
    if not identical_start or any(c.kind in ("engine-limits", "non-finite") for c in found):
        return []
    who = div.state.particles[0] if div.state.particles else {}
    seen = ""
    if event is not None and event["a"] is not None and event["b"] is not None:
        seen = (f"; the first sign is contact {event['index'] + 1} of the step "
                f"({case.describe(event['a'], times=False)}), whose time differs by "
                f"{abs(event['a']['time'] - event['b']['time']):.2g} s")
    return [Cause("outside-change",
                  f"both runs were bit-identical at the start of step {step} (frame {step - 1}), with the same "
                  f"settings and engine, yet sphere {who.get('particle')} differs by {who.get('position', 0):.3g} m "
                  f"after it{seen}. The engine is deterministic, so the state was changed outside its rules (a "
                  f"script that moved a sphere between steps), or the two runs did not come from the same engine "
                  f"build", {"particle": who}, step=step,
                  bodies=(who["particle"],) if "particle" in who else ())]


def sleep(case: StepCase, found: list[Cause]) -> list[Cause]:
    """A differing sphere asleep in one run and awake in the other, when the step began or
    when it ended (engine/sleep.py): a sleeper does not move, and falling asleep sets a
    sphere's velocity to zero."""
    d, div = case.differ, case.div
    if not d.by_step:
        return []
    frames = {"start": (d._state(d.ra, div.step - 1).asleep, d._state(d.rb, div.step_b - 1).asleep),
              "end": (d._state(d.ra, div.step).asleep, d._state(d.rb, div.step_b).asleep)}
    if all(mask is None for pair in frames.values() for mask in pair):
        return []

    def asleep(when: str, run: int, p: int) -> bool:
        mask = frames[when][run]
        return bool(mask is not None and mask[p])

    sleep_settings = [f"{s.name}: {_show(s.a)} in A, {_show(s.b)} in B" for s in d.settings
                      if s.name in ("sleep_speed", "sleep_time")]
    why = f" ({'; '.join(sleep_settings)})" if sleep_settings else ""
    for p in (entry["particle"] for entry in div.state.particles):
        start, end = (asleep("start", 0, p), asleep("start", 1, p)), (asleep("end", 0, p), asleep("end", 1, p))
        if start[0] != start[1]:
            sleeper, other = ("A", "B") if start[0] else ("B", "A")
            text = (f"sphere {p} was asleep in run {sleeper} and awake in run {other} when "
                    f"the step began{why}. A sleeping sphere does not move: what hits or pushes it bounces "
                    f"off it as off a wall")
        elif end[0] != end[1]:
            changed, other = ("A", "B") if end[0] != start[0] else ("B", "A")
            verb = "fell asleep" if not start[0] else "woke"
            text = (f"sphere {p} {verb} at the end of the step in run {changed} and did not in "
                    f"run {other}{why}" + (". Falling asleep sets its velocity to zero" if verb == "fell asleep"
                                           else ""))
        else:
            continue
        return [Cause("sleep", text + "." + case.consequence(),
                      {"particle": p, "asleep_at_start": list(start), "asleep_at_end": list(end)}, step=div.step,
                      bodies=(p,))]
    return []


# the first differing contact: exactly one of these describes it (_contact_difference)
def _contact_difference(case: StepCase, found: list[Cause]) -> str | None:
    """How the step's first differing contact differs: "ordering" (the runs order contacts
    by different settings), "tie", "order" (the same set in another order), "missed" (one
    run's contact the other did not make, or held), "outcome" (the same contact with another
    time or impulse), or None when no contact differs."""
    event = case.event
    if event is None:
        return None
    x, y = event["a"], event["b"]
    if case.settings_a.get("ordering") != case.settings_b.get("ordering") and (
            x is None or y is None or _key(x) != _key(y)):
        return "ordering"
    if x is not None and y is not None and _key(x) != _key(y) and _tied(x, y, case.ca, case.cb):
        return "tie"
    if (x is not None and y is not None and _key(x) != _key(y)
            and sorted(_key(r) for r in case.ca) == sorted(_key(r) for r in case.cb)):
        return "order"
    if x is None or y is None or _key(x) != _key(y) or x["resting"] != y["resting"]:
        return "missed"
    return "outcome"


def ordering_setting(case: StepCase, found: list[Cause]) -> list[Cause]:
    """The runs order a step's contacts by different settings, and took different ones first."""
    if _contact_difference(case, found) != "ordering":
        return []
    event, sa, sb, step = case.event, case.settings_a, case.settings_b, case.div.step
    return [Cause(
        "collision-order",
        f"run A (ordering = {sa.get('ordering')}) resolved "
        f"{case.sequence(case.ca, event['index'])}; run B (ordering = {sb.get('ordering')}) resolved "
        f"{case.sequence(case.cb, event['index'])}.{_order_note(sa, sb)}"
        + case.consequence(), {"a": event["a"], "b": event["b"], "index": event["index"],
                               "ordering": [sa.get("ordering"), sb.get("ordering")]}, step=step)]


def tie(case: StepCase, found: list[Cause]) -> list[Cause]:
    """Two runs that took contacts at one instant (_tied) in another order: a tie, which
    neither run has wrong; what in their settings orders ties otherwise, where one does."""
    if _contact_difference(case, found) != "tie":
        return []
    x, y, sa, sb, step = case.event["a"], case.event["b"], case.settings_a, case.settings_b, case.div.step
    names = sorted({_key(r) for r in case.ca if _at_one_instant(r, x)})
    both = " and ".join(contact_words(kind, a, other, case.differ.names_a) for kind, a, other in names[:4])
    why = ""
    if sa.get("space_order") != sb.get("space_order"):
        why = (f" The runs number their spheres differently (space_order: {sa.get('space_order')} in A, "
               f"{sb.get('space_order')} in B), and the numbering orders tied contacts.")
    text = (f"the contacts {both} happen at one instant (t = {x['time_in_step'] / x['dt']:.2f}·dt) in "
            f"both runs; run A took {case.describe(x, times=False)} first, run B {case.describe(y, times=False)}. "
            f"This is a tie: which of contacts at one instant goes first is not the model's to say, so neither run "
            f"is wrong.{why}")
    return [Cause("tie", text + case.consequence(), {"a": x, "b": y, "step": step,
                                                     "contacts": [list(k) for k in names]}, step=step)]


def collision_order(case: StepCase, found: list[Cause]) -> list[Cause]:
    """The same contacts in the step, resolved in another order."""
    if _contact_difference(case, found) != "order":
        return []
    x, y, sa, sb = case.event["a"], case.event["b"], case.settings_a, case.settings_b
    later_a = next((r for r in case.ca if _key(r) == _key(y)), None)
    text = (f"run A resolved {case.describe(x)} before "
            f"{case.describe(later_a) if later_a else '…'}{_why_order(sa.get('ordering'))}; run B resolved "
            f"{case.describe(y)} first{_why_order(sb.get('ordering'))}.")
    return [Cause("collision-order", text + case.consequence(),
                  {"a": x, "b": y, "ordering": [sa.get("ordering"), sb.get("ordering")]}, step=case.div.step)]


def missed_contact(case: StepCase, found: list[Cause]) -> list[Cause]:
    """A contact one run resolved and the other did not (or resolved later, or held with
    restitution 0 where the other bounced) — unless a tunnelling cause already says so."""
    if _contact_difference(case, found) != "missed" or any(c.kind == "tunnelling" for c in found):
        return []
    x, y, step = case.event["a"], case.event["b"], case.div.step
    present, missing, label, other = (x, y, "A", "B") if x is not None else (y, x, "B", "A")
    if present is not None and missing is not None and _key(present) == _key(missing):
        rest = "A" if x["resting"] else "B"
        text = (f"{case.describe(x, times=False)} was held in run {rest} (with restitution 0, "
                f"instead of bounced: the resting rule holds a pressed, slow contact, the rapid-contact rule a "
                f"pressed one soon after the spheres' previous contact, under rapid_contact_rule=tc only a slow "
                f"one) and bounced in the other")
        return [Cause("missed-contact", text + "." + case.consequence(), {"a": x, "b": y}, step=step)]
    in_other = [r for r in (case.cb if label == "A" else case.ca) if _key(r) == _key(present)]
    text = (f"run {label} resolved {case.describe(present)} (contact {present['index'] + 1} of the "
            f"step); run {other} " + (f"resolved it later, as contact {in_other[0]['index'] + 1}"
                                      if in_other else "had no such contact"))
    if missing is not None and not in_other:
        text += f", and resolved {case.describe(missing)} instead"
    return [Cause("missed-contact", text + "." + case.consequence(), {"a": x, "b": y}, step=step)]


def contact_outcome(case: StepCase, found: list[Cause]) -> list[Cause]:
    """The same contact at another time, or at the same time with another impulse."""
    if _contact_difference(case, found) != "outcome":
        return []
    x, y, step = case.event["a"], case.event["b"], case.div.step
    dt = x["dt"]
    if abs(x["time"] - y["time"]) > 0:
        text = (f"the same contact {case.describe(x, times=False)} happened at "
                f"{x['time_in_step'] / dt:.6f}·dt in A and {y['time_in_step'] / y['dt']:.6f}·dt in B "
                f"(a difference of {abs(x['time'] - y['time']):.2g} s)")
    else:
        text = (f"the same contact {case.describe(x, times=False)} at the same time had "
                f"another outcome: impulse {x['impulse']:.6g} N·s with e = {x['restitution']:.3g} in A, "
                f"{y['impulse']:.6g} N·s with e = {y['restitution']:.3g} in B")
        text += _rapid_rule(x, y, case.settings_a, case.settings_b)
    return [Cause("contact-outcome", text + "." + case.consequence(), {"a": x, "b": y}, step=step)]


def method_drift(case: StepCase, found: list[Cause]) -> list[Cause]:
    """No contact differs and nothing else explains the step: the methods drift apart."""
    if case.event is not None or any(c.kind in ("tunnelling", "engine-limits", "non-finite", "sleep") for c in found):
        return []
    d, step, growth = case.differ, case.div.step, case.growth
    method = [s.name for s in d.settings if s.matters and s.name in METHOD_SETTINGS]
    if method or not d.by_step:
        return [Cause("method-drift", f"no contact differs up to this step: the states drift apart "
                                      f"smoothly ({', '.join(method) or 'dt'} differ{'s' if len(method) == 1 else ''})"
                                      f"; {growth.sentence() if growth else ''}",
                      {"settings": method}, step=step)]
    return [Cause("method-drift", "no contact differs up to this step; the states drift apart because of the "
                                  "settings above", {}, step=step)]


STEP_CAUSES: tuple[Detector, ...] = (
    Detector(("initial-state",), initial_state, ends=True),
    Detector(("non-finite", "engine-limits"), engine_warnings),
    Detector(("tunnelling",), tunnelling),
    Detector(("outside-change",), outside_change, ends=True),
    Detector(("sleep",), sleep),
    Detector(("collision-order",), ordering_setting, leads=True),
    Detector(("tie",), tie),
    Detector(("collision-order",), collision_order),
    Detector(("missed-contact",), missed_contact),
    Detector(("contact-outcome",), contact_outcome),
    Detector(("method-drift",), method_drift),
)


def step_causes(case: StepCase, causes: list[Cause]) -> list[Cause]:
    """The causes of the diverging step, after ``causes`` (the settings that differ): each
    detector of STEP_CAUSES in turn, given what the ones before it found."""
    d, div = case.differ, case.div
    if case.prev_a is not None:  # decoded already by the search for the divergence
        d._states[(False, div.step - 1)], d._states[(True, div.step_b - 1)] = case.prev_a, case.prev_b
    for detector in STEP_CAUSES:
        made = detector.find(case, causes)
        for cause in made:
            if detector.leads:
                causes.insert(1 if causes and causes[0].kind == "settings" else 0, cause)
            else:
                causes.append(cause)
        if made and detector.ends:
            break
    return causes


# ----------------------------------------------------------------------------- helpers
def _rapid_rule(x: dict, y: dict, settings_a: dict, settings_b: dict) -> str:
    """Words for a contact made elastic in one run by physdbg's rapid-contact rule (e = 1
    where the other run's e is below 1, and the rule on in that run): its own cause, not
    the other run's mistake."""
    for label, row, other, settings in (("A", x, y, settings_a), ("B", y, x, settings_b)):
        window = settings.get("rapid_contact_time") or 0.0
        if row["restitution"] == 1.0 and other["restitution"] < 1.0 and window > 0:
            return (f" — e = 1 in {label} is physdbg's rapid-contact rule, which makes a contact that comes "
                    f"within rapid_contact_time = {window:g} s of either sphere's previous one elastic when "
                    f"nothing presses it (-s rapid_contact_time=0 turns it off)")
    return ""


def _order_note(sa: dict, sb: dict) -> str:
    if "index" in (sa.get("ordering"), sb.get("ordering")):
        return (" Ordering by index resolves the contacts predicted at the start of the step in index order, so a "
                "contact that an earlier one creates in the same step is missed; ordering by time resolves each "
                "contact at its time of impact and looks again after it.")
    return ""


def _why_order(ordering: str | None) -> str:
    return {"index": " because it orders by index", "time": " because it orders by time"}.get(ordering or "", "")


def _key(r: dict) -> tuple:
    """A contact row's identity: kind and partners (a pair the same either way round)."""
    if PARTNER_IS_SPHERE[r["kind"]]:
        return (r["kind"], min(r["a"], r["other"]), max(r["a"], r["other"]))
    return (r["kind"], r["a"], r["other"])


def _at_one_instant(r: dict, x: dict) -> bool:
    """Contact rows r and x of one step at one instant (resolve.SAME_INSTANT of the step)."""
    from ..engine.resolve import SAME_INSTANT

    return abs(r["time_in_step"] - x["time_in_step"]) <= SAME_INSTANT * x["dt"]


def _tied(x: dict, y: dict, ca, cb) -> bool:
    """Runs A and B first differ at contacts x (A's) and y (B's) of one step, at one instant,
    that share a sphere, and each run has the other's contact at that instant too: the
    contacts tied, and the runs took them in another order."""
    from .departure import bodies_of

    if not _at_one_instant(y, x) or not (set(bodies_of(x["kind"], x["a"], x["other"]))
                                         & set(bodies_of(y["kind"], y["a"], y["other"]))):
        return False
    return (any(_key(r) == _key(y) and _at_one_instant(r, x) for r in ca)
            and any(_key(r) == _key(x) and _at_one_instant(r, y) for r in cb))


def _touches(r: dict, crossing) -> bool:
    if r["kind"] != crossing.kind:
        return False
    if PARTNER_IS_SPHERE[crossing.kind]:
        return {r["a"], r["other"]} == {crossing.a, crossing.other}
    return r["a"] == crossing.a and r["other"] == crossing.other


def _count(n: int, noun: str) -> str:
    """'1 more step', '3 more steps' (report.count_words's words; report's annotations name
    diff's types, so this module does not import it)."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _show(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


__all__ = ["CAUSE_KINDS", "Cause", "Detector", "Divergence", "STEP_CAUSES", "StepCase", "step_causes"]
