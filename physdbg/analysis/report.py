"""What the commands print: diff, audit and check-run reports as text (the terminal),
Markdown (a CI step summary) and JSON, and the run summary, ``physdbg check``'s advice
and ``physdbg info``'s description as text. The CLI only chooses which.

The JSON form is ``report.as_dict()``; its fields are the dataclass fields documented in
docs/diff.md. Text and Markdown say the same things in the same order.
"""

from __future__ import annotations

import json
import math

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:  # for the annotations only: printing a summary loads no analysis
    from .audit import AuditReport
    from .departure import CheckRunReport
    from .diff import DiffReport


def _plain(value):
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)


def _clean(obj):
    """JSON cannot hold NaN or infinity: they become null."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    return obj


def versioned(data: dict) -> dict:
    """A JSON report with the physdbg and recording-format versions that made it first, so
    a script can tell which build's words and fields it reads."""
    from ..record.format import FORMAT_VERSION
    from ..version import __version__

    return {"physdbg_version": __version__, "format_version": FORMAT_VERSION, **data}


def report_json(report: DiffReport | AuditReport | CheckRunReport) -> str:
    """Any report as JSON (a run's summary too, api.RunSummary): its ``as_dict()`` with the
    versions first, NaN and infinity as null."""
    return json.dumps(versioned(_clean(report.as_dict())), indent=2, default=_plain)


_CELL = {ord("|"): "\\|"}  # a cell's own bar is text, not the table's


def markdown_table(columns: list[str], rows: list[list]) -> list[str]:
    """A Markdown table's lines: the header, its rule and one line per row (each cell as
    str, its bars escaped; None a cell with nothing in it). The one table writer of every
    Markdown report and chart page."""
    def line(cells) -> str:
        return "|" + "".join(" |" if cell is None else f" {str(cell).translate(_CELL)} |" for cell in cells)

    return [line(columns), "|" + "---|" * len(columns)] + [line(row) for row in rows]


class Record(Protocol):
    """What every report prints of a diff cause (diff_causes.Cause), an audit finding
    (audit.Finding) or a check-run departure (departure.Departure): code, its kind; step,
    the step (from 1) or None where the summary names it; bodies, the spheres; summary,
    one sentence; detail, the numbers behind it; advice, what to change ("" for none).
    Each class keeps its own JSON fields; these are read-only names over them."""

    code: str
    step: int | None
    bodies: tuple[int, ...]
    summary: str
    detail: dict
    advice: str


def record_lines(record: Record, summary: str | None = None, advice: str | None = None) -> list[str]:
    """A record as the text reports print it: '  - step 3 [code] summary' (no step: a diff's
    cause) and, with advice, '      what to do: advice'. summary, advice: the record's own,
    or what a report says instead (a part said once already is "as above")."""
    summary = record.summary if summary is None else summary
    advice = record.advice if advice is None else advice
    head = f"  - step {record.step} [{record.code}] " if record.step is not None else f"  - [{record.code}] "
    return [head + summary] + ([f"      what to do: {advice}"] if advice else [])


def record_markdown(record: Record, summary: str | None = None) -> str:
    """The same record as a Markdown list item: '- **step 3** *code*: summary — advice'."""
    summary = record.summary if summary is None else summary
    return (f"- **step {record.step}** " if record.step is not None else "- ") + f"*{record.code}*: {summary}" + (
        f" — {record.advice}" if record.advice else "")


def _tolerance(r: DiffReport) -> str:
    return "exact (bit for bit)" if r.atol == 0 and r.rtol == 0 else f"atol {r.atol:g}, rtol {r.rtol:g}"


def _integrity(r: DiffReport) -> str:
    """What was checked of the files' integrity, in words."""
    i = r.integrity
    if not i:
        return "nothing"
    if not i["verified"]:
        return "no state against its stored hash (--no-verify)"
    return (f"{i['a']} of {i['frames_a']} states of A and {i['b']} of {i['frames_b']} of B against their stored "
            f"hashes and the frame index" + ("" if i["a"] == i["frames_a"] and i["b"] == i["frames_b"] else
                                             " (the ones the verdict rests on)"))


