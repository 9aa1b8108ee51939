"""check-run --serve (physdbg/serve.py): runs sent by a page checked as they arrive, the
verdict answered to the page and shown there; hostile requests refused, the server going on."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import threading
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from typer.testing import CliRunner

from physdbg.api import load_scene, write_trace_js
from physdbg.cli import app
from physdbg.serve import CheckServer
from tests.student_engine import simulate_swept, trace_text

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def run_text(name: str, overrides: list[str], mistake: str | None = None) -> bytes:
    """A run of the swept student engine as physdbg-trace.js writes it (its scene first)."""
    scene = load_scene(name, overrides)
    return trace_text(scene, *simulate_swept(scene, scene.steps, scene.dt, mistake))


@pytest.fixture
def server(tmp_path):
    """A CheckServer on a free port, in a thread; its verdicts collected."""
    said = []
    srv = CheckServer(tmp_path / "runs", port=0, max_bytes=4 * 2**20, on_verdict=said.append)
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    srv.said = said
    yield srv
    srv.shutdown()
    thread.join(timeout=10)


def ask(srv, path: str, data: bytes | None = None, headers: dict | None = None, method: str | None = None):
    """(status, JSON answer) of a request to the server."""
    request = urllib.request.Request(srv.url + path, data=data, headers=headers or {}, method=method)
    try:
        with urllib.request.urlopen(request, timeout=120) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


@pytest.mark.slow
def test_a_run_sent_to_the_server_is_checked_and_its_verdict_answered(server, tmp_path):
    status, ping = ask(server, "/ping")
    assert status == 200 and "physdbg" in ping
    status, same = ask(server, "/check", run_text("bounce", ["integrator=euler", "steps=120"]),
                       {"X-Physdbg-File": "bounce.jsonl"})
    assert status == 200 and same["verdict"] == "SAME" and same["exit_code"] == 0 and same["file"] == "bounce.jsonl"
    status, wrong = ask(server, "/check", run_text("billiards", ["integrator=euler", "steps=60"], "one-missing"))
    assert status == 200 and wrong["verdict"] == "DEPARTS"
    assert (wrong["step"], wrong["cause"]) == (22, "one-missing") and "(1 + e)" in wrong["cause_words"]
    assert "effective restitution (-0.05 for 0–2" in wrong["finding"] and wrong["advice"]
    assert wrong["view"] == f"{server.url}/view/{wrong['run']}"
    # the terminal's lines, and the recordings kept for replay and diff
    assert [v.verdict for v in server.said] == ["SAME", "DEPARTS"]
    assert "step 22, sphere 8: the 1 of (1 + e) missing from the impulse" in server.said[1].line()
    kept = sorted((tmp_path / "runs").glob("0002-*"))[0]
    assert {p.name for p in kept.iterdir()} >= {"run.jsonl", "run.mcap", "reference.mcap"}
    # the comparison recording, made on first ask, for the web viewer
    with urllib.request.urlopen(f"{server.url}/runs/{wrong['run']}/view.rrd", timeout=120) as answer:
        assert answer.status == 200 and answer.read(4) == b"RRF2"


def test_hostile_requests_get_a_clear_error_and_the_server_goes_on(server):
    import http.client

    # a body larger than the server takes is refused on its Content-Length, before it is read
    connection = http.client.HTTPConnection("127.0.0.1", server.port, timeout=30)
    connection.putrequest("POST", "/check")
    connection.putheader("Content-Length", str(50 * 2**30))
    connection.endheaders()
    connection.send(b"x" * 1024)
    answer = connection.getresponse()
    assert answer.status == 413 and "more than this server takes" in json.loads(answer.read())["error"]
    connection.close()
    status, answer = ask(server, "/check", b"not json at all\n")
    assert status == 400 and answer["verdict"] == "ERROR" and "carries no scene" in answer["summary"]
    status, answer = ask(server, "/check", b'{"scene": {"particles": [{"position": [0, 1], "radius": 0.1}], '
                                           b'"dt": 0.01, "steps": 3}}\n{"step": 0}\n')
    assert status == 400 and "particles.0.position" in answer["summary"] and "\n" not in answer["summary"]
    status, answer = ask(server, "/check", b'{"scene": ' + b"[" * 5000 + b"]" * 5000 + b"}\n")
    assert status == 400 and answer["verdict"] == "ERROR"
    status, answer = ask(server, "/check", b'{"scene": "../../etc/passwd"}\n')
    assert status == 400 and "not a built-in scene" in answer["summary"]
    status, answer = ask(server, "/check", run_text("bounce", ["steps=5"]), {"Origin": "https://evil.example"})
    assert status == 403 and "another origin" not in answer["error"] and "evil.example" in answer["error"]
    status, answer = ask(server, "/ping", headers={"Host": "evil.example"})
    assert status == 403 and "Host" in answer["error"]
    assert ask(server, "/nowhere")[0] == 404 and ask(server, "/view/99")[0] == 404
    # pages of this machine may ask, from a file or a local server
    for origin in ("null", "http://localhost:8000", "http://127.0.0.1:5173"):
        status, answer = ask(server, "/ping", headers={"Origin": origin})
        assert status == 200, origin
    status, answer = ask(server, "/check", run_text("bounce", ["integrator=euler", "steps=30"]))
    assert status == 200 and answer["verdict"] == "SAME"  # still serving


@pytest.mark.slow
def test_check_run_serve_from_the_command_line_answers_and_stops_on_sigterm(tmp_path):
    process = subprocess.Popen([sys.executable, "-m", "physdbg", "check-run", "--serve", "--port", "0", "--keep",
                                str(tmp_path / "kept")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = process.stdout.readline()
        assert first.startswith("serving     http://127.0.0.1:"), first + process.stderr.read()
        url = first.split()[1]
        request = urllib.request.Request(url + "/check", data=run_text("bounce", ["integrator=euler", "steps=60"]))
        with urllib.request.urlopen(request, timeout=120) as answer:
            assert json.loads(answer.read())["verdict"] == "SAME"
        lines = [process.stdout.readline() for _ in range(3)]
        assert any(line.startswith("run 1") and "SAME" in line for line in lines), lines
    finally:
        process.send_signal(signal.SIGTERM)
        out, err = process.communicate(timeout=30)
    assert process.returncode == 0 and "stopped" in out and "Traceback" not in err


def test_check_run_serve_refuses_a_run_and_check_run_asks_for_one(tmp_path):
    both = CliRunner().invoke(app, ["check-run", str(tmp_path / "x.jsonl"), "--serve"])
    assert both.exit_code == 2 and "without --serve" in both.output
    for option in (["--port", "9"], ["--max-bytes", "5"]):
        alone = CliRunner().invoke(app, ["check-run", str(tmp_path / "x.jsonl"), *option])
        assert alone.exit_code == 2 and "go with --serve" in alone.output, option
    none = CliRunner().invoke(app, ["check-run"])
    assert none.exit_code == 2 and "--serve" in none.output and "Traceback" not in none.output


# ----------------------------------------------------------------------------- a real browser
def _page(site: Path, scene: str, server: str | bool, mistake: str | None = None) -> Path:
    """A student's page: the tracer, the scene `physdbg scenes show NAME --format js`
    prints, the engine; finish() when loaded."""
    write_trace_js(site, force=True)
    shutil.copy(ROOT / "tests" / "js" / "student_engine.js", site / "student_engine.js")
    shown = CliRunner().invoke(app, ["scenes", "show", scene, "--format", "js", "-s", "steps=120"])
    assert shown.exit_code == 0, shown.output
    (site / f"{scene}-scene.js").write_text(shown.output)
    options = {"server": server, **({"mistake": mistake} if mistake else {})}
    page = site / f"{scene}-{mistake or 'right'}.html"
    page.write_text(
        "<!doctype html><html><body>\n<script src=\"physdbg-trace.js\"></script>\n"
        f"<script src=\"{scene}-scene.js\"></script>\n<script src=\"student_engine.js\"></script>\n"
        f"<script>const scene = physdbgScenes[{json.dumps(scene)}]; scene.integrator = \"euler\";\n"
        f"studentEngine.run(scene, {json.dumps(options)}).finish();</script>\n</body></html>\n")
    return page


def _dom(page: Path, profile: Path) -> str:
    """The page's DOM once it is idle, from the headless command line the docs give (it
    waits for the fetch to the server: virtual time stands still while one is pending)."""
    done = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                           f"--user-data-dir={profile}", "--dump-dom", "--virtual-time-budget=60000", page.as_uri()],
                          capture_output=True, text=True, timeout=180)
    return done.stdout


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's chromium): "
                                             "the page's verdict panel is not read")
def test_the_verdict_appears_in_the_students_page_in_headless_chromium(server, tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    right = _dom(_page(site, "bounce", server.url), tmp_path / "p1")
    assert 'id="physdbg-verdict" data-verdict="SAME"' in right, right[-2000:]
    wrong = _dom(_page(site, "billiards", server.url, "one-missing"), tmp_path / "p2")
    assert 'data-verdict="DEPARTS"' in wrong and "step 22, sphere 8: the 1 of (1 + e) missing from the impulse" in wrong
    assert f'href="{server.url}/view/' in wrong  # the link that opens it in Rerun's web viewer
    assert [v.verdict for v in server.said] == ["SAME", "DEPARTS"]


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed: the page's download is not tried")
def test_with_no_server_the_page_still_downloads_the_run(tmp_path):
    import socket
    import time

    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        closed = f"http://127.0.0.1:{probe.getsockname()[1]}"
    site, downloads, profile = tmp_path / "site", tmp_path / "downloads", tmp_path / "profile"
    site.mkdir()
    page = _page(site, "bounce", closed)
    (profile / "Default").mkdir(parents=True)
    (profile / "Default" / "Preferences").write_text(json.dumps({
        "download": {"default_directory": str(downloads), "prompt_for_download": False},
        "profile": {"default_content_setting_values": {"automatic_downloads": 1}}}))
    browser = subprocess.Popen([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                                f"--user-data-dir={profile}", page.as_uri()], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    run = downloads / "bounce.jsonl"
    try:
        deadline = time.monotonic() + 120
        while not run.is_file() and time.monotonic() < deadline:
            time.sleep(0.2)
    finally:
        browser.kill()
        browser.wait()
    assert run.is_file()
    first = json.loads(run.read_text().splitlines()[0])
    assert first["scene"]["name"] == "bounce" and first["scene"]["integrator"] == "euler"


def test_what_a_page_may_send_is_bounded_whoever_sends_it(server):
    """A page opened from a file sends Origin "null", as a sandboxed frame of any site can:
    a scene a page sends reads no file and lifts no limit; a Content-Length that is not
    ASCII digits, a scene line that is not JSON, too deep or of a 5000-digit number, and a
    body trickled past the read time, each get a clear answer."""
    import http.client
    import socket

    from physdbg import serve

    for scene, field in (({"meshes": [{"file": "/etc/passwd"}]}, "meshes"), ({"max_memory": 1e18}, "max_memory"),
                         ({"max_contacts_per_step": 10**12}, "max_contacts_per_step"),
                         ({"max_events_per_step": 10**12}, "max_events_per_step")):
        status, answer = ask(server, "/check", json.dumps({"scene": scene}).encode() + b"\n", {"Origin": "null"})
        assert status == 400 and f"may not set {field}" in answer["summary"], answer
        assert str(server.folder) not in answer["summary"]  # (the page is told its run's name, not the folder)
    status, answer = ask(server, "/check", b'{"scene": {"dt": ' + b"9" * 5000 + b"}}\n")
    assert status == 400 and "not readable JSON" in answer["summary"]
    status, answer = ask(server, "/check", b'{"scene": ' + b"[" * 5000 + b"]" * 5000 + b"}\n")
    assert status == 400 and "nested more deeply" in answer["summary"]
    connection = http.client.HTTPConnection("127.0.0.1", server.port, timeout=30)
    connection.putrequest("POST", "/check")
    connection.putheader("Content-Length", "\u00b2")
    connection.endheaders()
    answer = connection.getresponse()
    assert answer.status == 411
    connection.close()
    # a body sent slower than the read time allows, in all, is cut off
    serve_timeout, serve.READ_TIMEOUT = serve.READ_TIMEOUT, 1.0
    try:
        with socket.create_connection(("127.0.0.1", server.port), timeout=30) as slow:
            slow.sendall(f"POST /check HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nContent-Length: 100\r\n\r\n"
                         .encode())
            for _ in range(3):
                slow.sendall(b"x")
                threading.Event().wait(0.5)
            assert b" 408 " in slow.recv(4096)
    finally:
        serve.READ_TIMEOUT = serve_timeout
    assert ask(server, "/ping")[0] == 200  # still serving


def test_the_server_keeps_runs_apart_from_another_session_s(tmp_path):
    kept = tmp_path / "kept"
    (kept / "0007-bounce").mkdir(parents=True)
    with pytest.raises(Exception, match="holds runs of another session; --force adds to it"):
        CheckServer(kept, port=0)
    srv = CheckServer(kept, port=0, force=True)
    try:
        job = srv.submit("bounce.jsonl", b"")
        assert job.number == 8  # after the runs kept there: none is written over
    finally:
        srv.http.server_close()
    refused = CliRunner().invoke(app, ["check-run", "--serve", "--port", "0", "--keep", str(kept)])
    assert refused.exit_code == 2 and "--force adds to it" in refused.output and "Traceback" not in refused.output
