"""physdbg: a physics engine that shows its work."""
__version__ = "0.1.0"


def open_recording(path):
    """Open a .mcap recording: steps as numpy arrays, events as typed records
    (see :class:`physdbg.record.Recording`)."""
    from .record import open_recording as _open

    return _open(path)