def _compared(r: DiffReport) -> str:
    """Which frames the verdict compared: all that both runs hold, or those up to the first
    difference (where the comparison stops: what follows is described, not compared)."""
    held = min(r.steps_a, r.steps_b) + 1  # frame 0 (the start) and one frame a step
    if r.divergence is not None and r.compared < held:
        return (f"{r.compared} of the {held} frames both runs hold, aligned by {r.aligned_by}: frame 0 to the first "
                f"difference (step {r.compared - 1}), where the comparison stops")
    return f"all {r.compared} frames both runs hold, aligned by {r.aligned_by}" if r.compared == held else \
        f"{r.compared} frames aligned by {r.aligned_by}"


def diff_text(r: DiffReport) -> str:
    lines = [f"A  {r.a}  ({r.scene_a}, {r.steps_a} steps)", f"B  {r.b}  ({r.scene_b}, {r.steps_b} steps)",
             f"result   {'EQUIVALENT' if r.equivalent else 'DIFFERENT'}: {r.headline}",
             f"compared {_compared(r)}; tolerance {_tolerance(r)}",
             f"checked  {_integrity(r)}"]
    if r.fork:
        lines.append(f"aligned  {r.alignment_note}")
    if r.settings:
        lines.append("settings that differ:")
        for s in r.settings:
            lines.append(f"  {s.name}: {_show(s.a)} (A)  {_show(s.b)} (B)" + (f"  — cannot matter: {s.note}"
                                                                              if not s.matters else ""))
    d = r.divergence
    if d is not None:
        lines.append(f"first difference: step {d.step}" + (f" of A, step {d.step_b} of B" if d.step_b != d.step else "")
                     + f" (t = {d.time:.6g} s): {d.state.count} sphere{'s differ' if d.state.count != 1 else ' differs'}")
        for p in d.state.particles:
            lines.append(f"  sphere {p['particle']}: |Δx| = {p['position']:.3g} m, |Δv| = {p['velocity']:.3g} m/s")
        if d.first_event is not None:
            lines.append(f"  first differing contact: contact {d.first_event['index'] + 1} of the step: "
                         f"A {_contact(d.first_event['a'])}; B {_contact(d.first_event['b'])}")
    if r.growth is not None and d is not None:
        lines.append("afterwards: " + r.growth.sentence())
    if r.causes:
        lines.append("why:")
        lines.extend(line for c in r.causes for line in record_lines(c, _cause_text(c, r)))
    lines.extend(f"try      in run {t['run']}: {tried_words(t)}" for t in r.tried)
    return "\n".join(lines)


def _cause_text(cause, r: DiffReport) -> str:
    """A cause's sentence, or a pointer to the result line when that already says it whole
    (the main cause's 80 words were printed twice)."""
    said = r.headline_cause is not None and r.causes[r.headline_cause] is cause
    return "the main cause, said on the result line" if said else cause.text


def diff_markdown(r: DiffReport) -> str:
    icon = "✅" if r.equivalent else "❌"
    lines = [f"### {icon} physdbg diff: {'equivalent' if r.equivalent else 'different'}", "",
             f"**{r.headline}**", "",
             *markdown_table([None, "recording", "scene", "steps"],
                             [["A", f"`{r.a}`", r.scene_a, r.steps_a], ["B", f"`{r.b}`", r.scene_b, r.steps_b]]), "",
             f"Compared {_compared(r)}; tolerance {_tolerance(r)}. "
             f"Checked {_integrity(r)}." + (f" Aligned: {r.alignment_note}." if r.fork else ""), ""]
    if r.settings:
        lines += markdown_table(["setting", "A", "B", "note"],
                                [[f"`{s.name}`", _show(s.a), _show(s.b), "" if s.matters else "cannot matter: " + s.note]
                                 for s in r.settings])
        lines.append("")
    d = r.divergence
    if d is not None:
        lines.append(f"**First difference: step {d.step}** (t = {d.time:.6g} s), {d.state.count} sphere(s):")
        lines.append("")
        lines += [f"- sphere {p['particle']}: \\|Δx\\| = {p['position']:.3g} m, \\|Δv\\| = {p['velocity']:.3g} m/s"
                  for p in d.state.particles]
        if d.first_event is not None:
            lines.append(f"- first differing contact: contact {d.first_event['index'] + 1} of the step: A "
                         f"{_contact(d.first_event['a'])}; "
                         f"B {_contact(d.first_event['b'])}")
        if r.growth is not None:
            lines.append(f"- afterwards: {r.growth.sentence()}")
        lines.append("")
    if r.causes:
        lines += ["**Why**", ""] + [record_markdown(c, _cause_text(c, r)) for c in r.causes]
    lines += [f"> tried in run {t['run']}: {tried_words(t)}" for t in r.tried]
    return "\n".join(lines) + "\n"


