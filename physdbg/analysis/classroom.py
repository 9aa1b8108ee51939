"""A class at once: check-run on every run in a folder of submissions, one table.

``api.check_class(runs, scene)`` runs ``api.check_run`` on each run (a .csv, .jsonl or .mcap
file) of the same scene, on local cores or an existing Dask cluster (sweep.run_jobs), and
returns one row per run: its verdict (SAME, DEPARTS, or ERROR for a file check-run cannot
read), its first departure and the cause, with the causes counted, most common first —
what a teaching assistant reads before office hours. One unreadable or hostile file is a
row with its error, never the end of the batch.
"""

from __future__ import annotations

import csv
import io
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

from .report import markdown_table

RUN_SUFFIXES = (".csv", ".jsonl", ".mcap")  # what a folder of submissions is searched for
MAX_RUNS = 10_000  # runs in one class, counted before any is checked


@dataclass
class ClassRow:
    """One run: verdict SAME | DEPARTS | ERROR; step, body: its first departure (None when
    SAME or ERROR); cause: the departure's kind (or the rule a SAME run set aside, a
    tie it took in another order, or "error"); said: the headline, or the error in one line."""

    run: str
    verdict: str
    step: int | None
    body: int | None
    cause: str | None
    said: str


@dataclass
class ClassReport:
    """check-run of a class: rows in the runs' order; counts: cause -> runs, most common first."""

    scene: str
    rows: list[ClassRow]
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def exit_code(self) -> int:
        """0 when every run is SAME, 1 otherwise (a departing or unreadable run)."""
        return 0 if all(r.verdict == "SAME" for r in self.rows) else 1

    def as_dict(self) -> dict:
        return {**asdict(self), "exit_code": self.exit_code}


def runs_in(paths: list[Path]) -> list[Path]:
    """The runs named: each folder's files ending in RUN_SUFFIXES (sorted, not recursive),
    each file itself."""
    from ..errors import PhysdbgError

    out: list[Path] = []
    for path in paths:
        if path.is_dir():
            out += sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in RUN_SUFFIXES)
        else:
            out.append(path)
        if len(out) > MAX_RUNS:
            raise PhysdbgError(f"more than {MAX_RUNS:,} runs: check a class in parts")
    if not out:
        raise PhysdbgError(f"no run (a {', '.join(RUN_SUFFIXES)} file) in {', '.join(map(str, paths))}")
    return out


def row_of(run: str, report) -> ClassRow:
    """A run's row from its check-run report (departure.CheckRunReport)."""
    if report.first is None:
        cause = (report.set_aside[0]["rule"] + " (physdbg's rule)" if report.set_aside
                 else "tie (either order)" if report.ties else None)
        return ClassRow(run, "SAME", None, None, cause, report.headline)
    return ClassRow(run, "DEPARTS", report.first.step, report.first.body, report.first.cause, report.headline)


def error_row(run: str, err: Exception) -> ClassRow:
    """A run check-run could not check: its error, in one line."""
    from ..errors import PhysdbgError

    said = str(err) if isinstance(err, PhysdbgError) else f"{type(err).__name__}: {err}"
    return ClassRow(run, "ERROR", None, None, "error", said.splitlines()[0] if said else "error")


def class_report(scene: str, rows: list[ClassRow]) -> ClassReport:
    """The rows with their causes counted, most common first ("same" for a SAME run)."""
    counts = Counter(row.cause or "same" for row in rows)
    return ClassReport(scene, rows, dict(counts.most_common()))


# ----------------------------------------------------------------------------- reports
COLUMNS = ("run", "verdict", "step", "body", "cause", "said")


def class_text(report: ClassReport) -> str:
    width = max(len(Path(r.run).name) for r in report.rows)
    lines = [f"class      {len(report.rows)} runs of {report.scene}: "
             f"{sum(r.verdict == 'SAME' for r in report.rows)} same, "
             f"{sum(r.verdict == 'DEPARTS' for r in report.rows)} depart, "
             f"{sum(r.verdict == 'ERROR' for r in report.rows)} unreadable"]
    lines.append("causes     " + ", ".join(f"{cause} {n}" for cause, n in report.counts.items()))
    for r in report.rows:
        where = f"step {r.step}, sphere {r.body}" if r.step is not None else ""
        lines.append(f"  {Path(r.run).name:<{width}}  {r.verdict:<7}  {where:<20}  {r.cause or '':<16}  {r.said}")
    return "\n".join(lines)


def class_markdown(report: ClassReport) -> str:
    lines = [f"### physdbg check-run: {len(report.rows)} runs of {report.scene}", "",
             *markdown_table(["cause", "runs"], [[cause, n] for cause, n in report.counts.items()]), "",
             *markdown_table(["run", "verdict", "first departure", "cause", "what check-run said"],
                             [[Path(r.run).name, r.verdict, f"step {r.step}, sphere {r.body}" if r.step is not None
                               else "", r.cause or "", r.said] for r in report.rows])]
    return "\n".join(lines) + "\n"


def class_csv(report: ClassReport) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(COLUMNS)
    for r in report.rows:
        writer.writerow([r.run, r.verdict, "" if r.step is None else r.step, "" if r.body is None else r.body,
                         r.cause or "", r.said])
    return out.getvalue()


# a class's report in each format but JSON (ClassReport.as_dict)
CLASS_FORMATS = {"text": class_text, "markdown": class_markdown, "csv": class_csv}
