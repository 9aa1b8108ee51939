"""What a command starts and leaves running: the Rerun viewer (native or in a browser) on
a recording's picture, and any server that answers until Ctrl-C or SIGTERM.

The CLI (cli.py) parses and prints; what it launches lives here, so a script can launch
the same: ``spawn_viewer`` starts the native viewer detached (it outlives the command),
``serve_web`` serves a .rrd file to the web viewer on localhost until stopped, and
``until_stopped`` runs any blocking loop (the web viewer's, check-run --serve's) so that
SIGTERM ends it as Ctrl-C does and the caller's ``finally`` always runs.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from .errors import PhysdbgError


def spawn_viewer(rrd: Path) -> None:
    """Start the native Rerun viewer on an .rrd file, detached (it outlives this process)."""
    import subprocess

    from .record.rerun_sink import viewer_binary

    try:
        subprocess.Popen([viewer_binary(), str(rrd)], start_new_session=True)
    except OSError as err:
        raise PhysdbgError(f"cannot start the Rerun viewer ({err})") from None


def until_stopped(wait: Callable[[], object]) -> bool:
    """Run ``wait`` (a blocking loop) until it returns, or until Ctrl-C or SIGTERM (main
    thread: SIGTERM is raised as Ctrl-C while it runs). Returns True when a signal stopped it."""
    import signal

    def stop(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        wait()
        return False
    except KeyboardInterrupt:
        return True
    finally:
        signal.signal(signal.SIGTERM, previous)


def serve_web(rrd: Path, port: int, say: Callable[[str], None]) -> None:
    """Serve the recording's picture to the Rerun web viewer on localhost only, until Ctrl-C
    or SIGTERM; ``say`` gets the address to open (one line, then where it is served). The
    viewer process is stopped either way; one that stops by itself with an error code is a
    PhysdbgError (its port taken, most likely)."""
    from .record.rerun_sink import start_web_viewer, stop_process

    try:
        viewer, port, grpc_port = start_web_viewer(str(rrd), port)
    except OSError as err:
        raise PhysdbgError(f"cannot start the Rerun viewer ({err})") from None
    code = 0

    def wait() -> None:
        nonlocal code
        say(f"open        http://127.0.0.1:{port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}%2Fproxy")
        say("            (served on localhost only; Ctrl-C to stop)")
        code = viewer.wait()

    try:
        until_stopped(wait)
    finally:
        stop_process(viewer)
    if code:
        raise PhysdbgError(f"the Rerun web viewer stopped with exit code {code} (is port {port} in use?)")
