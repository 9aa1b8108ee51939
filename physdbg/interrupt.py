"""Ctrl-C ends a run within a second, at a point where every file is whole.

Python runs a signal handler only between bytecodes of the main thread, so a step spent in
compiled code (a jammed pile's held-contact solve, a contact loop with a huge dt) would
see a Ctrl-C only when it ends, seconds or minutes later. So while a run steps:

- the SIGINT handler asks the world to stop (``World.request_stop``): the step under way
  ends half done, unreported (StepStopped, a KeyboardInterrupt), so the recorders hold
  every step before it and the files are closed as after any Ctrl-C;
- a watcher thread wakes on the signal itself, through ``signal.set_wakeup_fd`` (written
  by the interpreter's C-level handler the moment the signal arrives) and asks the world
  to stop from there: the engine's compiled functions release the GIL (``nogil``, jit.py),
  so the thread runs while a step is in compiled code, and the compiled event loop and
  held-contact solves read the stop switch as they go;
- a second Ctrl-C raises KeyboardInterrupt at once (if something in Python is stuck).

Only in the main thread (the only one signals reach); elsewhere a no-op.
"""

from __future__ import annotations

import signal
import socket
import threading


class StopOnCtrlC:
    """``with StopOnCtrlC(world):`` around the stepping loop (see the module docstring)."""

    def __init__(self, world):
        self.world = world
        self.presses = 0
        self._active = threading.current_thread() is threading.main_thread()
        self._previous_handler = None
        self._previous_fd = -1
        self._sockets: tuple[socket.socket, socket.socket] | None = None
        self._thread: threading.Thread | None = None

    def __enter__(self) -> StopOnCtrlC:
        if not self._active:
            return self
        self._previous_handler = signal.signal(signal.SIGINT, self._handler)
        reader, writer = socket.socketpair()
        writer.setblocking(False)
        self._sockets = (reader, writer)
        try:
            self._previous_fd = signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
        except ValueError:  # not the main thread of the main interpreter after all
            self._previous_fd = None
            return self
        self._thread = threading.Thread(target=self._watch, name="physdbg-ctrl-c", daemon=True)
        self._thread.start()
        return self

    def _watch(self) -> None:
        reader = self._sockets[0]
        while True:
            try:
                data = reader.recv(64)
            except OSError:
                return
            if not data:  # the other end closed: the run is over
                return
            if signal.SIGINT in data:
                self.world.request_stop()

    def _handler(self, signum, frame) -> None:
        self.presses += 1
        if self.presses > 1:
            raise KeyboardInterrupt
        self.world.request_stop()

    def __exit__(self, *exc) -> None:
        if not self._active:
            return
        if self._previous_fd is not None:
            signal.set_wakeup_fd(self._previous_fd)
        signal.signal(signal.SIGINT, self._previous_handler)
        if self._sockets is not None:
            reader, writer = self._sockets
            writer.close()  # the watcher's recv ends
            if self._thread is not None:
                self._thread.join(timeout=1.0)
            reader.close()