def _partner_words(partners: dict) -> str:
    """", 2 post partners": the partners of each kind declaring its own fields."""
    return "".join(f", {count} {kind} partner{'s' if count != 1 else ''}" for kind, count in partners.items())


def explain_text(r: AuditReport) -> str:
    lines = [f"{r.source}  ({r.scene}, {r.checked} of {r.steps} steps audited)"]
    if r.clean:
        tunnelling = ("tunnelling through the partners the audit checks" if getattr(r, "unchecked", None)
                      else "tunnelling")
        lines.append(f"result   CLEAN: no {tunnelling}, overlap, out-of-order contact, energy gain, NaN, budget hit "
                     "or collapse found")
    else:
        counts = ", ".join(f"{k} {v}" for k, v in r.counts.items())
        lines.append(f"result   FINDINGS: {counts}")
        from .audit import said_once

        for f, message, advice in said_once(r.findings):
            lines += record_lines(f, message, advice)
        lines.extend("  " + line for line in _more_lines(r.not_listed()))
    lines.extend(f"note     {n}" for n in r.notes)
    lines.extend(f"try      {tried_words(t)}" for t in r.tried)
    return "\n".join(lines)


def fork_line(fork: dict) -> str:
    """Where a fork came from and what it changed (its header entry: fork.fork_recording)."""
    changed = [f"{name}={value}" for name, value in fork["changes"].items()]
    if fork.get("dt"):
        changed.append(f"dt={fork['dt']:.6g} s")
    inherited = [e for e in fork.get("chain", []) if e["at"] != fork["at"]]
    return (f"of {fork['parent']} at step {fork['at']}: "
            + (f"{', '.join(changed)} from step {fork['at']} on" if changed
               else "no change (its parent, bit for bit)")
            + ("; and, as its parent, " + "; ".join(
                f"{', '.join(f'{k}={v}' for k, v in e['changes'].items())} from step {e['at']}" for e in inherited)
               if inherited else ""))


def tried_words(t: dict) -> str:
    """One advice tried on a fork (fork.try_advice), in one line: the change, whether the
    finding is gone, what else changed, what it cost."""
    change = ", ".join(f"{name}={value}" for name, value in t["settings"].items())
    who = f"sphere{'s' if len(t['particles']) > 1 else ''} {', '.join(map(str, t['particles']))}"
    outcome = (f"the {t['kind']} of step {t['step']} ({who}) is gone" if t["gone"] else
               f"the {t['kind']} of step {t['step']} is still there" if t.get("in_run", True) else
               f"the run's own audit names no {t['kind']} of step {t['step']} ({who}): nothing to remove")
    left = (f"{t['left']} {t['kind']} finding{'s' if t['left'] != 1 else ''} in those steps "
            f"({t['left_in_run']} in the run's same steps)")
    return (f"{change} from step {t['step']} for {count_words(t['steps'], 'step')}: {outcome}; {left}; "
            f"what else changed (diff of the run, A, against the fork, B): "
            f"{t['changed']}; {t['ms_before']:.3g} -> {t['ms_after']:.3g} ms a step in the engine"
            + ("" if t["verified"] else "; THE FORK DID NOT VERIFY"))


