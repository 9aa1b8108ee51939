"""physdbg-trace.js: a JavaScript engine written from the seed's slides (tests/js/), traced
under Node with the tracer `physdbg trace-js` writes, and its runs checked by check-run."""

from __future__ import annotations

import json
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import api
from physdbg.api import load_scene
from physdbg.cli import app
from physdbg.scene import scene_table

ROOT = Path(__file__).resolve().parents[1]
NODE = shutil.which("node")
needs_node = pytest.mark.skipif(NODE is None, reason="Node.js is not installed: the JavaScript tracer is not run")


def dump_scene(scene, path: Path, steps: int) -> None:
    """The scene as the JavaScript engine reads it: physdbg's scene table (what `physdbg
    scenes show NAME --format json` prints), run for ``steps`` steps."""
    path.write_text(json.dumps({**scene_table(scene), "steps": steps}))


@pytest.fixture(scope="module")
def tracer(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("js")
    result = CliRunner().invoke(app, ["trace-js", "-o", str(folder)])
    assert result.exit_code == 0, result.output
    assert f"wrote       {folder / 'physdbg-trace.js'}" in result.output
    return folder / "physdbg-trace.js"


def run_js(tracer: Path, scene, steps: int, out: Path, *flags: str) -> Path:
    dump_scene(scene, out.with_suffix(".scene.json"), steps)
    done = subprocess.run([NODE, str(ROOT / "tests" / "js" / "student_engine.js"), str(out.with_suffix(".scene.json")),
                           str(out), *flags], capture_output=True, text=True, env={"PHYSDBG_TRACE": str(tracer)},
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(out)
    return out


def test_trace_js_writes_the_tracer_and_never_overwrites_it_without_force(tmp_path):
    first = CliRunner().invoke(app, ["trace-js", "-o", str(tmp_path)])
    assert first.exit_code == 0 and (tmp_path / "physdbg-trace.js").read_text().startswith("// physdbg-trace.js")
    again = CliRunner().invoke(app, ["trace-js", "-o", str(tmp_path)])
    assert again.exit_code == 2 and "exists; --force replaces it" in again.output
    assert CliRunner().invoke(app, ["trace-js", "-o", str(tmp_path), "--force"]).exit_code == 0
    assert api.write_trace_js(tmp_path / "new").name == "physdbg-trace.js"


@needs_node
@pytest.mark.parametrize("name", ["bounce", "cradle", "billiards"])
def test_a_right_javascript_engine_traced_under_node_is_same(tracer, tmp_path, name):
    scene = load_scene(name, ["integrator=euler"])
    steps = scene.steps or round(scene.duration / scene.dt)
    steps = min(steps, 240)
    run = run_js(tracer, scene, steps, tmp_path / f"{name}.jsonl")
    report = api.check_run(run, name, ["integrator=euler"]).report
    assert report.exit_code == 0 and report.set_aside == [], report.headline  # no pile: no rapid-contact rule
    assert report.steps == steps
    if name == "billiards":  # the break, with the rule on as a scene may ask: named, not blamed
        ruled = api.check_run(run, name, ["integrator=euler", "rapid_contact_time=1e-4"]).report
        assert ruled.exit_code == 0 and [a["rule"] for a in ruled.set_aside] == ["rapid-contact"]


@needs_node
def test_a_javascript_clock_in_milliseconds_is_named(tracer, tmp_path):
    scene = load_scene("bounce", ["integrator=euler", "steps=30"])
    run = run_js(tracer, scene, 30, tmp_path / "ms.jsonl", "--ms")
    result = CliRunner().invoke(app, ["check-run", str(run), "--scene", "bounce", "--set", "integrator=euler",
                                      "--set", "steps=30"])
    assert result.exit_code == 2 and "time column counts milliseconds" in result.output
    again = CliRunner().invoke(app, ["check-run", str(run), "--scene", "bounce", "--set", "integrator=euler",
                                     "--set", "steps=30", "--time-unit", "ms"])
    assert again.exit_code == 0, again.output


@needs_node
def test_nan_and_infinity_reach_check_run_as_what_they_were(tracer, tmp_path):
    """JSON has neither; the tracer writes them as strings, check-run reads them back."""
    script = tmp_path / "blow.js"
    out = tmp_path / "blow.jsonl"
    script.write_text(f"""
const t = require({json.dumps(str(tracer))}).start("bounce", {{file: {json.dumps(str(out))}}});
t.frame(0, new Float64Array([0, 1, 0]), [[0, 0, 0]]);
t.frame(1 / 60, [[0, NaN, 0]], [[Infinity, -Infinity, 0]]);
t.finish();
""")
    done = subprocess.run([NODE, str(script)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    head, *lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert head == {"scene": "bounce"}  # the run's scene, on its first line
    assert lines[0] == {"step": 0, "time": 0, "positions": [[0, 1, 0]], "velocities": [[0, 0, 0]]}
    assert lines[1]["positions"] == [[0, "NaN", 0]] and lines[1]["velocities"] == [["Infinity", "-Infinity", 0]]
    from physdbg.record.foreign import read_run

    run = read_run(out, 1)
    assert np.isnan(run.positions[1, 0, 1]) and run.velocities[1, 0, 0] == np.inf and run.velocities[1, 0, 1] == -np.inf


# ----------------------------------------------------------------------------- a real browser
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# (no --dump-dom here: it ends the browser once the page has loaded, which may be before
# the download it started is written; the test waits for the file and then ends it)
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync")


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (.ci/run installs Debian's chromium): "
                                             "the browser test is skipped; the same engine runs under Node above")
@pytest.mark.parametrize("name", ["bounce", "billiards"])
def test_a_javascript_engine_in_headless_chromium_downloads_a_run_check_run_finds_same(tracer, tmp_path, name):
    """The page a student writes: the tracer and the engine as <script>s, finish() downloads
    the run; the downloaded file goes through check-run."""
    scene = load_scene(name, ["integrator=euler"])
    steps = min(scene.steps or round(scene.duration / scene.dt), 480)
    dump_scene(scene, tmp_path / "scene.json", steps)
    site = tmp_path / "site"
    site.mkdir()
    shutil.copy(tracer, site / "physdbg-trace.js")
    shutil.copy(ROOT / "tests" / "js" / "student_engine.js", site / "student_engine.js")
    (site / "index.html").write_text(
        "<!doctype html><html><body>\n<script src=\"physdbg-trace.js\"></script>\n"
        "<script src=\"student_engine.js\"></script>\n"
        f"<script>studentEngine.run({(tmp_path / 'scene.json').read_text()}).finish(); "
        "document.title = 'traced';</script>\n</body></html>\n")
    downloads, profile = tmp_path / "downloads", tmp_path / "profile"
    (profile / "Default").mkdir(parents=True)
    # where the headless browser saves a download, without asking
    (profile / "Default" / "Preferences").write_text(json.dumps({
        "download": {"default_directory": str(downloads), "prompt_for_download": False},
        "profile": {"default_content_setting_values": {"automatic_downloads": 1}}}))
    run = downloads / f"{name}.jsonl"
    # the headless browser stays open after the page is done: wait for the finished
    # download (Chromium writes it as .crdownload, then renames it), then close it
    browser = subprocess.Popen([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                                (site / "index.html").as_uri()], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not run.is_file() and browser.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
    finally:
        browser.kill()
        _, err = browser.communicate()
    assert run.is_file(), (f"no download in {downloads}: {sorted(p.name for p in downloads.glob('*'))}; "
                           f"{err.decode(errors='replace')[-2000:]}")
    report = api.check_run(run, name, ["integrator=euler"]).report
    assert report.exit_code == 0 and report.steps == steps, report.headline


THREE_BALLS = {  # a student's own scene, not a built-in: three balls rolling down onto a tilted plane
    "name": "three-balls", "dt": 1 / 120, "steps": 240, "integrator": "euler", "gravity": [0, -9.81, 0],
    "drag": 0.9,
    "particles": [
        {"position": [-0.5, 1.0, 0.0], "velocity": [1.0, 0.0, 0.0], "radius": 0.1, "mass": 1.0, "restitution": 0.9},
        {"position": [0.0, 1.2, 0.0], "velocity": [0.0, 0.0, 0.0], "radius": 0.1, "mass": 2.0, "restitution": 0.9},
        {"position": [0.6, 0.9, 0.1], "velocity": [-1.0, 0.5, 0.0], "radius": 0.15, "mass": 1.5, "restitution": 0.7},
    ],
    "planes": [{"name": "tilted", "normal": [0.2, 1.0, 0.0], "offset": -0.2, "restitution": 0.8}],
}


@needs_node
def test_a_trace_carrying_its_own_scene_is_checked_without_scene(tmp_path):
    """A scene of the student's own, as a plain object: the run carries it on its first line,
    check-run reads it (and says so), compares with the integrator it names: SAME; the same
    run with its mistake departs. No --scene anywhere."""
    scene_file = tmp_path / "three.json"
    scene_file.write_text(json.dumps(THREE_BALLS))
    tracer = api.write_trace_js(tmp_path)
    for mistake in (None, "impulse-doubled"):
        out = tmp_path / f"three-{mistake or 'right'}.jsonl"
        done = subprocess.run([NODE, str(ROOT / "tests" / "js" / "student_engine.js"), str(scene_file), str(out),
                               *(["--mistake", mistake] if mistake else [])], capture_output=True, text=True,
                              env={"PHYSDBG_TRACE": str(tracer)}, timeout=120)
        assert done.returncode == 0, done.stderr
        assert json.loads(out.read_text().splitlines()[0]) == {"scene": THREE_BALLS}
        result = CliRunner().invoke(app, ["check-run", str(out)])
        assert "the scene is the one the run carries on its first line ('three-balls': 3 spheres, 1 plane), " \
               "compared with its own integrator (euler)" in result.output
        if mistake is None:
            assert result.exit_code == 0 and "SAME" in result.output, result.output
        else:
            assert result.exit_code == 1 and "impulse applied twice" in result.output, result.output


def test_a_bad_scene_object_gets_the_one_line_error_a_toml_scene_gets(tmp_path):
    bad = {**THREE_BALLS, "particles": [{**THREE_BALLS["particles"][0], "radius": -1}]}
    run = tmp_path / "bad.jsonl"
    run.write_text(json.dumps({"scene": bad}) + "\n" + json.dumps({"step": 0, "time": 0, "positions": [[0, 1, 0]]}))
    result = CliRunner().invoke(app, ["check-run", str(run)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"{run}, line 1 (the run's scene): field 'particles.0.radius'" in result.output
    none = tmp_path / "none.jsonl"
    none.write_text(json.dumps({"step": 0, "time": 0, "positions": [[0, 1, 0]]}) + "\n")
    result = CliRunner().invoke(app, ["check-run", str(none)])
    assert result.exit_code == 2 and "carries no scene" in result.output and "--scene" in result.output


@needs_node
def test_scenes_show_js_is_loaded_by_the_javascript_engine_and_its_run_is_same(tmp_path):
    """`physdbg scenes show bounce --format js`, required under Node, is the scene the test
    engine runs; with scene.integrator = "euler" its run is SAME, with no --scene."""
    shown = CliRunner().invoke(app, ["scenes", "show", "bounce", "--format", "js"])
    assert shown.exit_code == 0
    (tmp_path / "bounce-scene.js").write_text(shown.output)
    tracer = api.write_trace_js(tmp_path)
    script = tmp_path / "run.js"
    script.write_text(f"""
const scene = require({json.dumps(str(tmp_path / 'bounce-scene.js'))});
scene.integrator = "euler";
global.physdbgTrace = require({json.dumps(str(tracer))});
require({json.dumps(str(ROOT / 'tests' / 'js' / 'student_engine.js'))});
console.log(globalThis.studentEngine.run(scene, {{file: {json.dumps(str(tmp_path / 'bounce.jsonl'))}}}).finish());
""")
    done = subprocess.run([NODE, str(script)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    report = api.check_run(tmp_path / "bounce.jsonl").report
    assert report.exit_code == 0 and report.steps == 300, report.headline


def test_scenes_show_prints_a_scene_as_toml_json_and_js(tmp_path):
    from physdbg.scene import read_scene, scene_from_dict

    toml = CliRunner().invoke(app, ["scenes", "show", "cradle"])
    assert toml.exit_code == 0 and toml.output.startswith('name = "cradle"')
    shown = CliRunner().invoke(app, ["scenes", "show", "billiards", "--format", "json"])
    table = json.loads(shown.output)
    assert len(table["particles"]) == 12 and len(table["planes"]) == 6  # the [box]'s cushions as planes
    again = scene_from_dict(table, "shown")
    assert np.array_equal(again.state.positions, read_scene("billiards").state.positions)
    assert again.settings == read_scene("billiards").settings and again.dt == read_scene("billiards").dt
    for args, words in ((["funnel", "--format", "json"], "meshes"), (["bounce", "--format", "yaml"], "one of toml"),
                        (["bounc"], "Did you mean 'bounce'"), (["bounce", "-s", "dt=2"], "--format json or js")):
        refused = CliRunner().invoke(app, ["scenes", "show", *args])
        assert refused.exit_code == 2 and words in refused.output and "Traceback" not in refused.output, args
    overridden = json.loads(CliRunner().invoke(app, ["scenes", "show", "bounce", "--format", "json", "-s",
                                                     "integrator=euler"]).output)
    assert overridden["integrator"] == "euler"


def test_date_now_clocks_in_whole_milliseconds_and_repeated_times_are_named_as_milliseconds(tmp_path):
    """Date.now() as it really is: whole milliseconds (0, 17, 33, 50, ...) where dt is 1/60 s,
    and a loop faster than the clock (0, 0, 0, ...): each named in one line with the fix."""
    from tests.student_engine import simulate_swept

    scene = load_scene("bounce", ["integrator=euler", "steps=60"])
    times, xs, vs = simulate_swept(scene, 60, scene.dt)
    for label, clock, words in (("whole", [round(t * 1000) for t in times], "a clock in whole milliseconds"),
                                ("stuck", [0] * len(times), "the same as the step before; time must increase. "
                                                            "A clock that counts whole milliseconds")):
        run = tmp_path / f"{label}.jsonl"
        run.write_text("".join(json.dumps({"step": k, "time": clock[k], "positions": xs[k].tolist(),
                                           "velocities": vs[k].tolist()}) + "\n" for k in range(len(times))))
        result = CliRunner().invoke(app, ["check-run", str(run), "--scene", "bounce", "-s", "integrator=euler",
                                          "-s", "steps=60"])
        assert result.exit_code == 2 and words in result.output and "Traceback" not in result.output, result.output
        assert "simulated time in seconds" in result.output and len(result.output.strip().splitlines()) == 1


def test_a_class_of_runs_that_carry_their_scenes_needs_no_scene(tmp_path):
    from physdbg.scene import scene_table
    from tests.student_engine import simulate_swept

    folder = tmp_path / "class"
    folder.mkdir()
    for name in ("bounce", "cradle"):
        scene = load_scene(name, ["integrator=euler", "steps=60"])
        times, xs, vs = simulate_swept(scene, 60, scene.dt)
        (folder / f"{name}.jsonl").write_text(json.dumps({"scene": scene_table(scene)}) + "\n" + "".join(
            json.dumps({"step": k, "time": float(t), "positions": xs[k].tolist(), "velocities": vs[k].tolist()}) + "\n"
            for k, t in enumerate(times)))
    result = CliRunner().invoke(app, ["check-run", str(folder), "-j", "1"])
    assert result.exit_code == 0, result.output
    assert "2 runs of each run's own scene: 2 same" in result.output


def test_check_run_of_a_missing_run_says_so_with_or_without_scene(tmp_path):
    for args in ([], ["--scene", "bounce"]):
        result = CliRunner().invoke(app, ["check-run", str(tmp_path / "gone.jsonl"), *args])
        assert result.exit_code == 2 and "gone.jsonl: no such file" in result.output, (args, result.output)
