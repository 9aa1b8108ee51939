"""The CLI through typer's CliRunner: output, JSON, exit codes, errors without tracebacks."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from physdbg import api
from physdbg.cli import app
from physdbg.scenes import builtin_names

runner = CliRunner()


def invoke(*args):
    result = runner.invoke(app, list(args))
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    return result


def test_scenes_lists_every_built_in_with_one_line_each():
    result = invoke("scenes")
    assert result.exit_code == 0
    lines = result.output.strip().splitlines()
    assert [line.split()[0] for line in lines] == builtin_names()
    assert all(len(line.split(None, 1)) == 2 for line in lines)


def test_run_prints_the_summary():
    result = invoke("run", "bounce")
    assert result.exit_code == 0
    for words in ("steps       300", "contacts    37", "relative change", "ms/step", "state hash", "brute-force",
                  "warnings    none"):
        assert words in result.output


def test_the_summary_counts_the_held_contacts_let_go_as_the_steps_do():
    """`run`'s contacts line: rapid and released over the run, each the sum of the steps'."""
    from physdbg.api import load_scene

    options = ["generate.count=300", "steps=150", "rapid_contact_time=1e-4", "rapid_contact_rule=hold",
               "sleep_speed=0"]  # the engine's rules
    scene = load_scene("rain", options)
    world = scene.build_world()
    steps = [world.step(dt) for dt in scene.step_lengths(None)]
    rapid, released = sum(s.counts.rapid for s in steps), sum(s.counts.released for s in steps)
    assert released > 0  # a pile forms: some held contacts come apart again
    result = invoke("run", "rain", *[f"--set={o}" for o in options])
    assert f"{rapid} rapid, {released} released; {world.held_count} held at the end" in result.output


def test_run_says_how_many_spheres_fell_asleep_only_when_sleeping_is_on():
    result = invoke("run", "bounce", "--set", "sleep_speed=0.05", "--set", "sleep_time=0.1")
    assert result.exit_code == 0
    assert "sleep       1 of 1 spheres asleep at the end  (1 fell asleep, 0 woke)" in result.output
    assert "sleep " not in invoke("run", "bounce").output


def test_the_speed_line_keeps_the_engine_apart_from_what_observes_it(tmp_path):
    """The engine's own ms/step (its five phases) comes first; the whole loop's, with the
    audit (run) or the recording and the audit (record), second. A recorder's work once
    made `record bounce` read as ten times slower an engine than `run bounce`."""
    import re

    pattern = r"speed       ([0-9.]+) ms/step in the engine \(forces .*\); ([0-9.]+) ms/step with {}; kernels"
    run = re.search(pattern.format("the audit"), invoke("run", "bounce").output)
    record = invoke("record", "bounce", "-o", str(tmp_path / "b.mcap"), "--no-rrd").output
    recorded = re.search(pattern.format("the recording and the audit"), record)
    assert run and recorded, record
    for found in (run, recorded):
        assert 0.0 < float(found.group(1)) <= float(found.group(2))


def test_run_json_is_machine_readable_and_repeats_exactly():
    first = json.loads(invoke("run", "cradle", "--json").output)
    second = json.loads(invoke("run", "cradle", "--json").output)
    assert first["steps"] == 180 and first["contacts"] == 4
    assert first["energy_drift"] == 0.0
    assert first["final_hash"] == second["final_hash"]
    assert set(first["phase_seconds"]) == {"forces", "broad_phase", "narrow_phase", "resolve", "finish"}


def test_overrides_change_the_run():
    exact = json.loads(invoke("run", "bullet-wall", "--json", "--set", "steps=1").output)
    tunnel = json.loads(invoke("run", "bullet-wall", "--json", "--set", "steps=1", "-s", "detection=discrete").output)
    assert exact["contacts"] == 1 and tunnel["contacts"] == 0
    assert tunnel["detection"] == "discrete"


@pytest.mark.parametrize("args, words", [
    (["run", "nosuchscene"], "no built-in scene or file called 'nosuchscene'"),
    (["run", "bounce", "--set", "integrator=rk4"], "field 'integrator'"),
    (["run", "bounce", "--set", "nonsense"], "key=value"),
])
def test_bad_input_is_one_clear_line_and_exit_code_2(args, words):
    result = invoke(*args)
    assert result.exit_code == 2
    assert words in result.output
    assert result.output.startswith("error: ")


def test_bad_scene_file_names_the_file(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text("dt = 0.1\nsteps = 2\nintegrator = 'rk4'\n")
    result = invoke("run", str(path))
    assert result.exit_code == 2
    assert f"{path}: field 'integrator'" in result.output


def test_real_time_run_can_be_repeated_exactly_from_its_dts(tmp_path):
    scene = tmp_path / "real.toml"
    scene.write_text('dt = "real"\nsteps = 40\ngravity = [0, -9.81, 0]\n'
                     "[[particles]]\nposition = [0, 0.5, 0]\nradius = 0.1\nrestitution = 0.7\n"
                     "[[planes]]\nnormal = [0, 1, 0]\n")
    dts = tmp_path / "dts.txt"
    live = json.loads(invoke("run", str(scene), "--json", "--dts-out", str(dts)).output)
    assert len(dts.read_text().split()) == 40
    assert len(set(live["dts"])) > 1  # real elapsed time: the steps differ
    again = json.loads(invoke("run", str(scene), "--json", "--dts", str(dts)).output)
    assert again["final_hash"] == live["final_hash"]
    assert again["dts"] == live["dts"]


def test_bad_dts_file_is_explained(tmp_path):
    dts = tmp_path / "dts.txt"
    dts.write_text("0.1\n-3\n")
    result = invoke("run", "bounce", "--dts", str(dts))
    assert result.exit_code == 2
    assert "entry 2" in result.output
    missing = invoke("run", "bounce", "--dts", str(tmp_path / "missing.txt"))
    assert missing.exit_code == 2 and "cannot read" in missing.output


def test_every_command_is_documented_with_an_example():
    result = invoke("--help")
    assert result.exit_code == 0
    for command in ("scenes", "run", "record", "replay", "info"):
        assert command in result.output
        help_text = invoke(command, "--help").output
        assert "Example: physdbg " + command in help_text


def test_help_does_not_import_the_engine():
    code = ("import sys; from physdbg.cli import app\n"
            "try:\n    app(['--help'])\nexcept SystemExit:\n    pass\n"
            "print('numba' in sys.modules, 'numpy' in sys.modules, 'rerun' in sys.modules, 'mcap' in sys.modules, 'rich' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "False False False False False"


@pytest.mark.slow
def test_console_script_runs(tmp_path):
    exe = [sys.executable, "-m", "physdbg.cli", "run", "cradle", "--set", "steps=3"]
    out = subprocess.run(exe, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "steps       3" in out.stdout
    bad = subprocess.run(exe[:3] + ["run", "nope"], capture_output=True, text=True)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and "error:" in bad.stderr
    # ``python -m physdbg`` is the same command line
    package = subprocess.run([sys.executable, "-m", "physdbg", "--help"], capture_output=True, text=True)
    assert package.returncode == 0 and "Usage: physdbg" in package.stdout and "record" in package.stdout
    # the installed ``physdbg`` is the same entry point (which also settles the garbage collector)
    from importlib.metadata import entry_points

    (script,) = [e for e in entry_points(group="console_scripts") if e.name == "physdbg"]
    assert script.value == "physdbg.cli:console_main"


def test_long_runs_show_progress_on_stderr_and_keep_stdout_clean(monkeypatch):
    from physdbg import cli

    monkeypatch.setattr(cli._progress_bar, "AFTER_SECONDS", 0.0)  # "long": past the first second
    result = invoke("run", "bounce", "--progress", "--set", "steps=20")  # whatever the step count
    assert result.exit_code == 0
    assert "step 20/20" in result.stderr
    assert result.stdout.startswith("scene ")
    quiet = invoke("run", "bounce", "--no-progress", "--set", "steps=20")
    assert "step 20/20" not in quiet.stderr


def test_short_runs_show_no_bar():
    result = invoke("run", "bounce", "--progress", "--set", "steps=20")
    assert "step 20/20" not in result.stderr


def test_a_slow_first_compile_says_what_it_is_doing(monkeypatch):
    import time

    from physdbg import cli, precompile

    monkeypatch.setattr(cli._progress_bar, "AFTER_SECONDS", 0.05)
    real = precompile.compile_kernels
    monkeypatch.setattr(precompile, "compile_kernels", lambda *a, **k: (time.sleep(0.3), real(*a, **k))[1])
    result = invoke("run", "bounce", "--no-progress", "--set", "steps=5")
    assert "compiling the engine's kernels" in result.stderr
    monkeypatch.setattr(precompile, "compile_kernels", real)
    assert "compiling" not in invoke("run", "bounce", "--set", "steps=5").stderr


def test_summary_says_which_broad_phase_auto_chose_and_why():
    rain = invoke("run", "rain", "--set", "steps=2", "--set", "generate.count=200")
    assert "broad phase grid: auto: 200 particles with similar radii" in rain.output
    small = invoke("run", "cradle", "--set", "steps=2")
    assert "broad phase brute-force: auto: 5 particles" in small.output
    chosen = invoke("run", "cradle", "--set", "steps=2", "--set", "broad_phase=bvh-lbvh")
    assert "broad phase bvh-lbvh: chosen in the scene" in chosen.output


# ----------------------------------------------------------------------------- record / replay / info
def test_record_writes_both_files_where_it_says_and_how_to_open_them(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = invoke("record", "cradle", "--set", "steps=60")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "recordings" / "cradle.mcap").stat().st_size > 0
    assert (tmp_path / "recordings" / "cradle.rrd").stat().st_size > 0
    assert "rerun recordings/cradle.rrd" in result.output and "recorded    60 steps" in result.output
    again = invoke("record", "cradle", "--set", "steps=60")
    assert again.exit_code == 2 and "already exists; pass --force" in again.output
    assert invoke("record", "cradle", "--set", "steps=10", "--force").exit_code == 0


def test_record_options_choose_paths_and_detail(tmp_path):
    out = tmp_path / "x" / "run.mcap"
    result = invoke("record", "bounce", "-s", "steps=30", "-o", str(out), "--no-rrd", "--detail", "state")
    assert result.exit_code == 0, result.output
    assert out.exists() and not out.with_suffix(".rrd").exists()
    info = invoke("info", str(out), "--json")
    data = json.loads(info.output)
    assert data["steps"] == 30 and data["detail"] == "state" and data["scene"] == "bounce"
    assert {c["topic"] for c in data["channels"]} >= {"/physdbg/state", "/physdbg/stats"}
    bad = invoke("record", "bounce", "--detail", "everything", "-o", str(tmp_path / "y.mcap"))
    assert bad.exit_code == 2 and "state, contacts, full" in bad.output


def test_info_prints_scene_settings_steps_channels_and_sizes(tmp_path):
    out = tmp_path / "b.mcap"
    invoke("record", "billiards", "-s", "steps=40", "-o", str(out), "--no-rrd")
    text = invoke("info", str(out)).output
    for words in ("scene       billiards", "integrator=exact", "steps       40", "/physdbg/contacts",
                  "bytes per particle-step", "final hash"):
        assert words in text, words


def test_info_and_run_say_how_a_kinematic_mesh_moves_and_that_it_does_work(tmp_path):
    out = tmp_path / "p.mcap"
    invoke("record", "paddle", "-s", "steps=3", "-o", str(out), "--no-rrd")
    motion = "meshes      'paddle' turns at 1080 deg/s (3 rev/s) about [0, 0.12, 0]"
    assert motion in invoke("info", str(out)).output
    run = invoke("run", "paddle", "-s", "steps=3").output
    assert motion in run
    # the energy the paddle puts in, beside an audit that judges contacts against its surface
    assert "a kinematic mesh's prescribed motion does work on what it strikes, so the audit judges each contact's " \
           "energy relative to the moving surface" in run
    assert "does work on what it strikes" not in invoke("run", "bounce", "-s", "steps=3").output


def test_replay_verifies_and_rebuilds_the_rerun_file(tmp_path):
    out = tmp_path / "g.mcap"
    invoke("record", "gas", "-s", "steps=40", "-o", str(out), "--no-rrd")
    result = invoke("replay", str(out), "--verify", "--rrd", str(tmp_path / "g.rrd"))
    assert result.exit_code == 0, result.output
    assert "verify      ok: 40 steps" in result.output and (tmp_path / "g.rrd").exists()
    assert invoke("replay", str(out)).exit_code == 2  # nothing asked


@pytest.mark.parametrize("content, words", [
    (b"not a recording at all", "not an MCAP file"),
    (b"\x89MCAP0\r\n" + b"\x00" * 40, "truncated before its first complete chunk"),
])
def test_foreign_or_broken_files_get_one_clear_line(tmp_path, content, words):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(content)
    for args in (("info", str(bad)), ("replay", str(bad), "--verify")):
        result = invoke(*args)
        assert result.exit_code == 2 and words in result.output, result.output


def test_a_damaged_chunk_is_reported_not_raised(tmp_path):
    out = tmp_path / "r.mcap"
    invoke("record", "rain", "-s", "steps=200", "-o", str(out), "--no-rrd", "--detail", "state")
    from mcap.reader import make_reader

    with open(out, "rb") as f:  # a chunk in the middle of the file that holds states
        summary = make_reader(f).get_summary()
    state_channel = next(i for i, c in summary.channels.items() if c.topic == "/physdbg/state")
    chunks = [c for c in summary.chunk_indexes if state_channel in c.message_index_offsets]
    chunk = chunks[len(chunks) // 2]
    data = bytearray(out.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle:middle + 64] = bytes(64)  # zeros over compressed chunk data
    out.write_bytes(bytes(data))
    for args in (("replay", str(out), "--verify"), ("replay", str(out), "--rrd", str(tmp_path / "r.rrd"))):
        result = invoke(*args)
        assert result.exit_code == 2 and "damaged" in result.output, result.output


@pytest.mark.slow
def test_replay_web_serves_the_recording_on_localhost_and_cleans_up_on_sigterm(tmp_path):
    import os
    import signal
    import socket
    import time
    import urllib.request

    pytest.importorskip("rerun_cli")
    out = tmp_path / "c.mcap"
    invoke("record", "cradle", "-s", "steps=20", "-o", str(out), "--no-rrd")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    scratch = tmp_path / "tmp"  # the replay's own temp folder: another physdbg beside this test has its own
    scratch.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "physdbg.cli", "replay", str(out), "--web", "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=dict(os.environ, CI="1", TMPDIR=str(scratch)))
    try:
        lines = [proc.stdout.readline() for _ in range(2)]
        url = lines[1].split()[1]
        # the URL opens the recording, not the welcome page
        assert url.startswith(f"http://127.0.0.1:{port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A"), lines
        deadline = time.time() + 60
        status = None
        while time.time() < deadline and status is None:
            try:
                status = urllib.request.urlopen(url, timeout=2).status
            except OSError:
                time.sleep(0.5)
        assert status == 200
        listening = subprocess.run(["ss", "-ltn"], capture_output=True, text=True).stdout
        ours = [line for line in listening.splitlines() if f":{port} " in line]
        assert ours and all("127.0.0.1:" in line for line in ours), ours  # localhost only
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
    time.sleep(0.5)
    with pytest.raises(OSError):
        urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2)  # the viewer child is gone
    assert list(scratch.iterdir()) == []  # no folder left


def test_record_caps_a_big_bvh_and_says_so(tmp_path):
    out = tmp_path / "b.mcap"
    result = invoke("record", "rain", "-s", "broad_phase=bvh-sah", "-s", "steps=5", "-o", str(out), "--no-rrd",
                    "--bvh-max-nodes", "30")
    assert result.exit_code == 0, result.output
    assert "note        BVH logged down to depth" in result.output and "--bvh-max-nodes 0" in result.output
    full = invoke("record", "rain", "-s", "broad_phase=bvh-sah", "-s", "steps=5", "-o", str(out), "--no-rrd",
                  "--bvh-max-nodes", "0", "--force")
    assert "note" not in full.output


def test_a_recording_held_to_max_memory_says_which_detail_needs_less(tmp_path):
    # At --detail full every swept test is kept: under this limit the log may not grow and
    # the steps say so; at --detail contacts only the hits are logged and the run is exact.
    args = ["rain", "-s", "generate.count=200", "-s", "steps=5", "-s", "max_memory=1.2e6", "--no-rrd"]
    full = invoke("record", *args, "-o", str(tmp_path / "full.mcap"))
    assert full.exit_code == 0, full.output
    assert "warnings    5 (5 max_memory)" in full.output
    assert "max_memory reached" in full.output and "or record below --detail full" in full.output
    explained = invoke("explain", str(tmp_path / "full.mcap"))
    assert "this step reached max_memory, so contacts after it were not resolved" in explained.output
    assert "record at --detail contacts" in explained.output
    lean = invoke("record", *args, "-o", str(tmp_path / "lean.mcap"), "--detail", "contacts")
    assert lean.exit_code == 0, lean.output
    assert "warnings    none" in lean.output and "audit       clean" in lean.output


def test_record_repeats_a_real_time_run_from_its_step_lengths(tmp_path):
    first = tmp_path / "rt.mcap"
    invoke("record", "bounce", "-s", "dt=real", "-s", "duration=0.1", "-o", str(first), "--no-rrd")
    from physdbg import open_recording

    rec = open_recording(first)
    dts = tmp_path / "dts.txt"
    dts.write_text("".join(f"{rec.state(k).dt!r}\n" for k in range(1, rec.frames)))
    again = tmp_path / "again.mcap"
    result = invoke("record", "bounce", "-s", "dt=real", "--dts", str(dts), "-o", str(again), "--no-rrd")
    assert result.exit_code == 0, result.output
    assert open_recording(again).state(-1).state_hash == rec.state(-1).state_hash


@pytest.mark.slow
def test_record_spawn_streams_to_a_viewer_it_starts(tmp_path, virtual_display):
    import os

    log = tmp_path / "stderr.txt"
    try:
        with open(log, "w") as err:  # a file, not a pipe: the detached viewer keeps its copy open
            done = subprocess.run([sys.executable, "-m", "physdbg.cli", "record", "cradle", "-s", "steps=30",
                                   "--spawn", "-o", str(tmp_path / "c.mcap")],
                                  env=dict(os.environ, DISPLAY=virtual_display, CI="1"), stdout=subprocess.DEVNULL,
                                  stderr=err, timeout=120)
        assert done.returncode == 0 and "Traceback" not in log.read_text(), log.read_text()[-2000:]
        assert (tmp_path / "c.rrd").stat().st_size > 0
        viewers = subprocess.run(["pgrep", "-f", "rerun_cli/rerun --port=9876"], capture_output=True, text=True)
        assert viewers.stdout.split(), "no viewer was started"
    finally:
        subprocess.run(["pkill", "-f", "rerun_cli/rerun --port=9876"], check=False)


@pytest.mark.slow
def test_output_into_a_closed_pipe_stops_quietly(tmp_path):
    """`physdbg ... | head` closes the pipe early: no 'internal error', no traceback."""
    import os
    import subprocess
    import sys

    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before the first line
    try:
        done = subprocess.run([sys.executable, "-m", "physdbg.cli", "bench", "accuracy", "--quick", "--problem",
                               "bounce", "--no-chart", "-o", str(tmp_path)], stdout=write_end,
                              stderr=subprocess.PIPE, text=True, timeout=60)
    finally:
        os.close(write_end)
    assert "internal error" not in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert done.returncode in (0, 1)  # click's own handling of a closed pipe: exit 1, nothing printed


@pytest.mark.parametrize("command", [["replay", "{mcap}", "--rrd", "/proc/physdbg-test.rrd"],
                                     ["record", "bounce", "-s", "steps=5", "-o", "/proc/physdbg-test.mcap"],
                                     ["diff", "{mcap}", "{mcap}", "--rrd", "/proc/physdbg-test.rrd"]])
def test_an_output_that_cannot_be_written_is_one_line_and_exit_2(tmp_path, command):
    """/proc takes no new files, even from root (a chmod'ed folder would not stop root)."""
    mcap = tmp_path / "b.mcap"
    api.record("bounce", ["steps=5"], mcap_path=str(mcap), rrd=False)
    result = CliRunner().invoke(app, [part.format(mcap=mcap) for part in command])
    assert result.exit_code == 2, result.output
    assert "cannot write in /proc" in result.output and "internal error" not in result.output


def test_scenes_as_json_and_the_progress_option_shows_one_default():
    from typer.testing import CliRunner

    from physdbg.cli import app
    from physdbg.scenes import builtin_names

    listed = CliRunner().invoke(app, ["scenes", "--json"])
    assert listed.exit_code == 0
    rows = json.loads(listed.output)
    assert [row["name"] for row in rows] == builtin_names() and all(row["description"] for row in rows)
    for command in ("run", "record"):
        shown = CliRunner().invoke(app, [command, "--help"], terminal_width=200).output
        assert "(default: when stderr is a terminal)" in shown and "[default: no-progress]" not in shown \
            and "[default: progress]" not in shown


def test_run_fails_on_findings_only_when_asked():
    """For CI: a run that finished exits 0 with findings unless --fail-on-findings."""
    tunnels = ["run", "bullet-wall", "-s", "detection=discrete"]
    assert runner.invoke(app, tunnels).exit_code == 0
    done = runner.invoke(app, tunnels + ["--fail-on-findings"])
    assert done.exit_code == 1 and "1 tunnelling" in done.output
    assert runner.invoke(app, ["run", "bullet-wall", "--fail-on-findings"]).exit_code == 0


@pytest.mark.parametrize("args", [["run", "nosuch", "--json"], ["check", "nosuch", "--json"],
                                  ["info", "nosuch.mcap", "--json"], ["explain", "nosuch.mcap", "--json"],
                                  ["diff", "a.mcap", "b.mcap", "--format", "json"]])
def test_errors_under_json_are_json_with_the_versions(args, tmp_path, monkeypatch):
    import json

    monkeypatch.chdir(tmp_path)
    done = runner.invoke(app, args)  # stdout alone (click 8.2): the error line went to stderr
    assert done.exit_code == 2
    data = json.loads(done.stdout)
    assert data["exit_code"] == 2 and data["error"] and data["physdbg_version"] and data["format_version"]


def test_json_reports_carry_the_physdbg_and_format_versions():
    import json

    from physdbg.record.format import FORMAT_VERSION
    from physdbg.version import __version__

    for args in (["run", "bounce", "-s", "steps=5", "--json"], ["check", "bounce", "--json"]):
        data = json.loads(runner.invoke(app, args).stdout)
        assert data["physdbg_version"] == __version__ and data["format_version"] == FORMAT_VERSION


def test_shell_completion_offers_scene_names_files_and_set_keys(tmp_path, monkeypatch):
    from physdbg.cli import _complete_scene, _complete_set

    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.toml").write_text("dt = 0.01\n")
    assert _complete_scene("bo") == ["bounce"]
    assert "mine.toml" in _complete_scene("")
    assert _complete_set("generate.co") == ["generate.count="]
    assert "particles.0.radius=" in _complete_set("particles.0.r") and "generate=" not in _complete_set("gen")
    done = subprocess.run([sys.executable, "-m", "physdbg"], env={**os.environ, "_PHYSDBG_COMPLETE": "complete_bash",
                                                                  "COMP_WORDS": "physdbg run bo", "COMP_CWORD": "2"},
                          capture_output=True, text=True, cwd=tmp_path)
    assert done.stdout.split() == ["bounce"], done.stdout + done.stderr
