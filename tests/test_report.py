"""analysis/report.py: one renderer per format for every kind of record, one table writer."""

from __future__ import annotations

from physdbg.analysis.audit import Finding
from physdbg.analysis.departure import Departure
from physdbg.analysis.diff_causes import Cause
from physdbg.analysis.report import markdown_table, record_lines, record_markdown


def test_a_cause_a_finding_and_a_departure_are_one_record_printed_one_way():
    """The three commands' records answer to the same names (code, step, bodies, summary,
    detail, advice), so one function prints each format; their JSON keeps its own fields."""
    cause = Cause("tunnelling", "sphere 0 went through wall 'w'", {"particle": 0}, step=3, bodies=(0,))
    whole_run = Cause("settings", "different settings: dt: 0.01 in A, 0.02 in B")
    finding = Finding("tunnelling", 3, [0], "sphere 0 went through wall 'w'", "use detection = swept")
    departure = Departure("tunnelling", 3, 0, "sphere 0 went through wall 'w'", "test along the path", other=None)
    assert (cause.code, cause.step, cause.bodies, cause.advice) == ("tunnelling", 3, (0,), "")
    assert (whole_run.step, whole_run.bodies) == (None, ())
    assert (finding.code, finding.step, finding.bodies, finding.detail) == ("tunnelling", 3, (0,), {})
    assert (departure.code, departure.bodies, departure.summary) == ("tunnelling", (0,), departure.text)
    assert record_lines(cause) == ["  - step 3 [tunnelling] sphere 0 went through wall 'w'"]
    assert record_lines(whole_run) == ["  - [settings] different settings: dt: 0.01 in A, 0.02 in B"]
    assert record_lines(finding) == ["  - step 3 [tunnelling] sphere 0 went through wall 'w'",
                                     "      what to do: use detection = swept"]
    assert record_lines(finding, advice="as above")[1] == "      what to do: as above"
    assert record_markdown(departure) == ("- **step 3** *tunnelling*: sphere 0 went through wall 'w' — "
                                          "test along the path")
    assert record_markdown(cause, "said above") == "- **step 3** *tunnelling*: said above"
    assert record_markdown(whole_run, "said above") == "- *settings*: said above"
    # the record's names are not fields of the JSON
    assert set(finding.as_dict()) == {"kind", "step", "particles", "message", "advice", "position", "evidence",
                                      "try_settings"}


def test_a_markdown_table_writes_empty_and_absent_cells_as_the_reports_always_have():
    assert markdown_table(["a", "b"], [["x", ""], ["y", None], [1, 2.5]]) == [
        "| a | b |", "|---|---|", "| x |  |", "| y | |", "| 1 | 2.5 |"]