def explain_markdown(r: AuditReport) -> str:
    icon = "✅" if r.clean else "⚠️"
    lines = [f"### {icon} physdbg explain: {'clean' if r.clean else 'findings'}", "",
             f"`{r.source}` ({r.scene}, {r.checked} of {r.steps} steps audited)", ""]
    if not r.clean:
        lines += markdown_table(["kind", "count"], [[k, v] for k, v in r.counts.items()]) + [""]
        lines += [record_markdown(f) for f in r.findings]
    lines += [f"> {n}" for n in r.notes]
    lines += [f"> tried: {tried_words(t)}" for t in r.tried]
    return "\n".join(lines) + "\n"


def _first(r: CheckRunReport) -> str:
    f = r.first
    off = (f"position off by {f.position:.3g} m, velocity by {f.velocity:.3g} m/s"
           if math.isfinite(f.position) and math.isfinite(f.velocity) else "its position or velocity is NaN or infinite")
    return (f"step {f.step} (t = {f.time:.6g} s), sphere {f.body}: {off}; {f.bodies} of {r.bodies} "
            f"bod{'y' if r.bodies == 1 else 'ies'} beyond the tolerance; cause: {f.cause}")


def _more(more: int) -> str:
    return f" ({more} more like it later)" if more else ""


def check_run_text(r: CheckRunReport) -> str:
    lines = [f"run        {r.run}  ({r.scene}, {r.steps} steps of {r.bodies} bod{'y' if r.bodies == 1 else 'ies'}, "
             f"velocities {r.velocities})",
             f"against    physdbg's exact run with the same steps ({r.reference_contacts} contact"
             f"{'' if r.reference_contacts == 1 else 's'})",
             f"result     {'DEPARTS' if r.first else 'SAME'}: {r.headline}",
             f"tolerance  atol {r.atol:g}, rtol {r.rtol:g} (m, m/s)"]
    if r.first is not None:
        lines.append("first      " + _first(r))
    if r.integrator is not None:
        lines.append("integrator " + r.integrator["sentence"])
    if r.departures:
        lines.append("departures, in step order:")
        for d in r.departures:
            lines += record_lines(d, d.text + _more(d.more))
    lines.extend(f"note       {n}" for n in r.notes)
    return "\n".join(lines)


def check_run_markdown(r: CheckRunReport) -> str:
    icon = "✅" if r.first is None else "❌"
    lines = [f"### {icon} physdbg check-run: {'same as physdbg' if r.first is None else 'departs'}", "",
             f"**{r.headline}**", "",
             f"`{r.run}` ({r.scene}, {r.steps} steps, velocities {r.velocities}) against physdbg's exact run with "
             f"the same steps; tolerance atol {r.atol:g}, rtol {r.rtol:g}.", ""]
    if r.first is not None:
        lines += [f"- **first departure**: {_first(r)}"]
    if r.integrator is not None:
        lines += [f"- **integrator**: {r.integrator['sentence']}"]
    lines.append("")
    if r.departures:
        lines += markdown_table(["step", "kind", "what happened", "what to do"],
                                [[d.step, d.kind, d.text + _more(d.more), d.advice] for d in r.departures])
        lines.append("")
    lines += [f"> {n}" for n in r.notes]
    return "\n".join(lines) + "\n"


# each command's report in each format but JSON (report_json), by (command, format)
RENDERINGS = {("diff", "text"): diff_text, ("diff", "markdown"): diff_markdown,
              ("explain", "text"): explain_text, ("explain", "markdown"): explain_markdown,
              ("check_run", "text"): check_run_text, ("check_run", "markdown"): check_run_markdown}


def _contact(c: dict | None) -> str:
    if c is None:
        return "no contact"
    if c.get("who"):
        who = c["who"]
    else:  # a contact without its words: the partner by its kind's name in the table, and its number
        from ..events import KIND_NAMES, PARTNER_IS_SPHERE

        kind = int(c["kind"])
        who = f"{c['a']}–{c['other']}" if PARTNER_IS_SPHERE[kind] else f"{c['a']}–{KIND_NAMES[kind]} #{c['other']}"
    return f"{who} at {c['time_in_step'] / c['dt']:.3f}·dt" + (" (resting)" if c["resting"] else "")


