"""physdbg: a physics engine that shows its work."""
from .version import __version__


def open_recording(path):
    """Open a .mcap recording: steps as numpy arrays, events as typed records
    (see :class:`physdbg.record.Recording`)."""
    from .record import open_recording as _open

    return _open(path)


def diff(a, b, atol=None, rtol=None):
    """Compare two recordings (paths or open recordings): where they part and why
    (a :class:`physdbg.analysis.DiffReport`; ``exit_code`` 0 equivalent, 1 different)."""
    from .analysis import diff as _diff

    return _diff(a, b, atol=atol, rtol=rtol)


def explain(recording):
    """Audit one recording: tunnelling, overlaps, out-of-order contacts, energy gained,
    NaN, budgets hit, collapse (a :class:`physdbg.analysis.AuditReport`)."""
    from .analysis import explain as _explain

    return _explain(recording)
