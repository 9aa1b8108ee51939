"""Analysis of runs and recordings: audit one run (explain), compare two (diff).

Outside the pure engine: these read events or recordings, never the engine's internals.
"""

from .audit import AuditReport, Auditor, Finding, explain
from .diff import DiffReport, diff

__all__ = ["AuditReport", "Auditor", "DiffReport", "Finding", "diff", "explain"]
