"""Every user-facing failure of physdbg is a :class:`PhysdbgError`.

The CLI catches exactly this hierarchy and prints its message (never a traceback),
so raising one of these is how library code reports bad input.
"""

from __future__ import annotations


class PhysdbgError(Exception):
    """Base class: a failure the user can act on; ``str(err)`` is the whole message."""

    exit_code = 2


class SceneError(PhysdbgError):
    """A scene file or override is wrong: names the file, the field and what is allowed."""

    def __init__(self, source: str, field: str, problem: str):
        self.source = source
        self.field = field
        self.problem = problem
        where = f"{source}: field '{field}'" if field else source
        super().__init__(f"{where}: {problem}")

    def __reduce__(self):  # so a worker process can hand it back (sweeps, benchmarks)
        return type(self), (self.source, self.field, self.problem)


class UnknownSceneError(PhysdbgError):
    """The scene is neither a built-in name nor a readable file."""


class KindRegistryError(PhysdbgError, ValueError):
    """The registry of collider kinds (events.COLLIDER_KINDS), the kinds' modules and the
    switch written from them disagree: physdbg was changed and its switch not written again."""


class RecordingError(PhysdbgError):
    """A file that is not a readable physdbg recording."""


class RecordingIntegrityError(RecordingError):
    """A recording that reads, but whose parts disagree: a state that does not give its
    stored hash, a frame index that disagrees with the states, frames out of order, a
    damaged summary, or more than one recording in one file. Names the file and the frame."""


class StuckRunError(PhysdbgError):
    """The world reached a state it cannot be stepped on from (WorldStuck): the run stopped
    there, every step up to it reported."""

    exit_code = 3


class NonFiniteRunError(StuckRunError):
    """A position or velocity became NaN or infinite while running: the run stopped there."""


class WorldStuck(Exception):
    """The engine's: a step ended in a state the world cannot be stepped on from. Raised
    after the step is reported (its StepEnd carries the warning that says why)."""


class PinnedSphere(WorldStuck):
    """A sphere pinned between a prescribed motion and something immovable (a kinematic
    mesh pressing it against a wall): no impulse can stop the motion, so the scene has no
    next state. step: the step (numbered from 1) in which it was found; words: the
    sentence that names the sphere and both partners."""

    def __init__(self, step: int, words: str):
        self.step, self.words = step, words
        super().__init__(f"{words}, in step {step}: a prescribed motion cannot be stopped, so the run cannot go on")


class NonFiniteState(WorldStuck, FloatingPointError):
    """A position or velocity became NaN or infinite in a step; the run cannot go on.

    step: the step (numbered from 1, as recordings and the CLI number it) at whose end it was
    found; particle: the first such particle; field: "position" or "velocity"; count: how
    many particles are affected.
    """

    def __init__(self, step: int, particle: int, field: str, count: int):
        self.step, self.particle, self.field, self.count = step, particle, field, count
        others = f" (and {count - 1} more)" if count > 1 else ""
        super().__init__(f"the {field} of sphere {particle}{others} became NaN or infinite in step {step}")


class StepStopped(KeyboardInterrupt):
    """A step left half done because the world was asked to stop (World.request_stop:
    Ctrl-C). The world's state is mid-step; the step was never reported (no StepEnd), so
    a recording holds every step before it. A KeyboardInterrupt, so a caller that stops
    on Ctrl-C stops on this."""

    def __init__(self, step: int):
        self.step = step
        super().__init__(f"stopped in step {step}, which was left half done and not reported")


class PeerError(PhysdbgError):
    """A peer engine that is missing or cannot run the scene."""


class ViewerError(PhysdbgError):
    """The Rerun viewer could not be started."""


class ForeignRunError(PhysdbgError):
    """A trajectory file that does not fit the format or the scene."""


class RecordingInterrupted(PhysdbgError):
    exit_code = 130


class CheckRunError(PhysdbgError):
    """The two runs cannot be compared (different bodies or steps, or too large)."""


class DaskMissing(PhysdbgError):
    """--dask without dask.distributed installed, or a scheduler that cannot be reached."""


class ChartsMissing(PhysdbgError):
    """matplotlib is not installed."""


class MeshError(PhysdbgError):
    """A mesh file or shape that cannot be used: the message names the file, the line and the problem."""


def one_line(message: str, longest: int = 200) -> str:
    """A message as a terminal shows it on one line: control characters escaped (a file
    name holding a newline or an escape sequence prints as ``\\n``, ``\\x1b``) and any word
    longer than ``longest`` characters (a 5,000-character file name) cut in its middle."""
    escaped = "".join(ch if ch.isprintable() or ch == " " else repr(ch)[1:-1] for ch in message)
    words = escaped.split(" ")
    for k, word in enumerate(words):
        if len(word) > longest:
            words[k] = f"{word[:longest - 60]}…({len(word):,} characters)…{word[-40:]}"
    return " ".join(words)


def os_error_words(err: OSError) -> str | None:
    """A one-line message for an OSError about a file the user named (None when it names
    none): the file and the system's reason, and a name the system refuses said as such."""
    import errno

    if err.filename is None:
        return None
    reason = err.strerror or str(err)
    if err.errno == errno.ENAMETOOLONG:
        reason = ("the system refuses this name: it is too long (most file systems allow 255 bytes a name, "
                  "4,096 a path)")
    return f"{err.filename}: {reason}"
