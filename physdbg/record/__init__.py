"""Recording: observers that write runs to MCAP (lossless) and Rerun (the picture), and
the reader that gives them back.

Nothing here is imported by the engine. ``rerun`` is imported only when a Rerun sink is
made, so ``physdbg --help`` and MCAP-only work stay quick.
"""

from .format import DETAIL_LEVELS
from .header import RecordingHeader
from .reader import FrameState, Recording, RecordingError, open_recording

__all__ = ["DETAIL_LEVELS", "FrameState", "Recording", "RecordingError", "RecordingHeader", "open_recording"]
