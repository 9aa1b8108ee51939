"""check-run --serve: the verdict in the student's own page.

A small HTTP server on this machine only (127.0.0.1). A page that traces its engine with
physdbg-trace.js sends its run here when ``finish()`` is called; the server checks each run
as it arrives (``api.check_run``, one at a time, the rest queued), prints the verdict in the
terminal, keeps both recordings for ``replay`` and ``diff``, and answers the page with the
verdict, which the tracer shows in a small panel: SAME, or the first departing step, the
body, the cause in words and the advice, with a link that opens the run against
physdbg's in Rerun's web viewer (the viewer rerun-sdk ships, started by this server on
localhost), paused where the runs part.

  GET  /ping                 {"physdbg": version}: how the tracer knows a server answers
  POST /check                the run's JSON Lines text: answers its verdict (Verdict, as JSON)
  GET  /runs/N/view.rrd      run N against physdbg's, one Rerun recording (made on first ask)
  GET  /view/N               the Rerun web viewer, opening /runs/N/view.rrd

Every answer is JSON or a file; a request from a page of another origin than this machine
(not file://, localhost or 127.0.0.1), a Host header naming another server, a body larger
than ``max_bytes`` (refused before it is read) or sent slower than READ_TIMEOUT allows, a
malformed run or a hostile scene object gets a clear error and the server goes on. A
page opened from a file sends the Origin "null", as a sandboxed frame of any site can:
so what a run may make the server do is bounded whoever sends it — a run's scene object
reads no file (no meshes), keeps the scene limits (no max_memory, max_particle_steps or
budget of its own: api.scene_of_run), and the runs are checked one at a time.
"""

from __future__ import annotations

import json
import queue
import re
import subprocess
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from urllib.parse import quote, urlsplit

from .errors import PhysdbgError

DEFAULT_PORT = 8765  # physdbg-trace.js sends to http://127.0.0.1:8765 unless told otherwise
MAX_BYTES = 64 * 2**20  # a run's body larger than this is refused unread (--max-bytes)
QUEUE = 64  # runs waiting to be checked; a page that finds the queue full is told so
CHECK_TIMEOUT = 600.0  # s a page waits for its verdict
READ_TIMEOUT = 30.0  # s a request may take to send its body, in all (and each read of its headers)
CONNECTIONS = 32  # requests served at once; one more is answered 503 at once
_LENGTH = re.compile(r"^[0-9]{1,12}$")  # a Content-Length (ASCII digits: "²".isdigit() is True)
_LOCAL_HOSTS = ("127.0.0.1", "localhost", "[::1]")
_ROUTE_VIEW = re.compile(r"^/view/([0-9]{1,9})$")
_ROUTE_RRD = re.compile(r"^/runs/([0-9]{1,9})/view\.rrd$")


@dataclass
class Verdict:
    """What the page is told of one run: run (its number on this server), file (the name
    the page gave), verdict SAME | DEPARTS | ERROR, exit_code (check-run's: 0, 1, 2),
    step, body, cause (the first departure's kind) and cause_words, summary (the
    headline, or the error), finding (what that departure says of the run), advice, view (the URL that opens it in Rerun's web viewer,
    for a run that departs), seconds (the check's wall time)."""

    run: int
    file: str
    verdict: str
    exit_code: int
    scene: str | None = None
    step: int | None = None
    body: int | None = None
    cause: str | None = None
    cause_words: str | None = None
    summary: str = ""
    finding: str | None = None
    advice: str | None = None
    view: str | None = None
    seconds: float = 0.0

    def line(self) -> str:
        """The verdict in one terminal line."""
        where = f"step {self.step}, sphere {self.body}: {self.cause_words}" if self.step is not None else ""
        head = f"run {self.run:<4} {self.file:<24} {self.verdict:<7}"
        if self.verdict == "ERROR":
            return f"{head} {self.summary}"
        return f"{head} {where or self.summary}" + (f"   {self.view}" if self.view else "")


@dataclass
class _Job:
    number: int
    file: str
    text: bytes
    done: threading.Event = field(default_factory=threading.Event)
    verdict: Verdict | None = None


