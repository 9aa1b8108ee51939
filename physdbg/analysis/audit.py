"""Auditing one run: what went wrong, where, in words.

Why one module of this size: the checks share one observer's state through a run (the
previous step, the warnings, the rattling beds, the findings said once), so they are
methods of one class, each a stage a reader can take alone (``AUDIT_CHECKS``); what they
measure with lives elsewhere (tunnel.py, mesh_interpenetration.py, the engine's rules).

:class:`Auditor` is an observer: it reads the engine's events (live, during ``physdbg
run`` / ``record``) or the same events read back from a recording (``physdbg explain``),
so the live summary and the audit of a file are the same code. Each check is one method
of :class:`Auditor`; each problem found is a :class:`Finding`.

Checks (kind: what it means):

* ``tunnelling``: a sphere crossed a wall or another sphere with no contact (the exact
  swept test run over the recorded states, :mod:`.tunnel`; watching physdbg's own engine
  live, a step whose swept tests were exact and complete takes its pairs of spheres from
  them: engine_tests_exact);
* ``overlap``: spheres left overlapping after a step by more than the contact tolerance;
* ``order``: contacts of a step resolved out of time order;
* ``energy-gain``: a collision that left more kinetic energy than it found (an impulse
  alone: one solved with held contacts also moves the spheres they hold);
* ``non-finite``: a position or velocity became NaN or infinite;
* ``budget``: a step hit the contact cap (max_contacts_per_step) or another work budget and left work undone;
* ``collapse``: a collision rate that blows up (inelastic collapse). With sleeping on, a
  bed that rattles like that is judged when its spheres are asleep: if every sphere of
  the step is asleep by the end of the run, sleeping ended it, and a note says so instead;
* ``mesh-overlap``: two meshes, at least one of them kinematic, pass into each other (their
  prescribed motions are a scene bug: :mod:`.mesh_interpenetration`);
* ``pinned``: a kinematic mesh pressed a sphere against something immovable from the
  opposite side (the engine's ``pinned`` warning, resting.pinned_by): no impulse can stop
  a prescribed motion, so the run ended there;
* ``simultaneous``: a sphere met two immovable partners at one instant, and the two were
  resolved one after the other (``ordering = "index"``; the time-ordered loop solves them
  together): the first impulse changed the second's closing speed (normals neither
  parallel nor at right angles), or the rapid-contact rule held the second only because
  it came right after the first, so the order decided the outcome.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
from numba import njit

from ..events import (FEATURE_NAMES, HOW_AT_ONE_INSTANT, HOW_IMPULSE, HOW_RAPID, HOW_RESTING, KIND_MESH, KIND_WALL,
                      PARTNER_IS_SPHERE, Contacts, EngineWarning, StepEnd, contact_words, feature_words,
                      partner_is_sphere, partner_words)
from .mesh_interpenetration import MeshOverlaps
from .quiet import quiet_numerics
from .tunnel import StepChecker, sorted_unique
from .tunnel_words import why_tunnelled

FINDING_KINDS = ("tunnelling", "overlap", "order", "energy-gain", "non-finite", "budget", "collapse", "mesh-overlap",
                 "pinned", "simultaneous")
EXAMPLES_PER_KIND = 5
# a step with more bounces (contacts resolved by an impulse with restitution above 0) than
# this many per sphere they involve (and at least COLLAPSE_MIN_CONTACTS) is a collision
# rate that has blown up. Contacts a resting or rapid rule held are the remedy at work,
# not the collapse: rain with 500 spheres, exact to its end, settles with ~5 000 contacts
# a step among ~500 spheres, but only ~6 bounces a sphere, spread evenly
COLLAPSE_CONTACTS_PER_SPHERE = 10
COLLAPSE_MIN_CONTACTS = 200
# with sleeping on, a bed still rattling when the run ends is a collapse, unless it was
# falling asleep: at most this fraction of its spheres awake, and no step rattled in the
# last SETTLED_QUIET_STEPS (rain 500 under the pile rules: the 2-second run ends with 2 of
# a rattling step's 220 spheres awake and 22 quiet steps; it was reported as a collapse)
SETTLING_AWAKE_FRACTION = 0.02
SETTLED_QUIET_STEPS = 10
ENERGY_GAIN_RELATIVE = 1e-9  # rounding in one impulse is ~1e-16 relative; this is a real gain
FOREIGN_ENERGY_GAIN = 1e-3  # a run without contact records: a step's gain beyond this is a contact's doing


@dataclass
class Finding:
    """One problem. step: the step it happened in, counted from 1 (step k ends at frame k);
    particles: the spheres involved; message: one sentence; advice: what to change;
    position: (3,) m where to put a marker (None when there is no one place);
    evidence: the numbers behind the sentence; aside: the explanation that findings of its
    kind can share (said once: ``said_once``), or "": given apart from the message, which
    then ends with it in parentheses. The aside is not a field of the JSON: it is in the
    message already."""

    kind: str
    step: int
    particles: list[int]
    message: str
    advice: str = ""
    position: list[float] | None = None
    evidence: dict = field(default_factory=dict)
    aside: str = ""
    # the advice as a change of settings a fork can try (physdbg explain --try), {} where the
    # advice is not one (check each impulse's sign) or cannot change in the middle of a run
    try_settings: dict = field(default_factory=dict)
    before_aside: str = field(default="", init=False, repr=False)  # the message up to its aside
    after_aside: str = field(default="", init=False, repr=False)  # and what ``add_words`` put after it

    def __post_init__(self) -> None:
        self.before_aside = self.message
        if self.aside:
            self.message = f"{self.message} ({self.aside})"

    def add_words(self, words: str) -> None:
        """Say more at the end of the message (after its aside)."""
        self.message += words
        self.after_aside += words

    # the record every report prints (report.Record); the JSON keeps the fields above
    code = property(lambda self: self.kind)
    bodies = property(lambda self: tuple(self.particles))
    summary = property(lambda self: self.message)
    detail = property(lambda self: self.evidence)

    def as_dict(self) -> dict:
        out = asdict(self)
        del out["aside"], out["before_aside"], out["after_aside"]
        return out


@dataclass(frozen=True)
class AuditCheck:
    """One check of a step: method, the Auditor's method that makes it (called with the
    Auditor, the step, its StepEnd and its Contacts or None); kinds: the findings it makes; when: the
    steps it runs on — "always"; "meshes" (kinematic meshes that can meet); "not finite"
    (the state holds a NaN or infinity) or "finite"; "contacts" (finite, with contact
    records); "foreign" (finite, no contact records, another engine's run)."""

    method: Callable
    kinds: tuple[str, ...]
    when: str




@dataclass
class AuditReport:
    """What the audit of one run found. counts: findings per kind (all of them);
    findings: the first EXAMPLES_PER_KIND of each kind (every one with every_finding), in
    step order; checked: the steps audited; notes: what could not be checked and why."""

    source: str
    scene: str
    steps: int
    checked: int
    counts: dict[str, int]
    findings: list[Finding]
    notes: list[str] = field(default_factory=list)
    # the collider kinds of the run's partners the tunnelling check has no rule for
    unchecked: list[str] = field(default_factory=list)
    # advice tried on forks of the run (fork.try_advice, explain --try): one dict a try
    tried: list[dict] = field(default_factory=list)

    @property
    def clean(self) -> bool:
        return not self.counts

    def as_dict(self) -> dict:
        return {"source": self.source, "scene": self.scene, "steps": self.steps, "checked": self.checked,
                "clean": self.clean, "counts": self.counts, "findings": [f.as_dict() for f in self.findings],
                "notes": self.notes, "unchecked": self.unchecked, "tried": self.tried}

    def not_listed(self) -> dict[str, int]:
        """How many findings of each kind the report counts but does not list."""
        return not_listed(self.counts, self.findings)


def not_listed(counts: dict[str, int], findings: list[Finding]) -> dict[str, int]:
    """Of ``counts`` (findings of each kind), how many ``findings`` (those listed) leave out."""
    shown: dict[str, int] = {}
    for f in findings:
        shown[f.kind] = shown.get(f.kind, 0) + 1
    return {kind: count - shown.get(kind, 0) for kind, count in counts.items() if count > shown.get(kind, 0)}


def engine_tests_exact(settings: dict, warnings: list) -> bool:
    """Whether a step of physdbg's engine (its recorded ``settings``; the step's engine
    ``warnings``) tested every pair that could meet, exactly, and resolved every contact
    it found: swept tests (times of impact, not samples), time order (a contact one
    creates is predicted and resolved), and no warning (a budget, max_memory or a
    too-wide periodic box leaves work undone; an overlap says something went wrong).
    Then a sphere can pass into another only through a fault in the engine itself,
    which the tests of its swept tests and its reference loop look for; the live audit
    takes such a step's pairs from the engine (Auditor.engine_tested)."""
    return (settings.get("detection", "swept") == "swept" and settings.get("ordering", "time") == "time"
            and not warnings)


def said_once(findings: list) -> list[tuple]:
    """(finding, message, advice) of each finding, where what it shares with the first of its
    kind is "as above": its aside (the explanation in parentheses), when the first's is the
    same, and its advice, when the same."""
    first: dict[str, Finding] = {}
    out = []
    for f in findings:
        lead = first.setdefault(f.kind, f)
        advice = f.advice if lead is f or f.advice != lead.advice else "as above"
        message = f.message
        if lead is not f and f.aside and f.aside == lead.aside:
            message = f"{f.before_aside} (as above){f.after_aside}"
        out.append((f, message, advice))
    return out


class Auditor:
    """Observer that audits a run step by step.

    header: the run's RecordingHeader (constants, walls, settings, initial state);
    on_finding: called with each Finding as it is made (e.g. to mark it in the viewer).
    """

    wants_swept_tests = False  # it judges contacts and states, not the test log (observe.py)
    wants_mesh_search = False  # nor the walks of the meshes' trees

    def __init__(self, header, on_finding: Callable[[Finding], None] | None = None,
                 examples_per_kind: int | None = EXAMPLES_PER_KIND, engine_tested: bool = False):
        self.header = header
        # observing physdbg's own engine as it runs (api.run): a step whose swept tests were
        # exact and complete (engine_tests_exact) takes its pairs of spheres from them
        # rather than walking every pair's path again (the audit's cost: docs/benchmarks.md,
        # "What the audit costs"); `physdbg explain` always walks them
        self.engine_tested = engine_tested and not header.meta.get("foreign")
        self.pairs_from_engine = 0  # steps whose pairs the engine's tests stood for
        self.examples_per_kind = examples_per_kind  # findings kept of each kind (None: every one)
        self.settings = header.meta.get("settings", {})
        self.names = header.walls.partner_names()
        self.wall_names = list(header.walls.names)
        self.radius = header.radius
        self.mass = np.where(header.inverse_mass > 0, 1.0 / np.where(header.inverse_mass > 0,
                                                                        header.inverse_mass, 1.0), np.inf)
        self.checker = StepChecker(header.radius, header.inverse_mass, header.gravity_scale, header.walls,
                                   self.settings)
        self.tolerance = float(self.settings.get("contact_tolerance", 1e-9))
        self._pile_hint: str | None | bool = False  # advisor.pile_hint, worked out when first needed
        self.listeners = [on_finding] if on_finding else []
        self.counts: dict[str, int] = {}
        self.examples: list[Finding] = []
        self.steps = 0
        self.notes: list[str] = []
        self._x, self._v = header.positions.copy(), header.velocities.copy()
        self._contacts: Contacts | None = None
        self._warnings: list[EngineWarning] = []
        self._in_overlap = False  # the step before ended overlapping: the same overlap goes on
        self._mesh_geometry = None  # the meshes' collider group, built at the first overlap (deepest_overlap)
        # the collider kinds of this run's partners that the tunnelling check has no rule for
        # (a kind beyond the sphere, the wall and the mesh): said, never called clean
        self.unchecked_kinds = [kind for kind, partners in header.walls.partners.items() if len(partners)]
        self._non_finite = False  # the step before ended with a NaN or infinity: the same one goes on
        self._saw_contacts = False
        self._energy: float | None = None  # kinetic + potential after the last step (J)
        # with sleeping on, a rattling bed (a collapse finding and its spheres) waits until
        # they are all asleep (then a note: sleeping ended it) or the run ends (a finding)
        self._rattling: list[tuple[Finding, np.ndarray]] = []
        # a foreign run's energy in free flight (the integrator's drift): J, steps, the most a step
        self._flight_gain, self._flight_steps, self._flight_most = 0.0, 0, 0.0
        gravity = np.asarray(self.settings.get("gravity", (0.0, 0.0, 0.0)), dtype=np.float64)
        self._free_flight_acc = np.where(np.isfinite(self.mass)[:, None],
                                         np.asarray(header.gravity_scale)[:, None] * gravity[None, :], 0.0)
        # meshes whose prescribed motions pass through each other (mesh_interpenetration.py)
        self._mesh_overlaps = MeshOverlaps(header.walls.meshes) if header.walls.meshes.moving.any() else None
        self._rattled: list[tuple[int, int]] = []  # (step of the rattle, step all were asleep)
        self._settling: list[tuple[int, int, int]] = []  # (step of the rattle, awake at the end, its spheres)
        self._last_rattle = 0  # the last step whose bed rattled (with sleeping on)
        self._asleep: np.ndarray | None = None  # the last step's asleep mask

    # ------------------------------------------------------------------ observer
    def on_event(self, event) -> None:
        if isinstance(event, Contacts):
            self._contacts = event
            self._saw_contacts = True
        elif isinstance(event, EngineWarning):
            self._warnings.append(event)
        elif isinstance(event, StepEnd):
            with quiet_numerics():  # NaN states and immovable spheres are judged in words, not warned about
                self._end_step(event)

    def _end_step(self, end: StepEnd) -> None:
        step = end.step
        for entry in (self.header.meta.get("fork") or {}).get("chain", []):
            if entry["at"] == step:  # a fork's settings from their step on
                self.settings = {**self.settings, **entry["changes"]}
                self.checker = StepChecker(self.header.radius, self.header.inverse_mass, self.header.gravity_scale,
                                           self.header.walls, self.settings)
        contacts = self._contacts
        finite = bool(np.isfinite(end.positions).all() and np.isfinite(end.velocities).all())
        if finite:
            self._non_finite = False  # a NaN that appears again is named again
        recorded = contacts is not None and len(contacts) > 0
        when = {"always": True, "meshes": self._mesh_overlaps is not None and bool(self._mesh_overlaps.pairs),
                "not finite": not finite, "finite": finite, "contacts": finite and recorded,
                "foreign": finite and not recorded and bool(self.header.meta.get("foreign"))}
        for check in AUDIT_CHECKS:
            if when[check.when]:
                check.method(self, step, end, contacts)
        self._asleep = end.asleep
        # a rattling step's spheres can all be asleep only once one of them fell asleep
        if self._rattling and end.asleep is not None and end.counts.slept:
            still = []
            for finding, involved in self._rattling:
                if end.asleep[involved].all():
                    self._rattled.append((finding.step, step))
                else:
                    still.append((finding, involved))
            self._rattling = still
        self._x, self._v = end.positions, end.velocities
        self._energy = end.kinetic + end.potential
        self._contacts = None
        self._warnings = []
        self.steps = step

    def _add(self, finding: Finding) -> None:
        self.counts[finding.kind] = self.counts.get(finding.kind, 0) + 1
        if self.examples_per_kind is None or self.counts[finding.kind] <= self.examples_per_kind:
            self.examples.append(finding)
        for listener in self.listeners:
            listener(finding)

    # ------------------------------------------------------------------ checks
    def _check_mesh_overlap(self, step: int, end: StepEnd, contacts: Contacts | None) -> None:
        meshes = self.header.walls.meshes
        for m in self._mesh_overlaps.step(end.time - end.dt, end.time):
            a, b = meshes.names[m.first], meshes.names[m.second]
            moving = " and ".join(f"'{meshes.names[k]}' {meshes.motion_words(k)}" for k in (m.first, m.second)
                                  if meshes.moving[k])
            at = ("at the start of the run" if m.time == 0.0 else
                  f"from t = {m.time:.6g} s ({(m.time - (end.time - end.dt)) / end.dt:.3f}·dt into the step)")
            self._add(Finding("mesh-overlap", step, [],
                              f"meshes '{a}' and '{b}' pass into each other {at}: '{a}' triangle {m.triangles[0]} "
                              f"meets '{b}' triangle {m.triangles[1]} ({moving}); no contact between meshes is "
                              f"resolved, and a sphere caught between them is crushed",
                              "a kinematic mesh moves whatever it meets: change the meshes' positions or motions "
                              "so that they stay apart (physdbg overlap A B --pose ... shows where two meshes meet)",
                              [float(q) for q in m.point],
                              {"meshes": [a, b], "triangles": list(m.triangles), "time": m.time}))

    def _check_warnings(self, step: int, end: StepEnd, contacts: Contacts | None) -> None:
        from ..engine.state import BUDGETS, budget_value

        for w in self._warnings:
            if w.code == "non-finite":
                self._add(Finding("non-finite", step, [], w.message[0].upper() + w.message[1:] + ".",
                                  "look at the contacts of this step; a restitution, mass or speed out of "
                                  "proportion usually starts it", evidence={"warning": w.message}))
            elif w.code == "pinned":
                self._add(Finding("pinned", step, list(w.bodies),
                                  w.message[0].upper() + w.message[1:] + ": a prescribed motion cannot be stopped, "
                                  "so the run ended with this step.",
                                  "a kinematic mesh moves whatever it meets: leave the sphere a way out (move the "
                                  "mesh or the wall, or stop the motion short of it)", evidence={"warning": w.message}))
            elif w.code in BUDGETS:
                what, consequence = BUDGETS[w.code]
                value = budget_value(w.code, self.settings.get(w.code), self.header.count)  # 0: sized
                advice = (f"raise it with --set {w.code}=N, or see whether the scene is in inelastic collapse "
                          f"(many bounces among few spheres)")
                pile = self._pile()
                who, spheres = self._busiest(self._contacts)
                self._add(Finding("budget", step, spheres, f"the {w.code} budget ({value} {what}) was hit: "
                                  f"{consequence}{who}.",
                                  advice + (f"; {pile}" if pile else ""), evidence={"budget": w.code, "value": value}))

    def _busiest(self, c: Contacts | None) -> tuple[str, list[int]]:
        """Who a budget-stopped step's contacts were spent on, in words ("; 9,980 of its
        10,000 contacts were sphere 0's, most with mesh 'platform' triangle 0"), and the
        sphere; ("", []) without contact records."""
        if c is None or not len(c):
            return "", []
        spheres = np.concatenate([c.a, c.other[partner_is_sphere(c.kind)]])
        counts = np.bincount(spheres)
        top = int(np.argmax(counts))
        mine = (c.a == top) | (partner_is_sphere(c.kind) & (c.other == top))
        partners = [(int(k), int(o) if a == top else int(a)) for k, a, o in zip(c.kind[mine], c.a[mine], c.other[mine])]
        kind, other = max(set(partners), key=partners.count)
        partner = f"sphere {other}" if PARTNER_IS_SPHERE[kind] else partner_words(kind, other, self.names)
        return (f"; {int(counts[top]):,} of its {len(c):,} contacts were sphere {top}'s, most with {partner}",
                [top])

    def _check_finite(self, step: int, end: StepEnd, contacts: Contacts | None) -> None:
        """A state with a NaN or infinity that no engine warning reported (a run of another
        engine, or a file): named once, at the step it first appears, with the sphere."""
        if self._non_finite or any(w.code == "non-finite" for w in self._warnings):
            self._non_finite = True
            return
        self._non_finite = True
        bad_x = ~np.isfinite(end.positions).all(axis=1)
        bad_v = ~np.isfinite(end.velocities).all(axis=1)
        spheres = np.flatnonzero(bad_x | bad_v)
        i = int(spheres[0])
        what = "position" if bad_x[i] else "velocity"
        where = self._x[i] if np.isfinite(self._x[i]).all() else None
        self._add(Finding("non-finite", step, [int(p) for p in spheres[:10]],
                          f"sphere {i}'s {what} is NaN or infinite after the step ({len(spheres)} sphere"
                          f"{'s' if len(spheres) != 1 else ''} in all); it was at {_point(where)} before it",
                          "look at this step's contacts: a division by a zero distance (two centres at one point), a "
                          "zero mass or a speed out of proportion usually starts it",
                          [float(q) for q in where] if where is not None else None,
                          {"sphere": i, "field": what, "spheres": len(spheres)}))

    def _pile(self) -> str | None:
        """advisor.pile_hint for this run (a foreign run's settings say nothing of physdbg's rules)."""
        if self._pile_hint is False:
            from ..advisor import pile_hint

            self._pile_hint = None if self.header.meta.get("foreign") else pile_hint(self.header)
        return self._pile_hint

    def _check_crossings(self, step: int, end: StepEnd, contacts: Contacts | None) -> None:
        walk_pairs = not (self.engine_tested and engine_tests_exact(self.settings, self._warnings))
        self.pairs_from_engine += not walk_pairs and len(self.radius) > 1
        for c in self.checker.check(self._x, self._v, end.positions, end.dt, contacts, end.time - end.dt,
                                    pairs=walk_pairs):
            detection = "foreign" if self.header.meta.get("foreign") else self.settings.get("detection", "swept")
            budgets = [w.code for w in self._warnings if w.code != "non-finite" and w.code != "overlap"]
            why = why_tunnelled(self.settings, budgets, detection == "foreign", PARTNER_IS_SPHERE[c.kind],
                                self._pile() if budgets else None)
            advice = why.advice
            # a test that looks only at some instants says so in the message too
            how = {detection: why.reason} if detection in ("discrete", "sampled") else {}
            speed = float(np.linalg.norm(self._v[c.a]))
            travel = self._travel_words(c.a, end)
            if c.kind == KIND_WALL:
                name = self.wall_names[c.other]
                message = (f"sphere {c.a} went through wall '{name}' with no contact "
                           f"({travel}{'; ' + how[detection] if detection in how else ''})")
                where = self.header.walls.normals[c.other] * self.header.walls.offsets[c.other]
                # the point where the centre's straight path met the plane
                x0, x1 = self._x[c.a], end.positions[c.a]
                n, d = self.header.walls.normals[c.other], self.header.walls.offsets[c.other]
                h0, h1 = float(n @ x0 - d), float(n @ x1 - d)
                if h0 != h1:
                    where = x0 + (x1 - x0) * (h0 / (h0 - h1))
                self._add(Finding("tunnelling", step, [c.a], message, advice, [float(q) for q in where],
                                  {"wall": name, "speed": speed, "dt": end.dt, "detection": detection},
                                  try_settings=why.settings))
            elif not PARTNER_IS_SPHERE[c.kind]:  # a mesh's triangle
                partner = partner_words(c.kind, c.other, self.names)
                meshes = self.header.walls.meshes
                mesh = int(meshes.mesh_of[c.other])
                part = FEATURE_NAMES[c.feature] if c.feature >= 0 else "face"
                if meshes.moving[mesh]:  # the mesh swept through the sphere, more than the other way round
                    surface = float(np.linalg.norm(meshes.surface_velocity(mesh, c.where, end.time)))
                    message = (f"{partner} ({meshes.motion_words(mesh)}) swept through sphere {c.a} with no contact "
                               f"(across its {part}; its surface there moved {surface * end.dt:.3g} m in the step "
                               f"at {surface:.3g} m/s, the sphere {speed:.3g} m/s; the sphere ended "
                               f"{_length(c.depth)} past the triangle's plane"
                               f"{'; ' + how[detection] if detection in how else ''})")
                else:
                    message = (f"sphere {c.a} went through {partner} with no contact (across its {part}; {travel}, "
                               f"ending {_length(c.depth)} past the triangle's plane"
                               f"{'; ' + how[detection] if detection in how else ''})")
                self._add(Finding("tunnelling", step, [c.a], message, advice, [float(q) for q in c.where],
                                  {"mesh": meshes.names[mesh], "triangle": c.other - int(meshes.first[mesh]),
                                   "feature": part,
                                   "triangle_index": c.other, "speed": speed, "dt": end.dt,
                                   "detection": detection}, try_settings=why.settings))
            else:
                message = (f"spheres {c.a} and {c.other} passed into each other with no contact at "
                           f"{c.time / end.dt:.3f}·dt, {_length(c.depth)} deep")  # then the aside, how
                where = 0.5 * (end.positions[c.a] + end.positions[c.other])
                self._add(Finding("tunnelling", step, [c.a, c.other], message, advice, [float(q) for q in where],
                                  {"time_in_step": c.time, "depth": c.depth, "detection": detection},
                                  aside=how.get(detection, ""), try_settings=why.settings))

    def _travel_words(self, i: int, end: StepEnd) -> str:
        """How far sphere i got in the step and how fast, from the run's own numbers: the
        straight distance from its start to its end (the nearest image in a periodic box),
        at its speed at the start, and at the end too where a contact or a force changed
        it by more than a tenth (a sphere struck in the step moved farther than its
        starting speed says)."""
        from ..engine.periodic import minimum_image

        moved = float(np.linalg.norm(minimum_image(end.positions[i] - self._x[i], self.header.walls.period)))
        before, after = float(np.linalg.norm(self._v[i])), float(np.linalg.norm(end.velocities[i]))
        if float(np.linalg.norm(end.velocities[i] - self._v[i])) <= 0.1 * max(before, after):
            return f"it moved {moved:.3g} m in the step at {before:.3g} m/s"
        return (f"it ended {moved:.3g} m from where it started the step, its velocity changed on the way "
                f"({before:.3g} m/s at the start, {after:.3g} m/s at the end)")

    def _check_overlap(self, step: int, end: StepEnd, contacts: Contacts | None) -> None:
        if not end.max_overlap > max(self.tolerance, 0.0):
            self._in_overlap = False
            return
        if self._in_overlap:  # counted where it began
            return
        self._in_overlap = True
        if self._mesh_geometry is None and self.header.walls.meshes.triangles:  # placed at each overlap
            from ..engine.colliders.mesh import MeshGeometry

            self._mesh_geometry = MeshGeometry.of(self.header.walls)  # the header's mesh set's trees
        depth, spheres, partner, where = deepest_overlap(end.positions, self.radius, self.header.walls, end.time,
                                                         self._mesh_geometry)
        wall = partner[1] if partner is not None and partner[0] == KIND_WALL else None
        if partner is not None:
            # a triangle with the feature the sphere's centre is nearest: its face, an edge or a corner
            where_on = f" ({feature_words(partner[2])})" if len(partner) > 2 else ""
            who = f"sphere {spheres[0]} and {partner_words(partner[0], partner[1], self.names)}{where_on} overlap"
        elif spheres:
            who = f"spheres {spheres[0]} and {spheres[1]} overlap"
        else:  # across a periodic boundary, where the search below does not look
            who, depth = "spheres overlap", end.max_overlap
        # an overlap after the first step may be the scene's own start: no setting removes that
        started = False
        if step == 1 and spheres:  # these spheres, overlapping already where the run starts
            mine = np.asarray(spheres, dtype=np.int64)
            started = deepest_overlap(self._x[mine], self.radius[mine], self.header.walls, end.time - end.dt,
                                      self._mesh_geometry)[0] > max(self.tolerance, 0.0)
        advice = ("the scene starts with bodies inside each other (`physdbg check` names each sphere that does), and "
                  "physdbg does not push bodies apart: it resolves contacts from where they are, so the overlap stays "
                  "until their motions part them; move them apart in the scene" if started
                  else self._overlap_advice(step))
        self._add(Finding("overlap", step, spheres,
                          f"{who} by {_length(depth)} after the step (the contact tolerance is {self.tolerance:g} m)",
                          advice, [float(q) for q in where] if where is not None else None,
                          {"depth": depth, "max_overlap": end.max_overlap, "wall": self.wall_names[wall]
                           if wall is not None else None, "at_start": started},
                          try_settings={} if started else self._overlap_try()))

    def _overlap_try(self) -> dict:
        """The overlap advice as settings a fork can try: swept detection where the run's
        test looks only at some instants (and no budget stopped the step: _overlap_advice's
        order), else none."""
        if self.header.meta.get("foreign") or any(w.code.startswith("max_") for w in self._warnings):
            return {}
        return {"detection": "swept"} if self.settings.get("detection", "swept") != "swept" else {}

    def _overlap_advice(self, step: int) -> str:
        """Why a run left an overlap, from what the run says of itself."""
        if self.header.meta.get("foreign"):
            return ("the other engine left them inside each other: a contact found late (where the step ends) or "
                    "resolved with too small an impulse; test along the path (a swept test) and resolve at the "
                    "time of impact")
        budgets = [w.code for w in self._warnings if w.code.startswith("max_")]
        if budgets:
            return f"this step hit the {budgets[0]} budget, so contacts after it were not resolved: raise it"
        detection = self.settings.get("detection", "swept")
        if detection != "swept":
            return (f"detection = {detection} finds a contact only once the spheres overlap (where a step ends or "
                    f"at sampled instants): use detection = swept, or a shorter dt")
        if self.settings.get("ordering") == "index":
            return ("ordering = index resolves the step's predicted contacts in index order, so a contact that an "
                    "earlier one creates in the same step is never looked for, and the spheres end inside each "
                    "other: use ordering = time")
        return ("a swept, time-ordered run should leave no overlap: if the scene did not start this way, please "
                "report it with the recording")

    def _check_order(self, step: int, end: StepEnd, c: Contacts) -> None:
        dt = end.dt
        t = c.time_in_step
        late = np.nonzero(t[1:] < t[:-1] - 1e-12 * dt)[0]
        if not len(late):
            return
        i = int(late[0])
        first, second = self._who(c, i), self._who(c, i + 1)
        ordering = self.settings.get("ordering", "time")
        self._add(Finding("order", step, [int(c.a[i]), int(c.a[i + 1])],
                          f"contacts resolved out of time order: {first} (t = {t[i] / dt:.3f}·dt) before "
                          f"{second} (t = {t[i + 1] / dt:.3f}·dt)"
                          + (" because ordering = index" if ordering == "index" else ""),
                          "use ordering = time: a contact is resolved before the later ones it changes",
                          evidence={"first": [i, float(t[i])], "second": [i + 1, float(t[i + 1])],
                                    "ordering": ordering}))

    def _check_simultaneous(self, step: int, end: StepEnd, c: Contacts) -> None:
        """Two contacts of one sphere with immovable partners at the same instant (the same
        time_in_step, to the bit), resolved one after the other, the first with an impulse
        not held, whose normals are neither parallel nor perpendicular (|n_1·n_2| between
        1e-9 and 1 - 1e-9), or the second held by the rapid-contact rule right after the
        first: the order decided how the sphere left (a ball dropped onto the crease of a
        symmetric V leaves it sideways). The time-ordered loop solves such contacts together
        (how = HOW_AT_ONE_INSTANT: never named); ``ordering = "index"`` resolves them in
        turn. Named once per step, the first such pair; swept runs only (another
        detection's, or another engine's, times are not instants)."""
        if self.settings.get("detection", "swept") != "swept" or self.header.meta.get("foreign"):
            return  # only a swept test's times are instants (a discrete run's contacts share the step's end)
        # the candidates, grouped by sphere and instant, in numpy (a step holds hundreds of
        # contacts, and a loop over every pair of them would be quadratic)
        rows = np.flatnonzero(~partner_is_sphere(c.kind) & (c.impulse > 0.0) & (c.how != HOW_AT_ONE_INSTANT))
        if len(rows) < 2:
            return
        rows = rows[np.lexsort((rows, c.time_in_step[rows], c.a[rows]))]
        same = (c.a[rows[1:]] == c.a[rows[:-1]]) & (c.time_in_step[rows[1:]] == c.time_in_step[rows[:-1]])
        for k in np.flatnonzero(same):
            i, j = int(rows[k]), int(rows[k + 1])  # in the order they were resolved
            if int(c.how[i]) in (HOW_RESTING, HOW_RAPID):
                continue  # held first: the second was solved with it, together
            facing = abs(float(np.dot(c.normal[i], c.normal[j])))
            coupled = 1e-9 < facing < 1.0 - 1e-9
            by_rule = int(c.how[j]) == HOW_RAPID
            if not (coupled or by_rule):
                continue
            a = int(c.a[i])
            first, second = (partner_words(int(c.kind[r]), int(c.other[r]), self.names) for r in (i, j))
            leaving = ", ".join(f"{q:.3g}" for q in np.asarray(c.velocity_a_after[j], dtype=np.float64))
            why = ("the rapid-contact rule held the second, with restitution 0, only because it came right "
                   "after the first" if by_rule else "the first impulse changed the second's closing speed")
            by_index = self.settings.get("ordering", "time") == "index"
            self._add(Finding("simultaneous", step, [a],
                              f"sphere {a} met {first} and {second} at one instant ({c.time_in_step[i] / end.dt:.3f}·dt "
                              f"into the step), and they were resolved one after the other: {first} first, with "
                              f"restitution {c.restitution[i]:.3g}, then {second}, with {c.restitution[j]:.3g}; "
                              f"{why}, so the order decided how it left (at ({leaving}) m/s)",
                              ("ordering = index resolves contacts in turn, in the order they were detected; "
                               "ordering = time solves a sphere's contacts at one instant together"
                               if by_index else
                               "the time-ordered loop solves together at most 4 contacts of a sphere at one "
                               "instant, one of each set of parallel normals")
                              + " (docs/meshes.md, \"Contacts at one instant\"); read the outcome as one of the "
                                "orders, not the answer",
                              evidence={"rows": [i, j], "time": float(c.time_in_step[i])}))
            return

    def _who(self, c: Contacts, i: int) -> str:
        return contact_words(int(c.kind[i]), int(c.a[i]), int(c.other[i]), self.names)

    def _kicked(self, end: StepEnd) -> bool:
        """Whether some sphere's velocity changed in the step by more than its free flight
        explains (gravity's g·dt, drag's share of its speed, and 1 % of g·dt for the
        integrator's own way of applying them): a contact, or anything else that kicked it."""
        dt = end.dt
        drag = float(self.settings.get("drag", 1.0))
        gravity = np.asarray(self.settings.get("gravity", (0.0, 0.0, 0.0)), dtype=np.float64)
        movable = np.isfinite(self.mass)
        flight = self._free_flight_acc * dt
        change = end.velocities - self._v - flight
        speed = np.linalg.norm(self._v, axis=1)
        allowed = speed * (1.0 - drag ** dt) * 2.0 + 0.01 * float(np.linalg.norm(gravity)) * dt + 1e-9 * (speed + 1.0)
        return bool(np.any(movable & (np.linalg.norm(change, axis=1) > allowed)))

    def _check_energy_of_states(self, step: int, end: StepEnd, contacts: None) -> None:
        """A run of another engine has no contact records: a step in which a sphere was
        kicked (its velocity changed by more than free flight explains: ``_kicked``) and
        that gained more mechanical energy than FOREIGN_ENERGY_GAIN of what it had is a
        contact that added energy. A step of free flight is the integrator's: explicit Euler
        gains energy under gravity every step by design; that drift is a note, not a finding
        (check-run names the integrator)."""
        before, after = self._energy, end.kinetic + end.potential
        if before is None or not np.isfinite(before) or not np.isfinite(after):
            return
        scale = max(abs(before), end.kinetic, 1e-12)
        if not self._kicked(end):
            self._flight_gain += after - before
            self._flight_steps += 1
            self._flight_most = max(self._flight_most, (after - before) / scale)
            return
        if after - before > FOREIGN_ENERGY_GAIN * scale:
            moved = np.linalg.norm(end.velocities - self._v, axis=1)
            who = [int(i) for i in np.argsort(-moved)[:2] if moved[i] > 0]
            self._add(Finding("energy-gain", step, who,
                              f"the run gained {after - before:.3g} J in this step ({before:.4g} -> {after:.4g} J, "
                              f"+{100 * (after - before) / scale:.2g} %), more than any integrator drifts in one step; "
                              f"spheres {', '.join(map(str, who))} changed velocity most",
                              "an impulse with the wrong sign, or restitution above 1: the impulse on a is "
                              "j = -(1 + e) (v_rel · n) / (1/m_a + 1/m_b) along n from b to a",
                              [float(q) for q in end.positions[who[0]]] if who else None,
                              {"before": before, "after": after}))

    def _check_energy(self, step: int, end: StepEnd, c: Contacts) -> None:
        before, after = contact_energies(self.mass, c.a.astype(np.int64), c.other.astype(np.int64),
                                         partner_is_sphere(c.kind), *(np.ascontiguousarray(rows, dtype=np.float64)
                                                                      for rows in (c.velocity_a_before,
                                                                                   c.velocity_a_after,
                                                                                   c.velocity_b_before,
                                                                                   c.velocity_b_after)))
        gain = after - before
        # only an impulse alone is a closed exchange between two spheres: a contact solved
        # with held contacts (held itself, or reaching them) moves other spheres as well,
        # and the pair's own energy may rise while theirs falls
        alone = c.how == HOW_IMPULSE
        bad = np.nonzero(alone & (gain > ENERGY_GAIN_RELATIVE * np.maximum(before, 1e-300)))[0]
        if not len(bad):
            return
        i = int(bad[0])
        self._add(Finding("energy-gain", step, [int(c.a[i])] + ([int(c.other[i])] if PARTNER_IS_SPHERE[c.kind[i]] else []),
                          f"contact {self._who(c, i)} left {gain[i]:.3g} J more kinetic energy than it found "
                          f"({before[i]:.3g} J before, e = {c.restitution[i]:.3g})",
                          "a restitution above 1, or an impulse applied twice", list(map(float, c.point[i])),
                          {"before": float(before[i]), "after": float(after[i]), "contact": i}))

    def _check_collapse(self, step: int, end: StepEnd | None, c: Contacts) -> None:
        bounce = c.restitution > 0.0
        bounces = int(bounce.sum())
        if bounces < COLLAPSE_MIN_CONTACTS:
            return
        involved = sorted_unique(np.concatenate([c.a[bounce], c.other[bounce & partner_is_sphere(c.kind)]]))
        if bounces < COLLAPSE_CONTACTS_PER_SPHERE * len(involved):
            return
        named = ", ".join(str(int(i)) for i in involved[:5]) + (", …" if len(involved) > 5 else "")
        spheres = f"{len(involved)} sphere{'s' if len(involved) != 1 else ''} ({named})"
        # name the rule against collapse that is off; with both on, what is left to change
        rules = []
        if not self.settings.get("rest_fraction"):
            rules.append(f"let slow pressed contacts rest (rest_fraction, now {self.settings.get('rest_fraction')})")
        if not self.settings.get("rapid_contact_time"):
            rules.append(f"hold contacts that follow each other within rapid_contact_time (now "
                         f"{self.settings.get('rapid_contact_time')} s)")
        if self.settings.get("rapid_contact_time") and self.settings.get("rapid_contact_rule") == "tc":
            if self.settings.get("sleep_speed"):
                rules.append(f"under tc a dense bed rattles until its spheres fall asleep: a higher sleep_speed "
                             f"(now {self.settings.get('sleep_speed')} m/s) or a shorter sleep_time (now "
                             f"{self.settings.get('sleep_time')} s) ends it sooner (rapid_contact_rule=hold holds "
                             f"such contacts instead, but passes each impact through the pile)")
            else:
                rules.append("hold pressed rapid contacts at any speed (rapid_contact_rule=hold): under tc the fast "
                             "ones stay elastic, so a dense pile keeps rattling; or let the slow spheres of the "
                             "pile sleep (sleep_speed, e.g. 0.1 m/s, with sleep_time=0.1): it freezes the bed as "
                             "it cools")
        # every sphere, wall and mesh of restitution 1 (not the contacts': the tc rule makes
        # a dense bed's fast contacts elastic): no energy is lost, so no gap shrinks
        # geometrically, and a blown-up rate means a step long for the motion
        walls = self.header.walls
        elastic = bool(np.all(self.header.restitution >= 1.0) and np.all(walls.restitution >= 1.0)
                       and np.all(walls.meshes.restitution >= 1.0))
        # a kinematic mesh's prescribed motion striking the same spheres again and again
        meshes = walls.meshes
        on_mesh = bounce & (c.kind == KIND_MESH)
        driven = on_mesh.copy()
        if on_mesh.any():
            driven[on_mesh] = meshes.moving[meshes.mesh_of[c.other[on_mesh]]]
        detection = self.settings.get("detection", "swept")
        headline = f"{bounces} bounces among {spheres} in one step: the collision rate has blown up"
        try_settings = {}
        if detection in ("discrete", "sampled") and self._at_the_test_s_instants(c, bounce, end, detection):
            # every contact of such a run is found at an instant the test looks, among
            # spheres already overlapping there: the storm is the test's, not the motion's
            where = ("where the step ends" if detection == "discrete"
                     else f"at its {self.settings.get('samples')} samples a step")
            headline = (f"{bounces} bounces among {spheres} in one step, at the instants the {detection} test looks "
                        f"({where})")
            why = (f"detection = {detection} finds contacts only among spheres already overlapping at those instants, "
                   "and an impulse can leave a sphere approaching another body it overlaps, so the same spheres are "
                   "bounced again and again at one instant; swept tests meet each contact at its own time of impact")
            advice = "use detection = swept (each contact at its time of impact), or a shorter dt"
            try_settings = {"detection": "swept"}
        elif 2 * int(driven.sum()) > bounces:
            names = sorted({f"'{meshes.names[k]}'" for k in meshes.mesh_of[c.other[driven]].tolist()})
            why = (f"kinematic mesh {', '.join(names)} drives them: its prescribed motion strikes the same spheres "
                   "again and again within the step, as when it carries a sphere or squeezes it against something, "
                   "and no contact can slow it")
            advice = "; ".join([*(rules[:2] and [f"{'; '.join(rules[:2])}: a held contact rides a moving surface"]),
                                "lowering the restitution or dt does not stop a prescribed motion: give the spheres "
                                "room (move what they are pressed against) or slow the mesh (docs/meshes.md)"])
        elif elastic:
            why = ("with restitution 1 this is not inelastic collapse: the spheres meet this often within one step "
                   "because the step is long for their speeds and the gaps between them")
            advice = "use a shorter dt (each step's contacts are bounded by max_contacts_per_step)"
        else:
            why = ("inelastic collapse: with restitution below 1 the gaps between a few spheres shrink geometrically "
                   "and they collide ever more often")
            advice = "; ".join(rules) or "lower the restitution, or use a shorter dt"
        finding = Finding("collapse", step, involved[:10].tolist(), headline, advice,
                          evidence={"contacts": len(c), "bounces": bounces, "spheres": len(involved)}, aside=why,
                          try_settings=try_settings)
        if self.settings.get("sleep_speed"):
            self._rattling.append((finding, involved))
            self._last_rattle = step
        else:
            self._add(finding)

    def _at_the_test_s_instants(self, c: Contacts, bounce: np.ndarray, end: StepEnd | None, detection: str) -> bool:
        """Whether most of a step's bounces (mask of c) fall at the instants a discrete
        (the step's end) or sampled test (its samples) looks: the storm is then the test's."""
        times = c.time_in_step[bounce]
        dt = end.dt if end is not None else float(times.max(initial=0.0))
        if not dt > 0:
            return False
        samples = 1 if detection == "discrete" else int(self.settings.get("samples", 4))
        where = times * samples / dt
        return 2 * int(np.count_nonzero(np.abs(where - np.round(where)) <= 1e-6)) > len(times)

    def finish(self) -> None:
        """The run has ended: a rattling bed not yet all asleep is a collapse finding after
        all (its listeners hear of it now). report() calls it; call it yourself before
        closing what the listeners write to."""
        quiet = self.steps - self._last_rattle
        for finding, involved in self._rattling:
            if self._asleep is not None:
                awake = int(np.count_nonzero(~self._asleep[involved]))
                if awake <= SETTLING_AWAKE_FRACTION * len(involved) and quiet >= SETTLED_QUIET_STEPS:
                    self._settling.append((finding.step, awake, len(involved)))
                    continue
                finding.add_words(f"; {awake} of the {len(involved)} spheres were still awake when the run "
                                  f"ended (step {self.steps})")
                finding.evidence["awake_at_end"] = awake
            self._add(finding)
        self._rattling = []

    # ------------------------------------------------------------------ result
    def report(self, source: str, total_steps: int | None = None) -> AuditReport:
        self.finish()
        notes = list(self.notes)
        if self._rattled:
            (first, _), last = self._rattled[0], max(asleep for _, asleep in self._rattled)
            notes.append(f"the bed rattled (at least {COLLAPSE_CONTACTS_PER_SPHERE} bounces a sphere) in "
                         f"{len(self._rattled)} step{'s' if len(self._rattled) != 1 else ''} from step {first}, and "
                         f"every sphere of those steps was asleep by step {last}: sleeping ended it, so it is not "
                         f"reported as a collapse")
        if self._settling:
            awake = sum(a for _, a, _ in self._settling)
            spheres = sum(n for _, _, n in self._settling)
            notes.append(f"the bed was still falling asleep when the run ended (step {self.steps}): "
                         f"{len(self._settling)} rattling step{'s' if len(self._settling) != 1 else ''} from step "
                         f"{self._settling[0][0]} left {awake} of {'its' if len(self._settling) == 1 else 'their'} "
                         f"{spheres} spheres awake, and no step rattled "
                         f"in the last {self.steps - self._last_rattle}: not reported as a collapse (a longer "
                         f"run shows whether it sleeps)")
        foreign = self.header.meta.get("foreign")
        if foreign and self.steps:
            notes.append(f"a run of another engine (from {foreign['source']}, velocities {foreign['velocities']}): "
                         "crossings and overlaps are judged from its states, energy from each step's total")
            if self._flight_steps and self._flight_gain > 0 and self._flight_most > FOREIGN_ENERGY_GAIN:
                notes.append(f"in free flight ({self._flight_steps} steps with no kick) the run gained "
                             f"{self._flight_gain:.3g} J, up to {100 * self._flight_most:.2g} % in a step: its "
                             f"integrator's drift, not a contact's (explicit Euler gains energy under gravity every "
                             f"step; physdbg check-run names the integrator)")
        elif not self._saw_contacts and self.steps:
            notes.append("no contacts recorded (detail state): crossings are judged from states alone, and "
                         "order, energy and collapse checks need --detail contacts")
        if self.unchecked_kinds:
            notes.append(unchecked_words(self.unchecked_kinds))
        examples = sorted(self.examples, key=lambda f: (f.step, FINDING_KINDS.index(f.kind)))
        return AuditReport(source, self.header.name, total_steps if total_steps is not None else self.steps,
                           self.steps, dict(self.counts), examples, notes, list(self.unchecked_kinds))


# the audit's checks of a step, in the order they run: each finding comes from one of them
AUDIT_CHECKS = (
    AuditCheck(Auditor._check_warnings, ("non-finite", "pinned", "budget"), "always"),
    AuditCheck(Auditor._check_mesh_overlap, ("mesh-overlap",), "meshes"),
    AuditCheck(Auditor._check_finite, ("non-finite",), "not finite"),
    AuditCheck(Auditor._check_crossings, ("tunnelling",), "finite"),
    AuditCheck(Auditor._check_overlap, ("overlap",), "finite"),
    AuditCheck(Auditor._check_order, ("order",), "contacts"),
    AuditCheck(Auditor._check_simultaneous, ("simultaneous",), "contacts"),
    AuditCheck(Auditor._check_energy, ("energy-gain",), "contacts"),
    AuditCheck(Auditor._check_collapse, ("collapse",), "contacts"),
    AuditCheck(Auditor._check_energy_of_states, ("energy-gain",), "foreign"),
)


def explain(recording, on_step: Callable[[int, int], None] | None = None, verify: bool = True,
            every_finding: bool = False) -> AuditReport:
    """Audit one recording (a path or an open Recording): every check, every step.
    verify: check every state against its stored hash and the frame index as it is read;
    every_finding: list every finding, not the first EXAMPLES_PER_KIND of each kind."""
    from ..record import open_recording
    from ..record.reader import Recording

    rec = recording if isinstance(recording, Recording) else open_recording(recording, verify=verify)
    try:
        with quiet_numerics():
            return _explain(rec, on_step, every_finding)
    finally:
        if rec is not recording:
            rec.close()


def _explain(rec, on_step, every_finding: bool = False) -> AuditReport:
    auditor = Auditor(rec.header, examples_per_kind=None if every_finding else EXAMPLES_PER_KIND)
    detail = "contacts" if rec.detail != "state" else "state"
    for events in rec.iter_step_events(detail=detail):
        for event in events:
            auditor.on_event(event)
        if on_step is not None:
            on_step(auditor.steps, rec.steps)
    report = auditor.report(str(rec.path), rec.steps)
    if rec.truncated:
        report.notes.append(f"the file is truncated (its writer was killed): steps 1..{rec.steps} audited")
    return report


@njit(cache=True)
def contact_energies(mass, a, other, pair, va_before, va_after, vb_before, vb_after):
    """The kinetic energy (J) each contact row found and left: (before, after), each (M,).

    mass: (N,) kg (inf: immovable, which counts 0); a, other: (M,) the rows' spheres and
    partners; pair: (M,) bool, whether the partner is a sphere; velocities (M, 3) m/s as
    recorded. A sphere's energy against a moving mesh is measured relative to the surface
    (recorded as b's velocity; NaN for anything else immovable): the surface does work on
    what it strikes, and the energy that must not grow is the one relative to it. Compiled:
    as numpy, ~0.75 ms a step for box-rain 10k's 5,500 contacts (numpy's einsum summed
    some rows differently in the last bit)."""
    m = a.shape[0]
    before = np.zeros(m)
    after = np.zeros(m)
    for r in range(m):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        if not pair[r] and np.isfinite(vb_before[r, 0]) and np.isfinite(vb_before[r, 1]) \
                and np.isfinite(vb_before[r, 2]):
            s0 = vb_before[r, 0]
            s1 = vb_before[r, 1]
            s2 = vb_before[r, 2]
        ma = mass[a[r]]
        if np.isfinite(ma):
            x0, x1, x2 = va_before[r, 0] - s0, va_before[r, 1] - s1, va_before[r, 2] - s2
            before[r] = 0.5 * ma * (x0 * x0 + x1 * x1 + x2 * x2)
            y0, y1, y2 = va_after[r, 0] - s0, va_after[r, 1] - s1, va_after[r, 2] - s2
            after[r] = 0.5 * ma * (y0 * y0 + y1 * y1 + y2 * y2)
        if pair[r]:
            mb = mass[other[r]]
            if np.isfinite(mb):
                x0, x1, x2 = vb_before[r, 0], vb_before[r, 1], vb_before[r, 2]
                before[r] += 0.5 * mb * (x0 * x0 + x1 * x1 + x2 * x2)
                y0, y1, y2 = vb_after[r, 0], vb_after[r, 1], vb_after[r, 2]
                after[r] += 0.5 * mb * (y0 * y0 + y1 * y1 + y2 * y2)
    return before, after


def warm_up() -> None:
    """Compile (or load from numba's cache) the audit's kernels: the step checker's
    (tunnel.warm_up) and contact_energies, on two contacts written out (a head-on pair and
    a wall), so that an audited run's first steps pay for none of it."""
    from .tunnel import warm_up as warm_up_checker

    warm_up_checker()
    velocities = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    contact_energies(np.ones(2), np.array([0, 1]), np.array([1, 0]), np.array([True, False]), velocities,
                     -velocities, velocities, np.full((2, 3), np.nan))


def deepest_overlap(x: np.ndarray, radius: np.ndarray, walls, time: float = 0.0, geometry: tuple | None = None):
    """(depth m, spheres, partner (kind, index), for a triangle (kind, index, contact
    feature code: events.FEATURE_NAMES, from 1) or None, where (3,) or None) of the deepest
    overlap of positions x (N, 3) at run time ``time`` (s; where the kinematic meshes
    are): sphere pairs found by the grid broad phase on the spheres' own boxes (not across
    a periodic boundary; partner None), every sphere with every wall (a sphere past a thin
    wall's middle went through it: tunnelling, not an overlap) and with every mesh
    triangle. Depth 0 when none. geometry: the meshes' collider group
    (colliders.mesh.MeshGeometry), if the caller keeps one: it is placed here."""
    from ..engine.broadphase.boxes import NO_LIMIT
    from ..engine.broadphase.grid import grid_pairs
    from ..engine.colliders.plane import gaps

    r = radius
    best = (0.0, [], None, None)
    finite = np.isfinite(x).all(axis=1)
    if len(x) > 1 and finite.all():
        pairs, _, _ = grid_pairs(x - r[:, None], x + r[:, None], 0.0, NO_LIMIT)
        if len(pairs):
            a, b = pairs[:, 0], pairs[:, 1]
            pen = r[a] + r[b] - np.linalg.norm(x[a] - x[b], axis=1)
            k = int(np.argmax(pen))
            if pen[k] > 0:
                i, j = int(a[k]), int(b[k])
                best = (float(pen[k]), [i, j], None, x[i] + (x[j] - x[i]) * (r[i] / (r[i] + r[j])))
    if len(walls.names) and finite.any():
        pen = -gaps(x, r, walls)  # on the side each centre is pushed back to
        pen = np.where(walls.two_sided[None, :] & (pen > r[:, None]), 0.0, pen)  # went through: tunnelling
        pen = np.where(finite[:, None], pen, -np.inf)
        i, w = np.unravel_index(int(np.argmax(pen)), pen.shape)
        if pen[i, w] > best[0]:
            best = (float(pen[i, w]), [int(i)], (KIND_WALL, int(w)), x[i])
    if walls.meshes.triangles and finite.all():
        from ..engine.colliders.mesh import MeshGeometry, deepest_where, place

        geometry = geometry if geometry is not None else MeshGeometry.of(walls)
        place(geometry, walls.meshes, time, 0.0)  # a kinematic mesh where it is at the end of the step
        depth, i, t = deepest_where(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(r, dtype=np.float64),
                                    tuple(geometry), True)
        if depth > best[0]:
            from ..engine.mesh.closest import closest_on_triangle

            corner = geometry.corners[int(t)]  # (3, 3), where the mesh is at ``time``
            feature = closest_on_triangle(*x[int(i)], *corner[0], *corner[1], *corner[2])[3]
            best = (float(depth), [int(i)], (KIND_MESH, int(t), int(feature) + 1), x[int(i)])
    if any(len(partners) for partners in walls.partners.values()) and finite.all():
        from ..engine.colliders import deepest_of_kind, extra_kinds, geometry_of

        kinds_geometry = geometry_of(walls)
        no_pairs = np.zeros((0, 2), dtype=np.int64)
        for code, _name, _module in extra_kinds():  # each through the engine's own switch
            depth, i, other = deepest_of_kind(code, np.ascontiguousarray(x, dtype=np.float64),
                                              np.ascontiguousarray(r, dtype=np.float64), no_pairs, kinds_geometry,
                                              True)
            if depth > best[0]:
                best = (float(depth), [int(i)], (code, int(other)), x[int(i)])
    return best


def unchecked_words(kinds: list[str]) -> str:
    """What the audit could not check of a run with partners of kinds it has no tunnelling
    rule for (Auditor.unchecked_kinds)."""
    return (f"tunnelling through {', '.join(f'{kind} partners' for kind in kinds)} is not checked (the tunnelling "
            f"check knows sphere pairs, walls and meshes); overlaps with them are checked")


def _length(metres: float) -> str:
    """A length in words: mm below a metre, m above."""
    return f"{metres * 1000:.3g} mm" if abs(metres) < 1 else f"{metres:.3g} m"


def _point(x) -> str:
    """A position in words, with its unit."""
    return "an unknown place" if x is None else "(" + ", ".join(f"{q:.4g}" for q in x) + ") m"


__all__ = ["AUDIT_CHECKS", "AuditCheck", "AuditReport", "Auditor", "Finding", "FINDING_KINDS", "deepest_overlap", "explain"]
