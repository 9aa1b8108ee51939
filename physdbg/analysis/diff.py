"""``physdbg diff A B``: where two recordings part ways, and why, in plain words.

Steps: (1) settings, scene and engine differences, each named with both values and
whether it can matter; (2) the first differing frame (hashes when the runs took the same
steps, states aligned by simulated time otherwise: see :mod:`.align`); (3) in that step,
the first diverging event (contact k: which pair or wall, when, in each run), which
particles and fields differ and by how much; (4) how the gap grows afterwards; (5) the
causes, each with its evidence.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from ..engine.space_order import chosen_order
from ..events import PARTNER_IS_SPHERE, contact_words
from ..record.format import TOPIC_CONTACTS as CONTACTS_TOPIC
from . import align
from .quiet import quiet_numerics
from .diff_causes import Cause, Divergence, StepCase, _count, _key, _show, settings_at, step_causes

DEFAULT_TOLERANCE = 1e-9  # atol (m, m/s) and rtol when a setting that matters differs
GROWTH_DENSE_STEPS = 64  # every frame this many steps after the divergence, then key frames
GROWTH_MAX_SAMPLES = 200

# settings that cannot change a run, and why
CANNOT_MATTER = {
    "broad_phase": "every broad phase finds the same candidate pairs, so runs are identical by design",
    "name": "a name", "description": "a description",
    "mesh_search": ("a walk per sphere and the simultaneous descent find the same triangles in the same order, so "
                    "runs are identical by design"),
}
# fields of each [[meshes]] table that cannot change a run
CANNOT_MATTER_MESH = {
    "bounding_volume": ("every volume's walk finds every triangle a path box meets, and a swept test decides the "
                        "rest, so runs are identical by design"),
}
BUDGET_SETTINGS = ("max_contacts_per_step", "max_pairs_per_step", "max_swept_tests_per_step",
                   "max_resting_work_per_step", "max_memory", "max_particle_steps")


@dataclass
class SettingDifference:
    """One setting or scene field that differs: name (dotted for scene fields), a, b
    (the values), matters (False when it cannot change the run), note (why not)."""

    name: str
    a: object
    b: object
    matters: bool = True
    note: str = ""


# causes that make runs different whatever their states do
DIFFERENT_ALONE = ("structure", "records")


@dataclass
class DiffReport:
    """What ``diff`` found. exit_code: 0 equivalent within tolerance, 1 different."""

    a: str
    b: str
    scene_a: str
    scene_b: str
    steps_a: int
    steps_b: int
    aligned_by: str
    alignment_note: str
    atol: float
    rtol: float
    compared: int
    settings: list[SettingDifference]
    divergence: Divergence | None
    growth: align.Growth | None
    causes: list[Cause]
    headline: str

    same_length: bool = True
    # what was checked of each file's integrity: {"verified": bool, "a": frames checked,
    # "frames_a": frames held, "b", "frames_b"} (docs/recording.md, "Integrity")
    integrity: dict = field(default_factory=dict)
    # each cause's advice tried on a fork (fork.try_causes, physdbg diff --try): {run, and
    # the fields of fork.try_change}
    tried: list = field(default_factory=list)
    # where one run is a fork of the other: {fork: "A" or "B", parent, at: K, dt} (fork_of)
    fork: dict = field(default_factory=dict)
    # the cause the headline says whole (its index in causes), so the report says it once;
    # not a field of the JSON, whose headline and causes both hold it
    headline_cause: int | None = None

    @property
    def equivalent(self) -> bool:
        return self.divergence is None and self.same_length and not any(c.kind in DIFFERENT_ALONE
                                                                         for c in self.causes)

    @property
    def exit_code(self) -> int:
        return 0 if self.equivalent else 1

    def as_dict(self) -> dict:
        out = asdict(self)
        del out["headline_cause"]
        out["equivalent"] = self.equivalent
        out["exit_code"] = self.exit_code
        if self.growth is not None:
            out["growth"] = self.growth.as_dict()
        return out


# ----------------------------------------------------------------------------- settings
# engine settings added after recordings were made, and what a recording made before
# each one existed used
SETTINGS_ADDED = {"rapid_contact_rule": "hold", "sleep_speed": 0.0, "sleep_time": 0.5, "space_order": "given",
                  "mesh_search": "walk", "event_loop": "step"}


def _flatten(value, prefix: str = "") -> dict:
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            out.update(_flatten(item, f"{prefix}.{key}" if prefix else str(key)))
        return out
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        out = {}
        for i, item in enumerate(value):
            out.update(_flatten(item, f"{prefix}.{i}"))
        return out
    return {prefix: value}


def compare_settings(meta_a: dict, meta_b: dict, warned_a: set[str], warned_b: set[str]) -> list[SettingDifference]:
    """Scene fields (after overrides), engine settings as used, and versions that differ.

    warned_a / warned_b: the budget names each run hit (a budget that neither hit
    cannot have mattered)."""
    table_a = _flatten(meta_a["scene"]["table"])
    table_b = _flatten(meta_b["scene"]["table"])
    used_a = {**table_a, **SETTINGS_ADDED, **meta_a.get("settings", {}), "dt": meta_a.get("dt")}
    used_b = {**table_b, **SETTINGS_ADDED, **meta_b.get("settings", {}), "dt": meta_b.get("dt")}
    out = []
    for name in sorted(set(used_a) | set(used_b), key=lambda n: (n.count("."), n)):
        a, b = used_a.get(name), used_b.get(name)
        if _same(a, b) or (name == "space_order" and _numbering(meta_a, a) == _numbering(meta_b, b)):
            continue
        if name in table_a or name in table_b:
            # a field given in one file and defaulted in the other: compare what was used
            base = name.split(".")[0]
            if base in meta_a.get("settings", {}) and name == base and _same(meta_a["settings"].get(base),
                                                                               meta_b["settings"].get(base)):
                continue
        matters, note = True, ""
        if name in CANNOT_MATTER:
            matters, note = False, CANNOT_MATTER[name]
        elif name.startswith("meshes.") and name.rsplit(".", 1)[-1] in CANNOT_MATTER_MESH:
            matters, note = False, CANNOT_MATTER_MESH[name.rsplit(".", 1)[-1]]
        elif name in BUDGET_SETTINGS and name not in warned_a | warned_b:
            matters, note = False, "a work limit that neither run reached"
        elif name == "space_order":
            note = ("the engine's own numbering of the spheres (space_order.py): only work that is otherwise a "
                    "tie depends on it (exactly simultaneous contacts, the order a held cluster is solved in), so "
                    "the runs can differ in the last bits")
        elif name == "samples" and "sampled" not in (used_a.get("detection"), used_b.get("detection")):
            matters, note = False, "used only by detection = sampled"
        out.append(SettingDifference(name, a, b, matters, note))
    for name in ("physdbg_version", "numpy_version"):
        if meta_a.get(name) != meta_b.get(name):
            out.append(SettingDifference(name, meta_a.get(name), meta_b.get(name), True,
                                         "recorded by different builds: results may differ in the last bits"))
    return out


def _numbering(meta: dict, space_order) -> str | None:
    """The numbering a recorded run's world kept ("given" or "morton"; space_order.py)."""
    settings = meta.get("settings", {})
    try:
        return chosen_order(str(space_order), int(meta.get("particles", 0)), settings.get("ordering", "time"))
    except ValueError:
        return None