class CheckServer:
    """The server: ``serve_forever`` until ``shutdown``. scene: the scene every run is
    checked against (None: each run's own, from its first line); overrides: -s KEY=VALUE;
    folder: where each run and its two recordings are kept (runs/N-NAME/); on_verdict:
    called with each Verdict (the CLI prints it); options: check_run's (atol, rtol,
    time_unit, length_unit, verify)."""

    def __init__(self, folder: str | Path, scene: str | None = None, overrides=(), port: int = DEFAULT_PORT,
                 max_bytes: int = MAX_BYTES, viewer_port: int = 0, on_verdict=None, force: bool = False,
                 **options):
        self.folder = Path(folder)
        self.scene, self.overrides = scene, list(overrides)
        self.options = options  # check_run's atol, rtol, time_unit, length_unit, verify
        self.max_bytes = int(max_bytes)
        self.on_verdict = on_verdict
        if self.folder.exists() and any(self.folder.iterdir()) and not force:
            raise PhysdbgError(f"{self.folder}: holds runs of another session; --force adds to it (runs already "
                               f"there are kept), or give another --keep folder")
        self.folder.mkdir(parents=True, exist_ok=True)
        from http.server import ThreadingHTTPServer

        try:
            self.http = ThreadingHTTPServer(("127.0.0.1", port), _handler(self))
        except OSError as err:
            raise PhysdbgError(f"cannot listen on 127.0.0.1:{port} ({err.strerror or err}): is another server "
                               f"there? give another --port") from None
        self.http.daemon_threads = True
        self.port = self.http.server_address[1]
        self.viewer_port = viewer_port
        self._viewer: subprocess.Popen | None = None
        self._viewer_lock = threading.Lock()
        self._queue: queue.Queue[_Job | None] = queue.Queue(QUEUE)
        self._connections = threading.BoundedSemaphore(CONNECTIONS)
        # (numbered after the runs kept there already, so none is written over)
        self._count = max((int(p.name[:4]) for p in self.folder.glob("[0-9][0-9][0-9][0-9]-*")), default=0)
        self._count_lock = threading.Lock()
        self._runs: dict[int, Path] = {}
        self._worker = threading.Thread(target=self._work, name="physdbg-check", daemon=True)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def serve_forever(self) -> None:
        self._worker.start()
        try:
            self.http.serve_forever(poll_interval=0.2)
        finally:
            self.close()

    def shutdown(self) -> None:
        """Stop serving (from another thread)."""
        self.http.shutdown()

    def close(self) -> None:
        from .record.rerun_sink import stop_process

        self._queue.put(None)
        self.http.server_close()
        stop_process(self._viewer)

    # ------------------------------------------------------------------ checking
    def submit(self, file: str, text: bytes) -> _Job:
        """Queue a run (its JSON Lines bytes); raises queue.Full when QUEUE wait."""
        with self._count_lock:
            self._count += 1
            job = _Job(self._count, file, text)
        self._queue.put_nowait(job)
        return job

    def _work(self) -> None:
        while True:
            job = self._queue.get()
            if job is None:
                return
            try:
                job.verdict = self._check(job)
            except Exception as err:  # noqa: BLE001 - a verdict, never the end of the server
                job.verdict = Verdict(job.number, job.file, "ERROR", 70, summary=f"{type(err).__name__}: {err}")
            finally:
                job.done.set()
            if self.on_verdict is not None:
                self.on_verdict(job.verdict)

    def _check(self, job: _Job) -> Verdict:
        from . import api
        from .analysis.departure import DEPARTURE_KINDS, cause_of
        from .errors import one_line

        started = time.perf_counter()
        stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", Path(job.file).stem)[:40] or "run"
        where = self.folder / f"{job.number:04d}-{stem}"
        where.mkdir(parents=True)
        run = where / "run.jsonl"
        run.write_bytes(job.text)
        try:
            result = api.check_run(run, self.scene, self.overrides, keep=where, force=True, from_a_page=True,
                                   **self.options)
        except PhysdbgError as err:
            # (the page is told the run's name, not where this server keeps it)
            said = one_line(str(err)).replace(str(run), job.file)
            return Verdict(job.number, job.file, "ERROR", err.exit_code, summary=said,
                           seconds=time.perf_counter() - started)
        report = result.report
        self._runs[job.number] = where
        first = report.first
        departure = cause_of(first, report.departures) if first is not None else None
        return Verdict(job.number, job.file, "SAME" if first is None else "DEPARTS", report.exit_code,
                       scene=report.scene, step=first.step if first else None, body=first.body if first else None,
                       cause=first.cause if first else None,
                       cause_words=DEPARTURE_KINDS[first.cause][0] if first else None, summary=report.headline,
                       finding=departure.text if departure is not None else None,
                       advice=departure.advice if departure is not None else None,
                       view=f"{self.url}/view/{job.number}" if first is not None else None,
                       seconds=time.perf_counter() - started)

    # ------------------------------------------------------------------ the view
    def view_rrd(self, number: int) -> Path | None:
        """Run ``number`` against physdbg's as one Rerun recording (api.overlay, opened where
        they part), made on first ask; None for an unknown run."""
        where = self._runs.get(number)
        if where is None:
            return None
        rrd = where / "view.rrd"
        with self._viewer_lock:  # (one at a time: two pages asking at once make it once)
            if not rrd.is_file():
                from . import api

                api.overlay(where / "run.mcap", where / "reference.mcap", rrd_path=str(rrd), force=True)
        return rrd

    def viewer_url(self, number: int) -> str:
        """The web viewer (started on first ask, on localhost) opening run ``number``'s view."""
        with self._viewer_lock:
            if self._viewer is None or self._viewer.poll() is not None:
                self._start_viewer()
        rrd = f"{self.url}/runs/{number}/view.rrd"
        return f"http://127.0.0.1:{self.viewer_port}/?url={quote(rrd, safe='')}"

    def _start_viewer(self) -> None:
        from .record.rerun_sink import start_web_viewer

        self._viewer, self.viewer_port, _ = start_web_viewer(None, self.viewer_port)

    # ------------------------------------------------------------------ who may ask
    def allowed_origin(self, origin: str | None) -> bool:
        """A page of this machine: no Origin (a local tool), "null" (a file:// page), or
        http(s) on localhost, 127.0.0.1 or [::1] at any port."""
        if origin is None or origin == "null":
            return True
        parts = urlsplit(origin)
        return parts.scheme in ("http", "https") and parts.hostname in ("127.0.0.1", "localhost", "::1")

    def allowed_host(self, host: str | None) -> bool:
        """The Host header names this server (a page on another site that resolves its own
        name to 127.0.0.1 is refused: DNS rebinding)."""
        if not host:
            return False
        return any(host == f"{name}:{self.port}" or host == name for name in _LOCAL_HOSTS)