def _show(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


# ----------------------------------------------------------------------------- runs, scenes, files
def _mesh_words(meshes: dict) -> str:
    """", 2 meshes (left 8, right 8 triangles)" or "" (meshes: name -> triangles)."""
    if not meshes:
        return ""
    return (f", {len(meshes)} mesh{'es' if len(meshes) != 1 else ''} ("
            + ", ".join(f"{name} {size}" for name, size in meshes.items()) + " triangles)")


def _interpreted(s) -> bool:
    """Whether a run summary's engine ran interpreted (tier.py)."""
    return bool(s.kernels["interpreted"])


# the step's phases (events.STEP_PHASES) as the run summary names them
PHASE_WORDS = {"forces": "forces", "broad_phase": "broad phase", "narrow_phase": "narrow phase", "resolve": "resolve",
               "finish": "finish"}


def summary_text(s, observers: str = "the audit") -> str:
    """The human-readable run summary; observers: what watched the run besides the engine
    (its time is in the second speed figure only)."""
    share = sum(s.phase_seconds.values()) or 1.0
    phases = ", ".join(f"{PHASE_WORDS.get(name, name)} {100 * sec / share:.0f}%" for name, sec in s.phase_seconds.items())
    dts = s.dts
    dt_text = f"dt {dts[0]:.6g} s" if dts and min(dts) == max(dts) else (
        f"dt {min(dts):.3g}..{max(dts):.3g} s" if dts else "no steps")
    lines = [
        f"scene       {s.scene}  ({s.source})",
        f"methods     integrator={s.integrator} detection={s.detection} ordering={s.ordering}",
        *auto_lines(s.auto),
        f"broad phase {s.broad_phase}: {s.broad_phase_reason}" + (
            f"; {s.scanned_steps} of {s.steps} steps scanned every path box for a changed path instead of listing "
            f"partners (fewer box tests: docs/broadphase.md, \"Partner lists or a scan\")" if s.scanned_steps else ""),
        *([f"event loop  {calendar_words(s.event_loop)}"] if s.event_loop else []),
        f"bodies      {count_words(s.particles, 'particle')}, {count_words(len(s.walls), 'wall')}"
        + _mesh_words(getattr(s, "meshes", {})) + _partner_words(getattr(s, "partners", {})),
        *(f"meshes      {note}" for note in getattr(s, "mesh_notes", [])),
        *(f"start       {note}" for note in getattr(s, "start_notes", [])),
        *([f"meshes      searched by the simultaneous descent in {s.together_steps} of {s.steps} steps, by a walk "
           f"per sphere in the rest (mesh_search = {s.mesh_search}: docs/meshes.md, \"Walks or the simultaneous "
           f"descent\")"] if getattr(s, "meshes", None) else []),
        f"steps       {s.steps}  ({s.sim_time:.6g} s simulated, {dt_text})",
        f"contacts    {s.contacts}  (at most {s.max_contacts_in_a_step} in a step; {s.swept_tests} swept tests; "
        f"{s.rapid} rapid, {s.released} released; {s.held_at_end} held at the end)",
        *([f"sleep       {s.asleep_at_end} of {s.particles} spheres asleep at the end  ({s.slept} fell asleep, "
           f"{s.woken} woke)"] if s.slept else []),
        # "change", not "drift": restitution, drag and held contacts take energy out and walls
        # and gravity change momentum by design; the audit line judges whether any was wrong
        f"energy      {s.energy_start:.6g} J -> {s.energy_end:.6g} J  (relative change {s.energy_drift:+.3e})"
        + ("; a kinematic mesh's prescribed motion does work on what it strikes, so the audit judges each "
           "contact's energy relative to the moving surface" if getattr(s, "meshes_driven", False) else ""),
        f"momentum    {_vec(s.momentum_start)} -> {_vec(s.momentum_end)} kg·m/s  (|change| {s.momentum_drift:.3e})",
        f"overlap     max {s.max_overlap:.3g} m" + (f"  ({overlap_where_words(s.overlap_where)})"
                                                    if s.overlap_where else ""),
        f"speed       {s.engine_ms_per_step:.3f} ms/step in the engine ({phases}); "
        f"{s.ms_per_step:.3f} ms/step with {observers}"
        + (f"; kernels compiled/loaded in {s.compile_seconds:.2f} s" if not _interpreted(s) else ""),
        *([f"kernels     {s.kernels['why']}"] if _interpreted(s) else []),
        f"state hash  {s.final_hash}",
        "warnings    " + _warning_totals(s.warning_counts),
    ]
    lines += [f"  step {w['step']}: {w['message']}" for w in s.warnings]
    tunnelling = ("tunnelling through the partners the audit checks" if getattr(s, "audit_unchecked", None)
                  else "tunnelling")
    lines.append("audit       " + (f"clean (no {tunnelling}, overlap, out-of-order contact, energy gain or collapse"
                                   + (", and no meshes passing into each other or pinning a sphere)"
                                      if getattr(s, "meshes_move", False)
                                      else ")")
                                   if not s.finding_counts else
                                   ", ".join(f"{n} {kind}" for kind, n in s.finding_counts.items())
                                   + "; the first of each kind:"))
    lines += [f"  {line}" for line in finding_lines(s.findings, s.finding_counts)]
    if getattr(s, "audit_unchecked", None):
        from .audit import unchecked_words

        lines.append(f"  {unchecked_words(s.audit_unchecked)}")
    if s.audit_pairs.get("from_engine"):
        lines.append(f"  {pairs_words(s.audit_pairs)}")
    return "\n".join(lines)


def overlap_where_words(where: dict) -> str:
    """Who overlapped most, and when (RunSummary.overlap_where): "spheres 3 and 4, step 12",
    "sphere 3 and wall 'floor', step 12"."""
    from ..events import parties_words

    return f"{parties_words(where['kind'], where['sphere'], where['partner'], where['partner_name'])}, step {where['step']}"


def calendar_words(use: dict) -> str:
    """Where a run asked for the event calendar, how it used it (RunSummary.event_loop)."""
    words = f"calendar in {use['calendar_steps']} of {use['steps']} steps"
    if use["unfit"]:
        words += f"; the time-ordered loop took the rest, which it cannot serve: {use['unfit']}"
    return words + " (docs/space-order.md, \"The event calendar\")"


def pairs_words(pairs: dict) -> str:
    """What a live audit did with the pairs of spheres (RunSummary.audit_pairs, with some
    taken from the engine)."""
    from_engine, steps = pairs["from_engine"], pairs["steps"]
    which = f"all {steps}" if from_engine == steps else f"{from_engine} of {steps}"
    return (f"pairs of spheres in {which} steps taken from the engine's own swept tests (exact and complete "
            f"there), not walked again: `physdbg explain` (or --full-audit) walks them")


def finding_lines(findings: list, counts: dict[str, int]) -> list[str]:
    """The run summary's findings (audit.Finding, the first of each kind; counts: of every
    kind): one line each, an explanation a finding shares with the first of its kind said
    once (the collapse paragraph was printed five times), then a line per kind for the
    ones not listed."""
    from .audit import not_listed, said_once

    return ([f"step {f.step}: {message}" for f, message, _ in said_once(findings)]
            + _more_lines(not_listed(counts, findings)))


def _more_lines(more: dict[str, int]) -> list[str]:
    return [f"... and {n} more {kind} findings" for kind, n in more.items()]


def auto_lines(auto: dict) -> list[str]:
    """One line per decision (advisor.Decision by setting): settings decided together join
    the line of the one whose words say why, 'auto  rapid_contact_rule=hold, sleep_speed=0.0:
    no closed box ...'."""
    lines: dict[str, list[str]] = {}
    for name, decision in auto.items():
        if decision.shared_with in lines:
            lines[decision.shared_with][0] += f", {name}={decision.value}"
        else:
            lines[name] = [f"{name}={decision.value}", decision_words(decision)]
    return [f"auto        {head}: {reason}" for head, reason in lines.values()]


def decision_words(decision) -> str:
    """Why an "auto" setting took its value (advisor.Decision): its own words, or the
    setting whose words it shares."""
    return decision.why or f"as {decision.shared_with}"


def _warning_totals(counts: dict[str, int]) -> str:
    """'none', or the total and a count per kind: '197: 76 max_contacts_per_step, 121 overlap'."""
    if not counts:
        return "none"
    kinds = ", ".join(f"{n} {code}" for code, n in sorted(counts.items(), key=lambda item: -item[1]))
    return f"{sum(counts.values())} ({kinds}); the first of each kind:"


def count_words(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _vec(values) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in values) + "]"


def _eos_lines(eos: dict | None) -> list[str]:
    """The equation of state read off the collisions (physdbg.analysis.pressure), if any."""
    if eos is None:
        return []
    first, last = eos["steps"]
    line = f"pressure    Z = PV/NkT = {eos['z_virial']:.4g} ± {eos['z_virial_error']:.2g} from the collisions"
    if eos["z_wall"] is not None:
        line += f", {eos['z_wall']:.4g} ± {eos['z_wall_error']:.2g} from the walls"
    line += f" (steps {first}..{last})"
    lines = [line, f"temperature kT = {eos['kT']:.4g} J"]
    if eos["collision_rate"]:
        line = (f"collisions  {eos['collision_rate']:.4g} ± {eos['collision_rate_error']:.2g} per sphere per second")
        if eos["collision_rate_enskog"] is not None:
            line += f" (Enskog: {eos['collision_rate_enskog']:.4g})"
        lines.append(line)
    if eos["z_carnahan_starling"] is not None:
        walls = "a periodic box has none" if eos["periodic"] else "walls shift a small box's Z"
        lines.append(f"reference   Carnahan–Starling at packing fraction {eos['packing_fraction']:.4g}: "
                     f"Z = {eos['z_carnahan_starling']:.4f} (a bulk fluid; {walls})")
    return lines


def size_words(n: int) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)


