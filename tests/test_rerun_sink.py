"""The Rerun picture: read back with rerun's own reader, replayed from MCAP, and shown in
the real viewer under Xvfb."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from physdbg import api, open_recording
from physdbg.events import StepEnd
from physdbg.observe import FanOut, ListObserver
from physdbg.record import RecordingHeader
from physdbg.record.mcap_sink import McapRecorder
from physdbg.record.rerun_sink import RerunSink, viewer_binary
from physdbg.api import load_scene

rerun_chunk = pytest.importorskip("rerun.chunk")


def read_rrd(path: Path) -> dict:
    """{(entity, step): {component: value}} of every temporal row of the recording."""
    reader = rerun_chunk.RrdReader(path)
    rows: dict = {}
    for chunk in reader.stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        steps = batch.column("step").to_pylist()
        for name in names:
            if ":" not in name or name.startswith("rerun."):  # timelines (step, sim_time, the opening's)
                continue
            for step, value in zip(steps, batch.column(name).to_pylist(), strict=True):
                rows.setdefault((chunk.entity_path, step), {}).setdefault(name, []).append(value)
    return rows


@pytest.fixture(scope="module")
def billiards_live(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("live")
    scene = load_scene("billiards", ["steps=120"])
    header = RecordingHeader.from_scene(scene)
    live = ListObserver()
    mcap, rrd = tmp / "b.mcap", tmp / "b.rrd"
    sinks = [McapRecorder(mcap, header), RerunSink(header, rrd)]
    api.run(scene, observer=FanOut(*sinks, live))
    for sink in sinks:
        sink.close()
    return mcap, rrd, live


def test_the_rrd_holds_the_engines_positions_at_every_step_and_a_blueprint(billiards_live):
    _, rrd, live = billiards_live
    reader = rerun_chunk.RrdReader(rrd)
    # the default blueprint, then the one that opens the file paused at the first contact
    assert len(reader.blueprints()) == 2 and len(reader.recordings()) == 1
    rows = read_rrd(rrd)
    ends = live.of_type(StepEnd)
    first = next(k for k, event in enumerate(ends) if event.counts.contacts) + 1
    opening = [value for chunk in reader.stream() if not chunk.is_static
               and "from first contact" in chunk.to_record_batch().schema.names
               for value in chunk.to_record_batch().column("from first contact").to_pylist()]
    assert min(opening) == first  # the timeline the file opens on begins at the first contact
    labels = rows[("/world/spheres", 0)]["Points3D:labels"][0]
    assert labels == [str(i) for i in range(len(ends[0].positions))]  # every sphere numbered
    for k in (1, 17, 60, 120):
        got = np.array(rows[("/world/spheres", k)]["Points3D:positions"][-1], dtype=np.float32)
        np.testing.assert_array_equal(got, ends[k - 1].positions.astype(np.float32))
    for name in ("contacts", "rapid", "released"):
        assert rows[(f"/stats/{name}", 60)]["Scalars:scalars"][0] == [getattr(ends[59].counts, name)]
    logged = [text for (entity, _), comps in rows.items() if entity == "/log"
              for row in comps.get("TextLog:text", []) for text in row]
    first = live.contacts[0]
    assert any(f"step {first.step}: sphere {first.a} hit" in text for text in logged)


def test_replay_from_mcap_alone_draws_the_same_picture_as_the_live_run(billiards_live, tmp_path):
    mcap, rrd, _ = billiards_live
    again = tmp_path / "replayed.rrd"
    api.replay(mcap, str(again))
    live_rows, replay_rows = read_rrd(rrd), read_rrd(again)
    assert live_rows.keys() == replay_rows.keys()
    assert live_rows == replay_rows


def test_replay_at_a_step_opens_the_file_paused_there(billiards_live, tmp_path):
    """`physdbg replay FILE --rrd OUT --at 40`: the final blueprint opens the timeline "from
    step 40", which begins at step 40; a step the file does not hold, or --at with nothing
    to draw, is one clear line."""
    from typer.testing import CliRunner

    from physdbg.cli import app

    mcap, _, _ = billiards_live
    out = tmp_path / "at40.rrd"
    done = CliRunner().invoke(app, ["replay", str(mcap), "--rrd", str(out), "--at", "40"])
    assert done.exit_code == 0, done.output
    reader = rerun_chunk.RrdReader(out)
    assert len(reader.blueprints()) == 2
    opening = [value for chunk in reader.stream() if not chunk.is_static
               and "from step 40" in chunk.to_record_batch().schema.names
               for value in chunk.to_record_batch().column("from step 40").to_pylist()]
    assert min(opening) == 40 and max(opening) == 120
    done = CliRunner().invoke(app, ["replay", str(mcap), "--rrd", str(tmp_path / "x.rrd"), "--at", "500"])
    assert done.exit_code == 2 and "--at 500: " in done.output and "holds steps 1..120" in done.output
    assert not (tmp_path / "x.rrd").exists()
    done = CliRunner().invoke(app, ["replay", str(mcap), "--verify", "--at", "5"])
    assert done.exit_code == 2 and "--at opens the view at a step: give it with --rrd FILE" in done.output


def test_replay_never_overwrites_without_force(billiards_live, tmp_path):
    mcap, _, _ = billiards_live
    out = tmp_path / "x.rrd"
    out.write_text("keep me")
    with pytest.raises(api.PhysdbgError, match="--force"):
        api.replay(mcap, str(out))
    assert out.read_text() == "keep me"


@pytest.mark.slow
def test_the_real_viewer_opens_the_recording_on_a_picture_that_is_not_blank(tmp_path, virtual_display):
    from PIL import Image

    rec = api.record("cradle", ["steps=100"], mcap_path=str(tmp_path / "c.mcap"), rrd_path=str(tmp_path / "c.rrd"))
    shot = tmp_path / "shot.png"
    done = subprocess.run([viewer_binary(), rec.rrd, "--new", "--screenshot-to", str(shot),
                           "--window-size", "1200x750"],
                          env=dict(os.environ, DISPLAY=virtual_display, CI="1"), capture_output=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    image = np.asarray(Image.open(shot).convert("RGB"))
    height, width, _ = image.shape
    assert width >= 1000 and height >= 600
    colours = len(np.unique(image.reshape(-1, 3), axis=0))
    assert colours > 200  # text, plots and shaded spheres, not a blank window
    scene_view = image[: int(height * 0.75), : int(width * 0.6)]
    orange = (scene_view[..., 0] > 200) & (scene_view[..., 1] > 90) & (scene_view[..., 1] < 190) & \
             (scene_view[..., 2] < 110)
    assert orange.sum() > 500  # the spheres are in the 3D view
    shutil.copy(shot, Path(rec.rrd).with_suffix(".png"))
    assert open_recording(rec.mcap).steps == 100


def test_each_path_runs_from_the_start_of_the_step_through_its_contacts_to_the_end(billiards_live):
    _, rrd, live = billiards_live
    rows = read_rrd(rrd)
    ends = live.of_type(StepEnd)
    first = live.contacts[0]
    frame = first.step
    strips = rows[("/world/paths", frame)]["LineStrips3D:strips"][0]
    assert len(strips) == 12  # every particle of a small scene has a path
    mine = [c for c in live.contacts if c.step == first.step]
    for particle in {first.a, first.other}:
        stops = [c for c in mine if particle in (c.a, c.other)]
        strip = np.array(strips[particle], dtype=np.float32)
        assert len(strip) == 2 + len(stops)
        np.testing.assert_array_equal(strip[0], ends[frame - 2].positions[particle].astype(np.float32))
        np.testing.assert_array_equal(strip[-1], ends[frame - 1].positions[particle].astype(np.float32))
    radius = load_scene("billiards").state.radius
    strip = np.array(strips[first.a], dtype=np.float32)
    np.testing.assert_allclose(strip[1], first.point + first.normal * radius[first.a], atol=1e-6)
    untouched = next(i for i in range(12) if all(i not in (c.a, c.other) for c in mine))
    assert len(strips[untouched]) == 2


def test_the_event_log_line_quoted_in_the_readme_is_what_cradle_writes(tmp_path):
    import re

    rec = api.record("cradle", mcap_path=str(tmp_path / "c.mcap"), rrd_path=str(tmp_path / "c.rrd"))
    rows = read_rrd(Path(rec.rrd))
    readme = " ".join((Path(__file__).resolve().parents[1] / "README.md").read_text().split())
    quoted = re.search(r"\(`(step 44: [^`]*)` in `physdbg record cradle`\)", readme).group(1)
    assert [quoted] in rows[("/log", 44)]["TextLog:text"]


def test_a_step_with_more_contacts_than_are_drawn_says_so(tmp_path, monkeypatch):
    from physdbg.record import view

    monkeypatch.setattr(view, "DRAWN_CONTACTS_PER_STEP", 2)
    monkeypatch.setattr(view, "LOG_LINES_PER_STEP", 1)
    rec = api.record("cradle", mcap_path=str(tmp_path / "c.mcap"), rrd_path=str(tmp_path / "c.rrd"))
    rows = read_rrd(Path(rec.rrd))
    ghosts = rows[("/world/contacts/ghosts", 44)]["Points3D:positions"][0]
    assert len(ghosts) == 2 and len(open_recording(rec.mcap).contacts(44)) == 4
    texts = [t for row in rows[("/log", 44)]["TextLog:text"] for t in row]
    assert "step 44: ... and 3 more contacts; ghosts and arrows for the first 2" in texts
    # sleeping is off in cradle: no flat-zero "asleep" series beside the contacts, and the
    # spheres keep the colours logged at the start (and again on the first contact's row,
    # where the timeline the file opens on begins), though the resting balls are exactly still
    assert not any(entity == "/stats/asleep" for entity, _ in rows)
    assert not any(entity == "/world/spheres" and step not in (0, 44) and "Points3D:colors" in comps
                   for (entity, step), comps in rows.items())


@pytest.mark.slow
def test_a_pile_falling_asleep_turns_grey_blue_live_and_replayed(tmp_path):
    """Sleeping spheres are drawn ASLEEP_COLOR from the step they fell asleep, and the log
    names who fell asleep and who woke; the MCAP state carries the mask, so the replay
    draws the same picture."""
    from physdbg.record.reader import open_recording
    from physdbg.record.view import ASLEEP_COLOR

    scene = load_scene("rain", ["generate.count=100", "box.max=[0.3,1,0.3]", "generate.speed=0",
                                "generate.restitution=0.5", "box.restitution=0.5", "rapid_contact_rule=tc",
                                "sleep_speed=0.05", "sleep_time=0.1", "steps=240"])
    header = RecordingHeader.from_scene(scene)
    mcap, rrd = tmp_path / "p.mcap", tmp_path / "p.rrd"
    sinks = [McapRecorder(mcap, header), RerunSink(header, rrd)]
    summary = api.run(scene, observer=FanOut(*sinks))
    for sink in sinks:
        sink.close()
    assert summary.asleep_at_end == 100
    rows = read_rrd(rrd)
    coloured = sorted(step for (entity, step), comps in rows.items()
                      if entity == "/world/spheres" and "Points3D:colors" in comps)
    assert coloured  # the colours change only when the still spheres do
    last = rows[("/world/spheres", coloured[-1])]["Points3D:colors"][-1]
    assert len(last) == 100
    packed = (ASLEEP_COLOR[0] << 24) | (ASLEEP_COLOR[1] << 16) | (ASLEEP_COLOR[2] << 8) | 255
    assert set(last) == {packed}
    again = tmp_path / "replayed.rrd"
    api.replay(mcap, str(again))
    spheres = {key: comps for key, comps in read_rrd(again).items() if key[0] == "/world/spheres"}
    assert spheres == {key: comps for key, comps in rows.items() if key[0] == "/world/spheres"}
    # every series keeps one value a step once nothing moves (the pressure is a gap there)
    pressure = [comps["Scalars:scalars"][0][0] for (entity, _), comps in rows.items() if entity == "/stats/pressure/z"]
    assert len(pressure) == 240 and np.isnan(pressure[-1])
    asleep = [comps["Scalars:scalars"][0][0] for (entity, _), comps in rows.items() if entity == "/stats/asleep"]
    assert len(asleep) == 240 and asleep[-1] == 100
    # the log counts every sphere that fell asleep and every one that woke, as the summary does
    texts = [t for (entity, _), comps in rows.items() if entity == "/log" for row in comps["TextLog:text"] for t in row]
    told = {"fell asleep": 0, "woke": 0}
    for text in texts:
        for verb in told:
            if f" {verb}: " in text:
                told[verb] += int(text.split(": ")[1].split()[0])
    assert told == {"fell asleep": summary.slept, "woke": summary.woken} and summary.slept >= 100
    # the recording's own mask: none at frame 0, all 100 at the end
    recording = open_recording(mcap)
    assert recording.state(0).asleep is None
    assert recording.state(-1).asleep.dtype == bool and recording.state(-1).asleep.all()



def test_a_mesh_scene_draws_its_bvh_moves_its_kinematic_mesh_and_draws_every_step_s_recorded_search(tmp_path):
    """paddle: the mesh's BVH by volume and level (static), the paddle's transform every
    step, and every step's recorded search of the triangles' BVH, in 3D and as a tree; the
    file opens (a second, final blueprint) at the first contact on the mesh, whose log line
    says what the search found."""
    from typer.testing import CliRunner

    from physdbg.cli import app

    rrd = tmp_path / "paddle.rrd"
    done = CliRunner().invoke(app, ["record", "paddle", "-s", "duration=0.2", "-o", str(tmp_path / "paddle.mcap"),
                                    "--rrd", str(rrd)])
    assert done.exit_code == 0, done.output
    reader = rerun_chunk.RrdReader(rrd)
    static = {chunk.entity_path for chunk in reader.stream() if chunk.is_static}
    for volume in ("aabb", "obb", "sphere"):
        assert {f"/world/meshes/paddle/bvh/{volume}/level_{d}" for d in range(8)} <= static
    assert "/legend" in static  # what the 3D view's colours mean, in a text panel beside it
    rows = read_rrd(rrd)
    turned = [k for (entity, k), comps in rows.items() if entity == "/world/meshes/paddle"
              and any(name.startswith("Transform3D") for name in comps)]
    assert sorted(turned) == list(range(1, 13))
    searched = sorted(k for entity, k in rows if entity == "/search/triangles")
    assert searched == list(range(1, 13))  # every step: each sphere's path box asks the tree
    assert all(("/world/mesh_search/met", k) in rows and ("/world/mesh_search/queries", k) in rows for k in searched)
    first = min(k for (entity, k), comps in rows.items() if entity == "/log" and any(
        "hit mesh 'paddle' triangle" in text for row in comps.get("TextLog:text", []) for text in row))
    logged = [text for (entity, k), comps in rows.items() if entity == "/log" and k == first
              for row in comps.get("TextLog:text", []) for text in row]
    assert any(text.startswith(f"step {first}: the search of the meshes' BVHs") and "as recorded" in text
               for text in logged)
    assert len(reader.blueprints()) == 2


def _last_blueprint(rrd: Path) -> dict:
    """The blueprint a file opens with (the last one sent; the reader lists them in no set
    order): entity -> component -> values."""
    reader = rerun_chunk.RrdReader(rrd)

    def sent(store) -> bytes:  # row ids grow with time: the latest row of a blueprint dates it
        return max(row for chunk in reader.stream(store=store)
                   for row in chunk.to_record_batch().column("rerun.controls.RowId").to_pylist())

    out: dict = {}
    for chunk in reader.stream(store=max(reader.blueprints(), key=sent)):
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.startswith(("TimePanelBlueprint", "ViewBlueprint")):
                out.setdefault(str(chunk.entity_path), {})[name] = batch.column(name).to_pylist()
    return out


TROUGH = ("v -1 0.5 -1\nv -0.3 0 -1\nv 0.3 0 -1\nv 1 0.5 -1\nv -1 0.5 1\nv -0.3 0 1\nv 0.3 0 1\nv 1 0.5 1\n"
          "f 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\n")


def test_a_file_opens_paused_at_its_first_finding_with_the_finding_on_that_timeline(tmp_path):
    """A fast ball under discrete detection goes through a trough in step 1; a slow one first
    touches it at step 25. The file opens at the tunnelling (the timeline "from first
    finding", paused), not at the first mesh contact, and the finding's marker and line are
    on that timeline."""
    (tmp_path / "trough.obj").write_text(TROUGH)
    scene = tmp_path / "trough.toml"
    scene.write_text('name = "trough"\ndt = "1/60"\nduration = 1.0\ngravity = [0.0, -9.81, 0.0]\n'
                     'detection = "discrete"\n[[meshes]]\nname = "trough"\nfile = "trough.obj"\n'
                     '[[particles]]\nposition = [0.0, 1.0, 0.0]\nvelocity = [0.0, -60.0, 0.0]\nradius = 0.05\n'
                     '[[particles]]\nposition = [0.5, 1.0, 0.3]\nradius = 0.05\n')
    rec = api.record(str(scene), mcap_path=str(tmp_path / "t.mcap"), rrd_path=str(tmp_path / "t.rrd"))
    reader = rerun_chunk.RrdReader(Path(rec.rrd))
    steps = {}
    for chunk in reader.stream():
        batch = chunk.to_record_batch()
        if not chunk.is_static and "from first finding" in batch.schema.names:
            steps.setdefault(str(chunk.entity_path), []).extend(batch.column("from first finding").to_pylist())
    assert min(min(v) for v in steps.values()) == 1
    assert 1 in steps["/world/findings"] and 1 in steps["/world/spheres"] and 1 in steps["/world/paths"]
    panel = _last_blueprint(Path(rec.rrd))["/time_panel"]
    assert panel["TimePanelBlueprint:timeline"] == [["from first finding"]]
    assert panel["TimePanelBlueprint:play_state"] == [[1]]  # paused


def test_a_file_with_no_contact_opens_paused_at_its_start_and_says_why_the_search_is_empty(tmp_path):
    (tmp_path / "trough.obj").write_text(TROUGH)
    scene = tmp_path / "far.toml"
    scene.write_text('name = "far"\ndt = "1/60"\nsteps = 20\ngravity = [0.0, 0.0, 0.0]\n'
                     '[[meshes]]\nname = "trough"\nfile = "trough.obj"\n'
                     '[[particles]]\nposition = [5.0, 1.0, 0.0]\nvelocity = [1.0, 0.0, 0.0]\nradius = 0.05\n')
    rec = api.record(str(scene), mcap_path=str(tmp_path / "f.mcap"), rrd_path=str(tmp_path / "f.rrd"))
    shown = _last_blueprint(Path(rec.rrd))
    assert shown["/time_panel"]["TimePanelBlueprint:timeline"] == [["step"]]
    assert shown["/time_panel"]["TimePanelBlueprint:play_state"] == [[1]]  # paused, at the start
    titles = [c["ViewBlueprint:display_name"][0][0] for c in shown.values() if "ViewBlueprint:display_name" in c]
    assert "the BVH search: no sphere's path reached a mesh's triangles in this run" in titles, titles


def test_only_the_walked_volume_of_a_mesh_s_bvh_is_shown_in_a_run_s_file_and_the_overlay():
    """funnel walks OBBs (auto) and paddle AABBs: the blueprint shows that volume's first
    levels and hides the other two (the overlay's the same, under /a and /b)."""
    from physdbg.record.rerun_sink import BVH_LEVELS_SHOWN, hidden_mesh_volumes

    for name, walked in (("funnel", "obb"), ("paddle", "aabb")):
        header = RecordingHeader.from_scene(api.ready_scene(name))
        assert list(header.walls.meshes.bounding_volume) == [walked]
        for root in ("", "/a"):
            hidden = hidden_mesh_volumes(header, root)
            path = f"{root}/world/meshes/{name}/bvh"
            others = {"aabb", "obb", "sphere"} - {walked}
            assert all(f"{path}/{volume}" in hidden for volume in others)
            assert f"{path}/{walked}" not in hidden
            assert all(f"{path}/{walked}/level_{level}" not in hidden for level in range(BVH_LEVELS_SHOWN))
            assert f"{path}/{walked}/level_{BVH_LEVELS_SHOWN}" in hidden
