"""Diff and audit reports as text (the terminal), Markdown (a CI step summary) and JSON.

The JSON form is ``report.as_dict()``; its fields are the dataclass fields documented in
docs/diff.md. Text and Markdown say the same things in the same order.
"""

from __future__ import annotations

import json
import math

from .audit import AuditReport
from .departure import CheckRunReport
from .diff import DiffReport


def to_json(report: DiffReport | AuditReport) -> str:
    return json.dumps(report.as_dict(), indent=2, default=_plain, allow_nan=False)


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


def diff_json(report: DiffReport) -> str:
    return json.dumps(_clean(report.as_dict()), indent=2, default=_plain)


def explain_json(report: AuditReport) -> str:
    return json.dumps(_clean(report.as_dict()), indent=2, default=_plain)


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


def diff_text(r: DiffReport) -> str:
    lines = [f"A  {r.a}  ({r.scene_a}, {r.steps_a} steps)", f"B  {r.b}  ({r.scene_b}, {r.steps_b} steps)",
             f"result   {'EQUIVALENT' if r.equivalent else 'DIFFERENT'}: {r.headline}",
             f"compared {r.compared} frames aligned by {r.aligned_by}; tolerance {_tolerance(r)}",
             f"checked  {_integrity(r)}"]
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
            lines.append(f"  first differing contact: #{d.first_event['index']} of the step: "
                         f"A {_contact(d.first_event['a'])}; B {_contact(d.first_event['b'])}")
    if r.growth is not None and d is not None:
        lines.append("afterwards: " + r.growth.sentence())
    if r.causes:
        lines.append("why:")
        lines.extend(f"  - [{c.kind}] {c.text}" for c in r.causes)
    return "\n".join(lines)


def diff_markdown(r: DiffReport) -> str:
    icon = "✅" if r.equivalent else "❌"
    lines = [f"### {icon} physdbg diff: {'equivalent' if r.equivalent else 'different'}", "",
             f"**{r.headline}**", "", "| | recording | scene | steps |", "|---|---|---|---|",
             f"| A | `{r.a}` | {r.scene_a} | {r.steps_a} |", f"| B | `{r.b}` | {r.scene_b} | {r.steps_b} |", "",
             f"Compared {r.compared} frames aligned by {r.aligned_by}; tolerance {_tolerance(r)}. "
             f"Checked {_integrity(r)}.", ""]
    if r.settings:
        lines += ["| setting | A | B | note |", "|---|---|---|---|"]
        lines += [f"| `{s.name}` | {_show(s.a)} | {_show(s.b)} | {'' if s.matters else 'cannot matter: ' + s.note} |"
                  for s in r.settings]
        lines.append("")
    d = r.divergence
    if d is not None:
        lines.append(f"**First difference: step {d.step}** (t = {d.time:.6g} s), {d.state.count} sphere(s):")
        lines.append("")
        lines += [f"- sphere {p['particle']}: \\|Δx\\| = {p['position']:.3g} m, \\|Δv\\| = {p['velocity']:.3g} m/s"
                  for p in d.state.particles]
        if d.first_event is not None:
            lines.append(f"- first differing contact #{d.first_event['index']}: A {_contact(d.first_event['a'])}; "
                         f"B {_contact(d.first_event['b'])}")
        if r.growth is not None:
            lines.append(f"- afterwards: {r.growth.sentence()}")
        lines.append("")
    if r.causes:
        lines += ["**Why**", ""] + [f"- *{c.kind}*: {c.text}" for c in r.causes]
    return "\n".join(lines) + "\n"


def explain_text(r: AuditReport) -> str:
    lines = [f"{r.source}  ({r.scene}, {r.checked} of {r.steps} steps audited)"]
    if r.clean:
        lines.append("result   CLEAN: no tunnelling, overlap, out-of-order contact, energy gain, NaN, budget hit "
                     "or collapse found")
    else:
        counts = ", ".join(f"{k} {v}" for k, v in r.counts.items())
        lines.append(f"result   FINDINGS: {counts}")
        for f in r.findings:
            lines.append(f"  - step {f.step} [{f.kind}] {f.message}")
            if f.advice:
                lines.append(f"      what to do: {f.advice}")
        lines.extend("  " + line for line in r.lines() if line.startswith("..."))
    lines.extend(f"note     {n}" for n in r.notes)
    return "\n".join(lines)


def explain_markdown(r: AuditReport) -> str:
    icon = "✅" if r.clean else "⚠️"
    lines = [f"### {icon} physdbg explain: {'clean' if r.clean else 'findings'}", "",
             f"`{r.source}` ({r.scene}, {r.checked} of {r.steps} steps audited)", ""]
    if not r.clean:
        lines += ["| kind | count |", "|---|---|"] + [f"| {k} | {v} |" for k, v in r.counts.items()] + [""]
        lines += [f"- **step {f.step}** *{f.kind}*: {f.message}" + (f" — {f.advice}" if f.advice else "")
                  for f in r.findings]
    lines += [f"> {n}" for n in r.notes]
    return "\n".join(lines) + "\n"


def check_run_json(report: CheckRunReport) -> str:
    return json.dumps(_clean(report.as_dict()), indent=2, default=_plain)


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
            lines.append(f"  - step {d.step} [{d.kind}] {d.text}{_more(d.more)}")
            lines.append(f"      what to do: {d.advice}")
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
        lines += ["| step | kind | what happened | what to do |", "|---|---|---|---|"]
        lines += [f"| {d.step} | {d.kind} | {d.text}{_more(d.more)} | {d.advice} |" for d in r.departures]
        lines.append("")
    lines += [f"> {n}" for n in r.notes]
    return "\n".join(lines) + "\n"


def _contact(c: dict | None) -> str:
    if c is None:
        return "no contact"
    who = c.get("who") or (f"{c['a']}–{c['other']}" if c["kind"] == 0 else f"{c['a']}–wall {c['other']}")
    return f"{who} at {c['time_in_step'] / c['dt']:.3f}·dt" + (" (resting)" if c["resting"] else "")


def _show(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)