def check_dict(result) -> dict:
    """`physdbg check --json`'s fields (api.check's CheckResult): the scene, whether its
    settings are the advised ones, the current and recommended settings, why, the facts
    the advice rests on and each method's prediction."""
    from dataclasses import asdict

    advice = result.advice
    return {"scene": result.scene.name, "ok": result.ok, "current": result.current,
            "recommended": advice.recommended, "reasons": advice.reasons, "facts": advice.facts,
            "predictions": [asdict(p) for p in advice.predictions]}


def check_text(result) -> str:
    """`physdbg check`'s text: the scene's facts, each method's prediction (* marks the
    scene's own), the pile advice, the auto decisions and the recommendation (result: an
    api.CheckResult)."""
    advice = result.advice
    f = advice.facts
    dt = f"dt {f['dt']:.6g} s" if result.scene.dt is not None else f"real-time steps up to {f['dt']:.6g} s"
    lines = [f"scene       {result.scene.name}  ({result.scene.source})",
             f"facts       {count_words(f['particles'], 'particle')}, {count_words(f['walls'], 'wall')}"
             f"{_mesh_words(f.get('meshes') or {})}{_partner_words(f.get('partners') or {})}; {dt}; "
             f"{f['duration']:.6g} s; speeds up to {f['speed_bound']:.3g} m/s ({f['speed_bound_why']}); "
             + ("contacts can happen" if f["contacts_possible"] else "no contact can happen")]
    if f["periodic"] is not None:
        lines.append(f"periodic    {f['periodic']['why']}")
    lines += [f"{'sweep' if k == 0 else '':<11} {sweep['why']}" for k, sweep in enumerate(f.get("mesh_sweeps") or [])]
    lines += [f"start       {p.why}" for p in advice.predictions if p.setting == "start"]
    lines += [f"note        {note}" for note in f.get("notes") or []]
    for setting in ("integrator", "detection", "ordering"):
        for k, p in enumerate(x for x in advice.predictions if x.setting == setting):
            mark = "*" if result.current[setting] == p.value else " "
            lines.append(f"{setting if k == 0 else '':<11} {mark}{p.value:<14} {p.outcome:<13} {p.why}")
    if f["pile"] is not None:  # speed and resting, not correctness: the exit code ignores it
        from ..advisor import PILE_REMEDY_FLAGS, pile_choice

        chosen = pile_choice(result.scene.settings)
        lines.append(f"pile        {f['pile']['why']}; an exact pile does not rest by itself:")
        for p in (x for x in advice.predictions if x.setting == "pile"):
            mark = "*" if p.value == chosen else " "
            lines.append(f"{'':<11} {mark}{p.value:<14} {p.outcome:<13} {p.why}")
        if chosen != "tc+sleep":
            lines.append(f'  to settle {PILE_REMEDY_FLAGS}  (docs/sleeping.md)')
    lines += auto_lines(result.scene.auto)
    lines.append("recommended " + " ".join(f"{k}={v}" for k, v in advice.recommended.items()))
    lines += [f"  {k:<12}{advice.reasons[k]}" for k in advice.recommended]
    settings = " ".join(f"{k}={v}" for k, v in result.current.items())
    pile = None
    if f["pile"] is not None:  # the pile's outcome under the scene's own rules, said beside the verdict
        from ..advisor import pile_choice

        chosen = pile_choice(result.scene.settings)
        pile = next((p for p in advice.predictions if p.setting == "pile" and p.value == chosen), None)
    if result.ok:
        lines.append(f"this scene  {settings} (*): predicted safe (no tunnelling or overlap left)"
                     + (f"; {', '.join(p.value for p in result.warnings)} inexact" if result.warnings else "")
                     + (f"; but its pile {pile.outcome} under {pile.value} (slow or stopped by a budget, not wrong)"
                        if pile is not None and pile.outcome != "settles" else "")
                     + ("; but a mesh turns so far in a step that its contacts may hit the swept-test budget (sweep)"
                        if f.get("mesh_sweeps") else ""))
    else:
        lines.append(f"this scene  {settings} (*): predicted to fail: "
                     + "; ".join("it starts with a sphere inside another body (start, above)" if p.setting == "start"
                                 else f"{p.setting}={p.value} {p.outcome}" for p in result.problems))
    return "\n".join(lines)


