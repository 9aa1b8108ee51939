"""physdbg: a physics engine that shows its work."""
from .version import __version__


def _engine_cache_dir() -> None:
    """Keep numba's compiled kernels in a folder named by a hash of the engine's sources.

    numba's cache (``cache=True``) keeps each compiled function with the code of the
    functions it calls, and reuses it after a callee changed: the old callee runs. That
    happened while building physdbg (tests passed on stale kernels that a fresh clone did
    not have; with a callee in another file, and with numba 0.68 for a callee in the same
    file). A folder per version of the engine's sources makes a
    stale kernel impossible. A NUMBA_CACHE_DIR set by the user is respected, and then
    nothing protects it: whoever sets one while editing the engine must empty it.
    """
    import hashlib
    import os
    from pathlib import Path

    if "NUMBA_CACHE_DIR" in os.environ:
        return
    engine = Path(__file__).parent / "engine"
    digest = hashlib.blake2b(digest_size=8)
    for source in sorted(engine.rglob("*.py")) + [Path(__file__).parent / "events.py"]:
        digest.update(str(source.relative_to(engine.parent)).encode() + source.read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    os.environ["NUMBA_CACHE_DIR"] = str(base / "physdbg" / "numba" / digest.hexdigest())


_engine_cache_dir()


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