def _handler(server: CheckServer):
    from http.server import BaseHTTPRequestHandler

    from .version import __version__

    class Handler(BaseHTTPRequestHandler):
        timeout = READ_TIMEOUT
        server_version = f"physdbg/{__version__}"
        protocol_version = "HTTP/1.1"

        def log_message(self, format, *args):  # noqa: A002 - the verdicts are printed, not each request
            pass

        def handle(self):
            if not server._connections.acquire(blocking=False):  # (slow senders may not pile up)
                self.close_connection = True
                try:
                    self.wfile.write(b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\n"
                                     b"Connection: close\r\n\r\n")
                except OSError:
                    pass
                return
            try:
                super().handle()
            finally:
                server._connections.release()

        def _cors(self) -> None:
            origin = self.headers.get("Origin")
            if origin is not None and server.allowed_origin(origin):
                self.send_header("Access-Control-Allow-Origin", origin)
                self.send_header("Vary", "Origin")

        def _send(self, code: int, payload: dict | bytes, kind: str = "application/json") -> None:
            body = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
            self.send_response(code)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self._cors()
            self.end_headers()
            self.wfile.write(body)

        def _refuse(self, code: int, message: str) -> None:
            self.close_connection = True
            self._send(code, {"verdict": "ERROR", "error": message, "exit_code": 2})

        def _who(self) -> bool:
            if not server.allowed_host(self.headers.get("Host")):
                self._refuse(403, f"Host {self.headers.get('Host')!r}: this server answers 127.0.0.1:{server.port} "
                                  f"and localhost:{server.port} only")
                return False
            origin = self.headers.get("Origin")
            if not server.allowed_origin(origin):
                self._refuse(403, f"a page of {origin} may not send runs here: this server answers pages of this "
                                  f"machine only (file://, localhost, 127.0.0.1)")
                return False
            return True

        def _body(self, size: int) -> bytes | None:
            """The request's body, read within READ_TIMEOUT in all (a sender that trickles its
            bytes is cut off); None when it did not arrive in time."""
            deadline = time.monotonic() + READ_TIMEOUT
            parts, got = [], 0
            while got < size:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self.connection.settimeout(left)
                try:
                    part = self.rfile.read1(min(size - got, 1 << 16))
                except OSError:
                    return None
                if not part:
                    break
                parts.append(part)
                got += len(part)
            return b"".join(parts)

        def do_OPTIONS(self):  # noqa: N802 - a CORS preflight
            if not self._who():
                return
            self.send_response(204)
            self._cors()
            self.send_header("Access-Control-Allow-Methods", "GET, POST, OPTIONS")
            self.send_header("Access-Control-Allow-Headers", "Content-Type, X-Physdbg-File")
            self.send_header("Access-Control-Max-Age", "600")
            self.send_header("Content-Length", "0")
            self.end_headers()

        def do_GET(self):  # noqa: N802
            if not self._who():
                return
            path = urlsplit(self.path).path
            if path == "/ping":
                return self._send(200, {"physdbg": __version__, "check": "/check"})
            if path == "/":
                return self._send(200, {"physdbg": __version__, "check": f"POST {server.url}/check"})
            found = _ROUTE_RRD.match(path)
            if found:
                try:
                    rrd = server.view_rrd(int(found.group(1)))
                except PhysdbgError as err:
                    return self._refuse(500, str(err))
                if rrd is None:
                    return self._refuse(404, f"no run {found.group(1)} on this server")
                return self._send(200, rrd.read_bytes(), "application/octet-stream")
            found = _ROUTE_VIEW.match(path)
            if found:
                number = int(found.group(1))
                if number not in server._runs:
                    return self._refuse(404, f"no run {number} that departs on this server")
                try:
                    location = server.viewer_url(number)
                except (PhysdbgError, OSError) as err:
                    return self._refuse(500, f"cannot start the Rerun web viewer ({err})")
                self.send_response(302)
                self.send_header("Location", location)
                self.send_header("Content-Length", "0")
                self.end_headers()
                return None
            return self._refuse(404, f"no {path} here: POST a run to /check")

        def do_POST(self):  # noqa: N802
            if not self._who():
                return
            if urlsplit(self.path).path != "/check":
                return self._refuse(404, f"no {self.path} here: POST a run to /check")
            length = self.headers.get("Content-Length", "")
            if not _LENGTH.match(length):
                return self._refuse(411, "a run needs a Content-Length (a whole number of bytes)")
            size = int(length)
            if size > server.max_bytes:
                return self._refuse(413, f"a run of {size:,} bytes is more than this server takes "
                                         f"({server.max_bytes:,}: --max-bytes)")
            text = self._body(size)
            if text is None:
                return self._refuse(408, f"the run did not arrive within {READ_TIMEOUT:.0f} s")
            if len(text) != size:
                return self._refuse(400, f"the run ended after {len(text)} of {size} bytes")
            file = Path(self.headers.get("X-Physdbg-File") or "run.jsonl").name[:80] or "run.jsonl"
            try:
                job = server.submit(file, text)
            except queue.Full:
                return self._refuse(503, f"{QUEUE} runs are waiting to be checked; send this one again in a moment")
            if not job.done.wait(CHECK_TIMEOUT):
                return self._refuse(504, f"the check took more than {CHECK_TIMEOUT:.0f} s; it goes on, and the "
                                         f"terminal prints its verdict")
            verdict = job.verdict
            return self._send(200 if verdict.verdict != "ERROR" else 400, asdict(verdict))

    return Handler