def info_text(data: dict) -> str:
    """`physdbg info`'s text (data: api.info's dict)."""
    settings = " ".join(f"{k}={v}" for k, v in data["settings"].items())
    lines = [
        f"recording   {data['path']}  ({size_words(data['bytes'])}"
        + (", TRUNCATED: the writer stopped before closing it" if data["truncated"] else "") + ")",
        f"scene       {data['scene']}  ({data['source']})",
        f"settings    {settings}",
        *([f"fork        {fork_line(data['fork'])}"] if data.get("fork") else []),
        f"steps       {data['steps']}  ({data['sim_time']:.6g} s simulated), detail {data['detail']}",
        f"bodies      {count_words(data['particles'], 'particle')}, {count_words(len(data['walls']), 'wall')}"
        + _mesh_words(data.get("meshes") or {}) + _partner_words(data.get("partners") or {}),
        *(f"meshes      {motion}" for motion in data.get("mesh_motion") or []),
        *([f"sleep       {data['asleep_at_end']} of {data['particles']} spheres asleep at the end "
           f"(sleep_speed {data['settings'].get('sleep_speed')} m/s)"] if data["asleep_at_end"] is not None else []),
        f"size        {data['bytes_per_particle_step']:.1f} bytes per particle-step (everything)"
        if data["bytes_per_particle_step"] else "size        -",
        f"final hash  {data['final_hash']}",
        f"written by  physdbg {data['physdbg_version']}, format {data['format_version']}",
        *([f"foreign     another engine's run, from {data['foreign']['source']} ({data['foreign']['format']}, "
           f"velocities {data['foreign']['velocities']})"] if data.get("foreign") else []),
        *[f"how         {note}" for note in (data.get("foreign") or {}).get("notes", [])],
        *_eos_lines(data["equation_of_state"]),
        "channels",
    ]
    width = max(len(c["topic"]) for c in data["channels"])
    for c in data["channels"]:
        lines.append(f"  {c['topic']:<{width}}  {c['messages']:>7} messages  {c['encoding']:<14} {c['schema']}")
    return "\n".join(lines)