def _same(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return float(a) == float(b) or (a != a and b != b)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


# ----------------------------------------------------------------------------- diff
def diff(a, b, atol: float | None = None, rtol: float | None = None,
         on_status: Callable[[str], None] | None = None, verify: bool = True) -> DiffReport:
    """Compare two recordings (paths or open Recordings); see the module doc.

    atol, rtol: a particle differs when |Δx| > atol + rtol·|x| (or the same for v);
    default exact (0, 0) when no setting that matters differs, else 1e-9 each.
    verify: check every state read against its stored hash and the frame index, reading
    both runs from frame 0 up to the divergence (RecordingIntegrityError on a mismatch)."""
    from ..record.reader import opened

    with opened(a, b, verify=verify) as (ra, rb), quiet_numerics():
        report = _Differ(ra, rb, atol, rtol).run()
        foreign = [label for label, rec in (("A", ra), ("B", rb)) if rec.meta.get("foreign")]
        if len(foreign) == 1 and not report.equivalent:
            _explain_foreign(report, ra, rb, foreign[0], atol, rtol)
        return report


def _explain_foreign(report: DiffReport, ra, rb, label: str, atol, rtol) -> None:
    """One run is another engine's: say why it departs as check-run does (analysis.departure),
    step by step from its own states, instead of comparing contact records it does not have."""
    from .departure import CheckRunError, compare

    foreign, reference = (ra, rb) if label == "A" else (rb, ra)
    other = "B" if label == "A" else "A"
    try:
        found = compare(foreign, reference, atol or None, rtol or None,
                        subject=f"run {label} (another engine's) departs from run {other}")
    except CheckRunError as err:
        report.causes.append(Cause("foreign", f"run {label} is another engine's; it could not be judged step by "
                                              f"step ({err})"))
        return
    causes = [c for c in report.causes if c.kind in ("settings", "engine-version", "length")]
    for d in found.departures:
        causes.append(Cause(d.kind, f"in run {label} (another engine's), {d.text}", {"departure": asdict(d)},
                            step=d.step, bodies=d.bodies, advice=d.advice))
    if found.integrator is not None:
        causes.append(Cause("integrator", f"run {label}: {found.integrator['sentence']}", found.integrator))
    report.causes, report.headline_cause = causes, None
    report.headline = found.headline


def run_meta(meta: dict) -> dict:
    """A recording's meta with the settings it ran under at its end (settings_at): a fork's
    steps before its own are its parent's, bit for bit, so where two runs part the fork's
    own settings hold."""
    return {**meta, "settings": settings_at(meta)} if meta.get("fork") else meta


def fork_of(ra, rb) -> dict:
    """{"fork": "B", "parent": "A", "at": K, "dt": its dt from K or None} where one run
    forks the other (its header names the other's run id), else {}."""
    for mine, other, label, of in ((rb, ra, "B", "A"), (ra, rb, "A", "B")):
        fork = mine.meta.get("fork")
        if fork and fork.get("parent_run_id") and fork["parent_run_id"] == other.meta.get("run_id"):
            return {"fork": label, "parent": of, "at": int(fork["at"]), "dt": fork.get("dt")}
    return {}


def fork_words(ra, rb) -> str:
    """"B is a fork of A at step 20: " (and its dt from there, where it changed) where one
    run forks the other, else "" (fork_of)."""
    fork = fork_of(ra, rb)
    if not fork:
        return ""
    dt = f" (steps of {fork['dt']:.6g} s from there)" if fork["dt"] else ""
    return f"{fork['fork']} is a fork of {fork['parent']} at step {fork['at']}{dt}: "


class _Differ:
    def __init__(self, ra, rb, atol, rtol):
        self.ra, self.rb = ra, rb
        self.ta, self.tb = ra.frame_table(), rb.frame_table()
        self.warn_a, self.warn_b = _warnings(ra), _warnings(rb)
        budgets_a = {w["code"] for ws in self.warn_a.values() for w in ws}
        budgets_b = {w["code"] for ws in self.warn_b.values() for w in ws}
        self.settings = compare_settings(run_meta(ra.meta), run_meta(rb.meta), budgets_a, budgets_b)
        matters = any(s.matters for s in self.settings)
        default = DEFAULT_TOLERANCE if matters else 0.0
        self.atol = default if atol is None else float(atol)
        self.rtol = default if rtol is None else float(rtol)
        self.by_step = align.same_steps(self.ta.dt, self.tb.dt)
        self.names_a = ra.header.walls.partner_names()
        # positions of a periodic box differ through the minimum image (None: no box)
        self.period = ra.header.walls.period if ra.header.walls.periodic else None
        movable = ra.header.inverse_mass > 0
        self.radius = float(ra.header.radius[movable].min()) if movable.any() else float(ra.header.radius.min())
        self._states: dict[tuple[bool, int], object] = {}  # frames the causes read, decoded once (_state)

    def _state(self, rec, k: int):
        """Frame k of run A or B (rec), decoded once: the causes read the frames around the
        divergence several times, and each read decodes from the key frame before it."""
        key = (rec is self.rb, k)
        if key not in self._states:
            self._states[key] = rec.state(k)
        return self._states[key]

    # ------------------------------------------------------------------ driver
    def run(self) -> DiffReport:
        ra, rb = self.ra, self.rb
        structure = self._structure()
        if ra.header.count != rb.header.count:
            return self._report(None, None, structure + self._setting_causes(), 0)
        if self.by_step:
            found, compared = self._first_by_step()
        else:
            found, compared = self._first_by_time()
        if found is None:
            causes = structure + self._setting_causes()
            if not self._same_length():
                shorter = min(ra.steps, rb.steps)
                agree = (f"the runs agree for the {shorter} steps both have" if self.by_step else
                         f"the runs agree up to t = {min(self.ta.time[-1], self.tb.time[-1]):.6g} s")
                longer = "A" if self.ta.time[-1] > self.tb.time[-1] else "B"
                more = abs(ra.steps - rb.steps)
                causes.append(Cause("length", f"{agree}; run {longer} goes on for {_count(more, 'more step')}"
                                    + ("" if self.by_step else
                                       f" (to t = {max(self.ta.time[-1], self.tb.time[-1]):.6g} s)"),
                                    {"steps_a": ra.steps, "steps_b": rb.steps}))
            elif np.array_equal(self.ta.hashes, self.tb.hashes):
                records = self._records()
                if records is not None:
                    causes.append(records)
            return self._report(None, None, causes, compared)
        fa, fb, xa, va, xb, vb, prev_a, prev_b = found
        state = align.state_difference(xa, va, xb, vb, self.atol, self.rtol, self.period)
        event, contacts_a, contacts_b = self._first_event(fa, fb)
        divergence = Divergence(fa, fb, float(self.ta.time[fa]), state, event)
        growth = self._growth(fa, fb)
        causes = structure + step_causes(StepCase(self, divergence, prev_a, prev_b, contacts_a, contacts_b, growth),
                                           self._setting_causes())
        return self._report(divergence, growth, causes, compared)

    def _structure(self) -> list[Cause]:
        """The runs are not of the same bodies: another count, scene, radius, kind of body
        (movable or immovable) or set of walls. Always a difference (exit 1), whatever the
        states do: equal states of different bodies are not the same run."""
        ha, hb = self.ra.header, self.rb.header
        found = []
        if ha.name != hb.name:
            found.append(f"they are runs of different scenes ('{ha.name}' in A, '{hb.name}' in B)")
        if ha.count != hb.count:
            found.append(f"they have different numbers of spheres ({ha.count} in A, {hb.count} in B), so their "
                         f"states cannot be compared sphere by sphere")
        else:
            radius = np.flatnonzero(ha.radius != hb.radius)
            if len(radius):
                i = int(radius[0])
                found.append(f"{len(radius)} sphere{'s have' if len(radius) != 1 else ' has'} another radius "
                             f"(sphere {i}: {ha.radius[i]:.6g} m in A, {hb.radius[i]:.6g} m in B)")
            kind = np.flatnonzero((ha.inverse_mass > 0) != (hb.inverse_mass > 0))
            if len(kind):
                i = int(kind[0])
                found.append(f"sphere {i} is {'movable' if ha.inverse_mass[i] > 0 else 'immovable'} in A and "
                             f"{'movable' if hb.inverse_mass[i] > 0 else 'immovable'} in B"
                             + (f" ({len(kind)} spheres in all)" if len(kind) > 1 else ""))
        wa, wb = ha.walls, hb.walls
        if len(wa.names) != len(wb.names) or list(wa.two_sided) != list(wb.two_sided) \
                or not np.array_equal(wa.period, wb.period):
            found.append(f"their walls differ ({_walls_words(wa)} in A, {_walls_words(wb)} in B)")
        if not found:
            return []
        return [Cause("structure", "the runs are not of the same bodies: " + "; ".join(found),
                      {"differences": found})]  # the headline lists the differences (_report)

    def _records(self) -> Cause | None:
        """Runs whose every state is bit-identical: their recorded contacts must be the
        same too, message for message (byte for byte: the same rows encode the same), or,
        where the bytes differ, row for row once contacts at one instant are put in one
        order (another numbering of the spheres, ``space_order``, resolves simultaneous
        contacts in another order to the same states). One that differs is an edited or
        damaged file, or an engine that reports other contacts for the same motion; either
        way not the same record. None when they agree, or when a run records no contacts."""
        ra, rb = self.ra, self.rb
        last = min(ra.frames, rb.frames) - 1
        if last < 1 or not (ra.records_contacts and rb.records_contacts):
            return None
        for (fa, da), (fb, db) in zip(ra.raw_messages(CONTACTS_TOPIC, 1, last), rb.raw_messages(CONTACTS_TOPIC, 1, last),
                                      strict=False):
            if fa == fb and da == db:
                continue
            k = min(fa, fb)
            ca, cb = ra.contacts(k), rb.contacts(k)
            if fa == fb and _same_rows_at_each_instant(ca, cb):
                continue
            return Cause("records", f"every state is bit-identical, but the contacts recorded for step {k} differ: "
                                    f"{_contacts_differ(ca, cb, self.names_a)}", {"step": k}, step=k)
        return None

    def _report(self, divergence, growth, causes, compared) -> DiffReport:
        ra, rb = self.ra, self.rb
        note = ("frame k of A against frame k of B (the same steps); stored hashes compared first"
                if self.by_step else
                "by simulated time: each frame of the run with longer steps against the other run at that time "
                "(its own frame when one falls there, else Hermite interpolation between its two frames)")
        fork = fork_of(ra, rb)
        if fork:
            # a fork's frames before K are its parent's, made by the same steps: compared
            # all the same (each state read and checked against its hash), and said so
            before = fork["at"] - 1
            same = divergence is None or divergence.step > before
            shared = "its parent's, equal as they should be" if same else "meant to be its parent's, and are not"
            note = (f"{fork['fork']} is a fork of {fork['parent']} at step {fork['at']}: frames 0..{before} are "
                    f"{shared}; from step {fork['at']} on, {note}")
        structure = next((c for c in causes if c.kind == "structure"), None)
        records = next((c for c in causes if c.kind == "records"), None)
        said = None  # the cause the headline says whole
        if structure is not None:
            headline = "different structure: " + "; ".join(structure.evidence["differences"])
            if divergence is not None:
                headline += f"; their states part in step {divergence.step}"
        elif records is not None:
            headline, said = "different records: " + records.text, records
        elif divergence is None:
            if not self._same_length():
                headline = (f"different lengths: they agree for the {min(ra.steps, rb.steps)} steps both have, then "
                            f"one run stops" if self.by_step else
                            f"different lengths: they agree up to t = {min(self.ta.time[-1], self.tb.time[-1]):.6g} s, "
                            f"then one run stops")
            else:
                exact = self.atol == 0 and self.rtol == 0
                headline = ("equivalent: every state is bit-identical" if exact and self.by_step else
                            f"equivalent within atol={self.atol:g}, rtol={self.rtol:g}")
        if divergence is not None and structure is None:
            headline = ("the runs differ from the start" if divergence.step == 0 else
                        f"the runs part in step {divergence.step}") + (
                f" (step {divergence.step_b} of B)" if divergence.step_b != divergence.step else "") + \
                (": " + _main(causes).text if causes else "")
            said = _main(causes) if causes else None
        return DiffReport(str(ra.path), str(rb.path), ra.header.name, rb.header.name, ra.steps, rb.steps,
                          "step" if self.by_step else "time", note, self.atol, self.rtol, compared,
                          self.settings, divergence, growth, causes, headline, self._same_length(),
                          {"verified": ra.verify and rb.verify, "a": ra.checked_frames, "frames_a": ra.frames,
                           "b": rb.checked_frames, "frames_b": rb.frames},
                          fork=fork, headline_cause=next((i for i, c in enumerate(causes) if c is said), None))

    def _same_length(self) -> bool:
        if self.by_step:
            return self.ra.steps == self.rb.steps
        end_a, end_b = float(self.ta.time[-1]), float(self.tb.time[-1])
        return abs(end_a - end_b) <= 1e-9 * max(float(self.ta.dt[-1]), float(self.tb.dt[-1]), 1e-300)

    # ------------------------------------------------------------------ finding the step
    def _gap(self, xa: np.ndarray, xb: np.ndarray) -> float:
        """The largest distance (m) between a sphere's positions in the two runs (infinite
        when a position is NaN or infinite in either)."""
        gaps = np.linalg.norm(align.position_gap(xa, xb, self.period), axis=1)
        if not len(gaps):
            return 0.0
        return float(gaps.max()) if np.isfinite(gaps).all() else math.inf

    def _first_by_step(self):
        ra, rb = self.ra, self.rb
        start = align.first_differing_frame(self.ta.hashes, self.tb.hashes)
        common = min(ra.frames, rb.frames)
        if ra.verify or rb.verify:
            # The frames before `start` are equal by the index's hashes, but the index is only
            # trusted once each state has been read and found to give it (the reader checks
            # every state it decodes): so both runs stream from frame 0.
            pairs = self._paired_states(common)
        elif start is None:
            return None, common
        else:
            first = max(start - 1, 0)
            pairs = zip(ra.states(first, common), rb.states(first, common), strict=True)
        previous = None
        for sa, sb in pairs:
            if start is None or sa.frame < start:
                previous = (sa, sb)
                continue
            d = align.state_difference(sa.positions, sa.velocities, sb.positions, sb.velocities, self.atol,
                                       self.rtol, self.period)
            if d.count:
                prev_a, prev_b = previous if previous else (None, None)
                return (sa.frame, sb.frame, sa.positions, sa.velocities, sb.positions, sb.velocities,
                        prev_a, prev_b), sa.frame + 1
            previous = (sa, sb)
        return None, common

    def _paired_states(self, stop: int):
        """(state of A, state of B) of frames 0..stop-1, each checked; where B's stored message
        is A's byte for byte (and so are the ones it is coded against) B's state is A's,
        decoded and hashed once: two equivalent runs cost one decoding, not two."""
        from ..record.reader import StateStream

        stream_a, stream_b = StateStream(self.ra), StateStream(self.rb)
        for (frame_a, data_a), (frame_b, data_b) in zip(self.ra.state_messages(0, stop),
                                                         self.rb.state_messages(0, stop), strict=True):
            sa = stream_a.decode(frame_a, data_a)
            if data_a == data_b and stream_b.can_share(frame_b, stream_a):
                yield sa, stream_b.share(frame_b, sa, stream_a)
            else:
                yield sa, stream_b.decode(frame_b, data_b)

    def _first_by_time(self):
        """Align by simulated time (the coarser run's frames against the finer run)."""
        ra, rb = self.ra, self.rb
        swap = np.median(self.tb.dt[1:]) > np.median(self.ta.dt[1:]) if rb.frames > 1 and ra.frames > 1 else False
        coarse, fine = (rb, ra) if swap else (ra, rb)
        fine_states = fine.states()
        before = next(fine_states)
        after = next(fine_states, None)
        compared = 0
        for sc in coarse.states():
            t = sc.time
            while after is not None and after.time < t - 1e-9 * max(after.dt, 1e-300):
                before, after = after, next(fine_states, None)
            if after is None and before.time < t - 1e-9 * max(before.dt, 1e-300):
                break  # past the end of the finer run
            if after is not None and abs(after.time - t) <= 1e-9 * max(after.dt, 1e-300):
                xf, vf, match = after.positions, after.velocities, after
            elif abs(before.time - t) <= 1e-9 * max(before.dt, sc.dt, 1e-300):
                xf, vf, match = before.positions, before.velocities, before
            else:
                xf, vf = align.hermite(t, before, after, self.period)
                match = after
            compared += 1
            xa, va, xb, vb = (xf, vf, sc.positions, sc.velocities) if swap else (sc.positions, sc.velocities, xf, vf)
            d = align.state_difference(xa, va, xb, vb, self.atol, self.rtol, self.period)
            if d.count:
                fa, fb = (match.frame, sc.frame) if swap else (sc.frame, match.frame)
                return (fa, fb, xa, va, xb, vb, None, None), compared
        return None, compared

    # ------------------------------------------------------------------ the step itself
    def _step_contacts(self, rec, frame: int, since_time: float | None = None):
        """Contacts with absolute times: of step ``frame``, or of every step after
        ``since_time`` up to it (when aligned by time). None when not recorded."""
        if rec.detail == "state" or frame < 1:
            return None
        table = rec.frame_table()
        first = frame
        if since_time is not None:
            while first > 1 and table.time[first - 1] > since_time + 1e-12:
                first -= 1
        rows = []
        for k in range(first, frame + 1):
            c = rec.contacts(k)
            base = float(table.time[k - 1])
            resting = c.resting
            for i in range(len(c)):
                rows.append({"step": k, "index": i, "time": base + float(c.time_in_step[i]),
                             "who": contact_words(int(c.kind[i]), int(c.a[i]), int(c.other[i]), self.names_a),
                             "time_in_step": float(c.time_in_step[i]), "dt": float(table.dt[k]),
                             "kind": int(c.kind[i]), "a": int(c.a[i]), "other": int(c.other[i]),
                             "resting": bool(resting[i]), "impulse": float(c.impulse[i]),
                             "restitution": float(c.restitution[i]),
                             "velocity_a_after": [float(q) for q in c.velocity_a_after[i]]})
        return rows

    def _first_event(self, fa: int, fb: int):
        since = None
        if not self.by_step:
            since = min(float(self.ta.time[fa - 1]) if fa > 0 else 0.0, float(self.tb.time[fb - 1]) if fb > 0 else 0.0)
        ca = self._step_contacts(self.ra, fa, since)
        cb = self._step_contacts(self.rb, fb, since)
        if ca is None or cb is None:
            return None, ca, cb
        tol_t = 1e-9 * max(float(self.ta.dt[fa]) if fa else 0.0, 1e-300) if (self.atol or self.rtol) else 0.0
        for i in range(max(len(ca), len(cb))):
            x = ca[i] if i < len(ca) else None
            y = cb[i] if i < len(cb) else None
            if x is None or y is None or _key(x) != _key(y) or abs(x["time"] - y["time"]) > tol_t \
                    or not _close(x["impulse"], y["impulse"], self.atol, self.rtol) \
                    or x["resting"] != y["resting"]:
                return {"index": i, "a": x, "b": y}, ca, cb
        return None, ca, cb

    # ------------------------------------------------------------------ growth
    def _growth(self, fa: int, fb: int) -> align.Growth | None:
        if not self.by_step:
            return self._growth_by_time(fa)
        ra, rb = self.ra, self.rb
        common = min(ra.frames, rb.frames)
        frames = list(range(fa, min(fa + GROWTH_DENSE_STEPS, common)))
        key = ((fa + GROWTH_DENSE_STEPS) // 64 + 1) * 64
        later = list(range(key, common, 64))
        if len(later) > GROWTH_MAX_SAMPLES:
            later = [later[int(i)] for i in np.linspace(0, len(later) - 1, GROWTH_MAX_SAMPLES)]
        gaps = {}
        for sa, sb in zip(ra.states(frames[0], frames[-1] + 1), rb.states(frames[0], frames[-1] + 1), strict=True):
            gaps[sa.frame] = self._gap(sa.positions, sb.positions)
        for k in later:
            sa, sb = ra.state(k), rb.state(k)
            gaps[k] = self._gap(sa.positions, sb.positions)
        self._refine(gaps, 1e-3)
        self._refine(gaps, self.radius)
        steps = np.array(sorted(gaps))
        values = np.array([gaps[k] for k in steps])
        growth = align.fit_growth(steps, self.ta.time[steps], values, self.radius, fa, float(self.ta.time[fa]),
                                  float(self.ta.dt[fa]))
        growth.judge_chaos(self._spheres_collide(fa, _last_below(steps, values, self.radius)))
        return growth

    def _refine(self, gaps: dict, level: float) -> None:
        """Fill in every frame between the last sample below ``level`` and the first above."""
        steps = sorted(gaps)
        above = [k for k in steps if gaps[k] >= level]
        if not above:
            return
        first = above[0]
        below = [k for k in steps if k < first]
        if not below or first - below[-1] <= 1:
            return
        for sa, sb in zip(self.ra.states(below[-1] + 1, first), self.rb.states(below[-1] + 1, first), strict=True):
            gaps[sa.frame] = self._gap(sa.positions, sb.positions)

    def _growth_by_time(self, fa: int) -> align.Growth | None:
        """Gaps at the frames of A (aligned by time, as for the divergence)."""
        ra, rb = self.ra, self.rb
        fine = rb.states()
        before = next(fine)
        after = next(fine, None)
        steps, times, gaps = [], [], []
        for sa in ra.states(fa):
            t = sa.time
            while after is not None and after.time < t - 1e-9 * max(after.dt, 1e-300):
                before, after = after, next(fine, None)
            if after is None:
                break
            if abs(after.time - t) <= 1e-9 * max(after.dt, 1e-300):
                xb = after.positions
            else:
                xb, _ = align.hermite(t, before, after, self.period)
            steps.append(sa.frame)
            times.append(t)
            gaps.append(self._gap(sa.positions, xb))
        if not steps:
            return None
        growth = align.fit_growth(np.array(steps), np.array(times), np.array(gaps), self.radius, fa,
                                  float(self.ta.time[fa]), float(self.ta.dt[fa]))
        growth.judge_chaos(self._spheres_collide(fa, _last_below(np.array(steps), np.array(gaps), self.radius)))
        return growth

    def _spheres_collide(self, first: int, last: int) -> bool:
        """Whether two spheres collide in either run in frames first..last (the stats'
        ``collisions``, read until the first one)."""
        for rec in (self.ra, self.rb):
            if rec.header.count < 2 or not np.any(rec.header.inverse_mass > 0):
                continue
            for row in rec.iter_stats(first, last + 1):
                if int(row["collisions"][0]) > 0:
                    return True
        return False

    # ------------------------------------------------------------------ causes
    def _setting_causes(self) -> list[Cause]:
        out = []
        matters = [s for s in self.settings if s.matters and s.name not in ("physdbg_version", "numpy_version")]
        if matters:
            listed = "; ".join(f"{s.name}: {_show(s.a)} in A, {_show(s.b)} in B" for s in matters[:6])
            more = f" (and {len(matters) - 6} more)" if len(matters) > 6 else ""
            out.append(Cause("settings", f"{fork_words(self.ra, self.rb)}different settings: {listed}{more}",
                             {"settings": [s.name for s in matters]}))
        elif fork_words(self.ra, self.rb):  # a fork that changed no setting: its dt, or nothing
            out.append(Cause("settings", fork_words(self.ra, self.rb) + "no setting differs", {"settings": []}))
        versions = [s for s in self.settings if s.name in ("physdbg_version", "numpy_version")]
        if versions:
            out.append(Cause("engine-version", "recorded by different engine builds: " + "; ".join(
                f"{s.name} {s.a} in A, {s.b} in B" for s in versions), {"versions": [asdict(s) for s in versions]}))
        return out


def _last_below(steps: np.ndarray, gaps: np.ndarray, level: float) -> int:
    """The last sampled frame before the gap first reaches ``level`` (or the last one)."""
    above = np.flatnonzero(~(gaps < level))
    return int(steps[above[0]]) if len(above) else int(steps[-1]) if len(steps) else 0


def _walls_words(walls) -> str:
    n = len(walls.names)
    two = int(np.count_nonzero(walls.two_sided))
    words = f"{n} wall{'s' if n != 1 else ''}" + (f", {two} two-sided" if two else "")
    return words + (", a periodic box" if walls.periodic else "")


def _main(causes: list[Cause]) -> Cause:
    """The most telling cause: the mechanism, rather than the list of settings."""
    specific = [c for c in causes if c.kind not in ("settings", "engine-version")]
    return specific[0] if specific else causes[0]


POINT_ULPS = 8  # a pair's contact point, computed from the other sphere's side, may differ by rounding


def _instant_order(contacts) -> np.ndarray:
    """Rows of one step's contacts (events.Contacts) in one form and one order: a sphere
    pair written with the lower sphere number as ``a`` (the normal and the two spheres'
    velocities turned to match), sorted by time in the step, kind and partners. The same
    contacts come out the same whatever order, and whichever way round, the engine met
    them in."""
    rows = contacts.rows.copy()
    pair = np.array([PARTNER_IS_SPHERE[k] for k in rows["kind"]], dtype=bool)
    swap = pair & (rows["a"] > rows["other"])
    if swap.any():
        turned = rows[swap]
        turned["a"], turned["other"] = rows["other"][swap], rows["a"][swap]
        turned["normal"] = -rows["normal"][swap]
        for when in ("before", "after"):
            turned[f"velocity_a_{when}"] = rows[f"velocity_b_{when}"][swap]
            turned[f"velocity_b_{when}"] = rows[f"velocity_a_{when}"][swap]
        rows[swap] = turned
    return rows[np.lexsort((rows["other"], rows["a"], rows["kind"], rows["time_in_step"]))]


def _same_rows_at_each_instant(a, b) -> bool:
    """Do two records of one step's contacts hold the same contacts once put in one form
    and order (``_instant_order``): every field bit for bit, but the contact point, which
    is computed from one sphere's side and may differ by ``POINT_ULPS`` units of rounding?"""
    if len(a) != len(b):
        return False
    x, y = _instant_order(a), _instant_order(b)
    if any(x[name].tobytes() != y[name].tobytes() for name in x.dtype.names if name != "point"):
        return False
    px, py = x["point"], y["point"]
    return bool(np.all(np.abs(px - py) <= POINT_ULPS * np.spacing(np.maximum(np.abs(px), np.abs(py)))))


def _contacts_differ(a, b, names) -> str:
    """In words, where two records of one step's contacts (events.Contacts) first differ."""
    if len(a) != len(b):
        return f"A holds {_count(len(a), 'contact')}, B {len(b)}"
    for i in range(len(a)):
        x, y = a.rows[i], b.rows[i]
        if (x["kind"], x["a"], x["other"]) != (y["kind"], y["a"], y["other"]):
            return (f"contact {i + 1} is {contact_words(int(x['kind']), int(x['a']), int(x['other']), names)} "
                    f"in A and {contact_words(int(y['kind']), int(y['a']), int(y['other']), names)} in B")
        fields = [name for name in x.dtype.names if x[name].tobytes() != y[name].tobytes()]
        if fields:
            return f"contact {i + 1} ({contact_words(int(x['kind']), int(x['a']), int(x['other']), names)}) " \
                   f"has another {', '.join(fields)}"
    return "their messages differ, not their rows"


def _close(a: float, b: float, atol: float, rtol: float) -> bool:
    if a == b or (math.isinf(a) and a == b):
        return True
    return abs(a - b) <= atol + rtol * abs(b)


def _warnings(rec) -> dict[int, list[dict]]:
    """Every warning of a recording, by step (frame), from its warnings channel."""
    import json

    from ..record import format as fmt
    from ..record.header import current_name

    out: dict[int, list[dict]] = {}
    for _, frame, data in rec._messages([fmt.TOPIC_WARNINGS], 1, rec.frames - 1):
        warning = json.loads(data)
        warning["code"] = current_name(warning["code"])
        out.setdefault(frame, []).append(warning)
    return out


__all__ = ["Cause", "DiffReport", "Divergence", "SettingDifference", "compare_settings", "diff"]
