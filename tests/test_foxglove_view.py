"""The view channels and what tools other than physdbg make of a recording: MCAP's own
statistics (duration), Foxglove's schemas (scene, point cloud, log), rerun's MCAP importer,
the TypeScript MCAP reader, and the Foxglove layout shipped in docs/."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from physdbg import api, open_recording
from physdbg.cli import app
from physdbg.record import format as fmt
from physdbg.record.foxglove_view import _rotations_from_x, view_schemas

ROOT = Path(__file__).resolve().parents[1]


def messages(path, topic):
    """(log_time, decoded message) of a view or physdbg protobuf topic, with mcap's protobuf decoder."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [(m.log_time, d) for _, _, m, d in reader.iter_decoded_messages(topics=[topic])]


def summary_duration(path) -> float:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    return (stats.message_end_time - stats.message_start_time) / 1e9


# ----------------------------------------------------------------------------- time
def test_the_file_summary_gives_the_simulated_duration(tmp_path):
    bounce = api.record("bounce", mcap_path=str(tmp_path / "b.mcap"), rrd=False)
    assert abs(summary_duration(bounce.mcap) - 5.0) <= 1 / 60
    real = api.record("bounce", ["dt=real", "duration=0.3"], mcap_path=str(tmp_path / "r.mcap"), rrd=False)
    rec = open_recording(real.mcap)
    simulated = rec.state(rec.steps).time
    assert rec.meta["dt"] is None and simulated > 0.25
    assert abs(summary_duration(real.mcap) - simulated) <= max(np.diff(rec.frame_table().time))
    # rerun's structural and timeline check (publish after log time, ...) finds nothing
    from physdbg.record.rerun_sink import viewer_binary

    for path in (bounce.mcap, real.mcap):
        done = subprocess.run([viewer_binary(), "mcap", "check", path], capture_output=True, text=True,
                              env={**os.environ, "RERUN_ANALYTICS": "0"})
        rows = [line.split() for line in done.stdout.splitlines()  # table rows: status, id, chunks, topic, issues
                if len(line.split()) >= 5 and line.split()[1].isdigit()]
        assert done.returncode == 0 and rows and all(row[0] == "ok" and row[-1] == "—" for row in rows), done.stdout


def test_log_times_stay_strictly_increasing_when_rounding_would_repeat_them():
    times = [0.0, 1e-10, 2e-10, 1.0, 1.0, float("nan"), 2.0]
    out, previous = [], -1
    for t in times:
        previous = fmt.frame_nanoseconds(t, previous)
        out.append(previous)
    assert out == [0, 1, 2, 1_000_000_000, 1_000_000_001, 1_000_000_002, 2_000_000_000]
    assert fmt.frame_nanoseconds(1e30, 5) == fmt.MAX_NANOSECONDS


# ----------------------------------------------------------------------------- view content
def test_the_3d_scene_has_every_sphere_by_id_the_walls_and_an_arrow_per_contact(tmp_path):
    result = api.record("cradle", mcap_path=str(tmp_path / "c.mcap"), rrd=False)
    rec = open_recording(result.mcap)
    updates = messages(result.mcap, fmt.TOPIC_VIEW_SCENE)
    walls = [u for _, u in updates if any(e.id == "walls" for e in u.entities)]
    assert len(walls) == 1 and len(walls[0].entities[0].lines) == len(rec.header.walls)
    per_frame = [u for _, u in updates if not any(e.id == "walls" for e in u.entities)]
    assert len(per_frame) == rec.frames
    k = 44  # the cradle's first contacts
    spheres = [e for e in per_frame[k].entities if e.id.startswith("sphere ")]
    assert [e.id for e in spheres] == [f"sphere {i}" for i in range(rec.header.count)]
    centres = np.array([[e.spheres[0].pose.position.x, e.spheres[0].pose.position.y, e.spheres[0].pose.position.z]
                        for e in spheres])
    assert np.array_equal(centres, rec.state(k).positions)
    assert [e.spheres[0].size.x for e in spheres] == (2 * rec.header.radius).tolist()
    arrows = [e for e in per_frame[k].entities if e.id == "contacts"][0].arrows
    contacts = rec.contacts(k)
    assert len(arrows) == len(contacts) > 0
    for arrow, point, normal in zip(arrows, contacts.point, contacts.normal, strict=True):
        assert [arrow.pose.position.x, arrow.pose.position.y, arrow.pose.position.z] == point.tolist()
        q = arrow.pose.orientation
        assert np.allclose(_rotate_x(q.x, q.y, q.z, q.w), normal, atol=1e-12)
    stamps = {e.timestamp.ToNanoseconds() for e in per_frame[k].entities}
    assert stamps == {updates[k + 1][0]}  # the frame's log time (message 0 is the walls)


def _rotate_x(x, y, z, w):
    """The image of +x under the unit quaternion (x, y, z, w)."""
    return np.array([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)])


def test_the_3d_scene_carries_every_step_s_recorded_search_of_the_meshes_trees(tmp_path):
    """A scene with a mesh: entity "mesh search" each step, drawing the walks of the spheres
    the step is about (those that hit the mesh first, as the Rerun view): the edges of the
    nodes met (8 corners and 12 edges of index pairs a box), the triangles reached; its metadata the spheres
    drawn and the counts of the whole search the file records (/physdbg/mesh_search)."""
    from physdbg.record import mesh_view

    done = api.record("paddle", ["duration=0.1"], mcap_path=str(tmp_path / "p.mcap"), rrd=False)
    recording = open_recording(done.mcap)
    searches = [entity for _, update in messages(done.mcap, fmt.TOPIC_VIEW_SCENE) for entity in update.entities
                if entity.id == "mesh search"]
    assert len(searches) == recording.steps
    hits = 0
    for k, entity in enumerate(searches, start=1):
        search, contacts = recording.mesh_search(k), recording.contacts(k)
        meta = {m.key: m.value for m in entity.metadata}
        shown = mesh_view.searched_spheres(search, contacts, 12)
        assert meta["spheres drawn"] == " ".join(str(i) for i in shown)
        hit = contacts.a[contacts.kind == 2]
        hits += len(hit)
        assert set(hit.tolist()) <= set(shown)
        assert int(meta["boxes asked"]) == len(search.query_sphere)
        assert int(meta["node visits"]) == len(search.visit_node)
        mine = np.isin(search.query_sphere[search.visit_query], shown)
        met = np.unique(search.visit_node[mine & (search.visit_outcome != 1)])
        green = [line for line in entity.lines if line.color.g > 0.8]
        assert sum(len(line.points) for line in green) == 8 * len(met)
        assert sum(len(line.indices) for line in green) == 24 * len(met)
        assert all(max(line.indices) < len(line.points) for line in green)
        reached = len(np.unique(search.visit_node[mine & (search.visit_outcome == 2)]))
        assert sum(len(face.points) for face in entity.triangles) == 3 * reached
    assert hits > 0


def test_arrow_rotations_turn_x_onto_any_direction_including_minus_x():
    rng = np.random.default_rng(3)
    d = rng.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = np.vstack([d, [[-1.0, 0, 0], [1.0, 0, 0], [0, -1.0, 0]]])
    for q, direction in zip(_rotations_from_x(d), d, strict=True):
        assert np.allclose(_rotate_x(*q), direction, atol=1e-12)


def test_the_point_cloud_holds_the_positions_and_the_log_the_words(tmp_path):
    result = api.record("cradle", mcap_path=str(tmp_path / "c.mcap"), rrd=False)
    rec = open_recording(result.mcap)
    clouds = messages(result.mcap, fmt.TOPIC_VIEW_POINTS)
    assert len(clouds) == rec.frames
    cloud = clouds[44][1]
    offsets = {f.name: f.offset for f in cloud.fields}
    from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField

    kinds = {f.name: PackedElementField.NumericType.Name(f.type) for f in cloud.fields}
    assert kinds == {"x": "FLOAT32", "y": "FLOAT32", "z": "FLOAT32", "radius": "FLOAT32", "id": "UINT32"}
    rows = np.frombuffer(cloud.data, np.uint8).reshape(-1, cloud.point_stride)
    column = {a: rows[:, offsets[a]:offsets[a] + 4].copy().view("<f4")[:, 0] for a in ("x", "y", "z", "radius")}
    xyz = np.stack([column[a] for a in "xyz"], axis=1)
    assert np.array_equal(xyz, rec.state(44).positions.astype(np.float32))
    assert np.array_equal(column["radius"], rec.header.radius.astype(np.float32))
    logs = [m.message for _, m in messages(result.mcap, fmt.TOPIC_VIEW_LOG)]
    assert logs[0].startswith("cradle: 5 spheres")
    assert any(line.startswith("step 44: sphere ") for line in logs)


def test_sleeping_spheres_are_grey_blue_in_the_3d_scene_and_named_in_the_log(tmp_path):
    """Foxglove shows what the Rerun view shows: a sphere is grey-blue exactly while the
    state's asleep mask says so, and the log names who fell asleep."""
    from physdbg.record.view import ASLEEP_COLOR

    result = api.record("bounce", ["sleep_speed=0.05", "sleep_time=0.1"], mcap_path=str(tmp_path / "b.mcap"),
                        rrd=False)
    rec = open_recording(result.mcap)
    per_frame = [u for _, u in messages(result.mcap, fmt.TOPIC_VIEW_SCENE)
                 if not any(e.id == "walls" for e in u.entities)]
    grey_blue = [c / 255.0 for c in ASLEEP_COLOR]
    for k in (0, rec.frames // 2, rec.frames - 1):
        colour = per_frame[k].entities[0].spheres[0].color
        asleep = rec.state(k).asleep
        assert np.allclose([colour.r, colour.g, colour.b], grey_blue) == bool(asleep is not None and asleep[0])
    assert rec.state(-1).asleep[0]  # the ball has come to rest and sleeps by the end
    logs = [m.message for _, m in messages(result.mcap, fmt.TOPIC_VIEW_LOG)]
    assert sum(line.endswith("1 sphere fell asleep: 0") for line in logs) == result.summary.slept >= 1


def test_view_channels_follow_detail_and_no_view_leaves_them_out(tmp_path):
    runner = CliRunner()
    out = tmp_path / "none.mcap"
    done = runner.invoke(app, ["record", "cradle", "--no-rrd", "--no-view", "-o", str(out)])
    assert done.exit_code == 0, done.output
    assert "view        view channels left out (--no-view)" in done.output
    topics = {c.topic for c in open_recording(out).channels()}
    assert not topics & set(fmt.VIEW_TOPICS) and fmt.TOPIC_STATE in topics
    state = tmp_path / "state.mcap"
    done = runner.invoke(app, ["record", "cradle", "--no-rrd", "--detail", "state", "-o", str(state)])
    assert done.exit_code == 0, done.output
    updates = [u for _, u in messages(state, fmt.TOPIC_VIEW_SCENE)]
    assert not any(e.id == "contacts" for u in updates for e in u.entities)
    assert not any("hit" in m.message for _, m in messages(state, fmt.TOPIC_VIEW_LOG))
    assert out.stat().st_size < state.stat().st_size
    assert "view        Foxglove view channels written (--no-view leaves them out)" in done.output


def test_a_big_scene_leaves_the_view_out_unless_asked_and_says_so(tmp_path):
    runner = CliRunner()
    big = ["record", "rain", "-s", "generate.count=2500", "-s", "steps=2", "--no-rrd", "--detail", "state"]
    done = runner.invoke(app, [*big, "-o", str(tmp_path / "auto.mcap")])
    assert done.exit_code == 0, done.output
    assert "view channels left out: 2500 spheres > 2000" in done.output and "--view writes them" in done.output
    assert not {c.topic for c in open_recording(tmp_path / "auto.mcap").channels()} & set(fmt.VIEW_TOPICS)
    done = runner.invoke(app, [*big, "--view", "-o", str(tmp_path / "asked.mcap")])
    assert done.exit_code == 0, done.output
    assert set(fmt.VIEW_TOPICS) <= {c.topic for c in open_recording(tmp_path / "asked.mcap").channels()}


# ----------------------------------------------------------------------------- other tools
def test_rerun_mcap_convert_gives_points_at_the_engine_positions_and_plottable_stats(tmp_path):
    import rerun.chunk as rerun_chunk

    from physdbg.record.rerun_sink import viewer_binary

    result = api.record("billiards", ["steps=40"], mcap_path=str(tmp_path / "b.mcap"), rrd=False)
    rec = open_recording(result.mcap)
    converted = tmp_path / "converted.rrd"
    subprocess.run([viewer_binary(), "mcap", "convert", result.mcap, "-o", str(converted)], check=True,
                   capture_output=True, env={**os.environ, "RERUN_ANALYTICS": "0"})
    points, stats = {}, {}
    for chunk in rerun_chunk.RrdReader(converted).stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        times = batch.column("message_log_time").cast("int64").to_pylist()
        if chunk.entity_path == fmt.TOPIC_VIEW_POINTS:
            for t, value in zip(times, batch.column("Points3D:positions").to_pylist(), strict=True):
                points[t] = np.array(value)
        elif chunk.entity_path == fmt.TOPIC_STATS:
            column = batch.column("physdbg.StepStats:message")
            for t, value in zip(times, column.to_pylist(), strict=True):
                stats[t] = value
            struct = column.type.value_type if hasattr(column.type, "value_type") else column.type
            numeric = {struct.field(i).name: str(struct.field(i).type) for i in range(struct.num_fields)}
    assert len(points) == rec.frames
    for k, t in enumerate(sorted(points)):  # log times increase with the frame
        assert np.array_equal(points[t], rec.state(k).positions.astype(np.float32)), k
    assert len(stats) == rec.steps
    for k, t in enumerate(sorted(stats), start=1):
        value = stats[t][0] if isinstance(stats[t], list) else stats[t]
        end = rec.step_end(k)
        assert value["step"] == k and value["kinetic"] == end.kinetic and value["energy"] == end.kinetic + end.potential
    assert numeric["kinetic"] == "double" and numeric["contacts"] == "int64"


def _npm_mcap_reader(tmp_path) -> Path | str:
    """A folder with @mcap/core, @mcap/support and @mcap/nodejs (cached between runs), or
    the reason there is none."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        return "node and npm are not installed"
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "physdbg-tests" / "mcap-ts"
    if not (base / "node_modules" / "@mcap" / "support").is_dir():
        base.mkdir(parents=True, exist_ok=True)
        done = subprocess.run(["npm", "install", "--no-audit", "--no-fund", "--prefix", str(base),
                               "@mcap/core@2", "@mcap/support", "@mcap/nodejs"],
                              capture_output=True, text=True, timeout=300)
        if done.returncode != 0:
            return f"npm could not install @mcap/core ({done.stderr.strip().splitlines()[-1:]})"
    return base


TS_READER = (ROOT / "tests" / "mcap_ts_reader.js")


def test_the_typescript_mcap_reader_reads_every_recording_with_crcs_checked(tmp_path):
    where = _npm_mcap_reader(tmp_path)
    if isinstance(where, str):
        pytest.skip(where)
    files = sorted((ROOT / "recordings").rglob("*.mcap"))
    for detail in ("state", "contacts", "full"):
        files.append(Path(api.record("rain", ["steps=30"], mcap_path=str(tmp_path / f"{detail}.mcap"), rrd=False,
                                     detail=detail).mcap))
    files.append(Path(api.record("bounce", ["dt=real", "duration=0.1"], mcap_path=str(tmp_path / "real.mcap"),
                                 rrd=False).mcap))
    done = subprocess.run(["node", str(TS_READER), *map(str, files)], capture_output=True, text=True,
                          env={**os.environ, "NODE_PATH": str(where / "node_modules")}, timeout=300)
    assert done.returncode == 0, done.stderr
    read = json.loads(done.stdout)
    for path in files:
        rec = open_recording(path)
        got = read[str(path)]
        assert got["streamed"] == got["indexed"] > rec.frames
        assert got["channels"] == len(rec.channels())
        assert int(got["end"]) - int(got["start"]) == round(rec.state(rec.steps).time * 1e9)


# ----------------------------------------------------------------------------- layout
def test_the_foxglove_layout_names_topics_and_fields_a_recording_has(tmp_path):
    layout = json.loads((ROOT / "docs" / "foxglove-layout.json").read_text())
    text = json.dumps(layout)
    import re

    paths = set(re.findall(r'"(/(?:physdbg|view)/[a-z_]+)((?:\.[a-z_]+)*)', text))
    assert paths, "the layout names no topic"
    classes = view_schemas()
    from physdbg.record.proto import message_class

    for topic, fields in paths:
        assert topic in fmt.topics_for("full", view=True), topic
        message = classes.get(topic) or message_class(fmt.MESSAGE_OF_TOPIC[topic])
        descriptor = message.DESCRIPTOR
        for field in filter(None, fields.split(".")):
            assert field in descriptor.fields_by_name, (topic, field)
            descriptor = descriptor.fields_by_name[field].message_type
    panels = {key.split("!")[0] for key in layout["configById"]}
    assert {"3D", "Plot", "RosOut"} <= panels


def test_audit_findings_reach_the_foxglove_log_and_scene_at_their_step(tmp_path):
    """CI and Foxglove users see what Rerun users see: a tunnelling is a warning on /view/log
    and a red marker on /view/scene at the step where it happened."""
    path = tmp_path / "tunnel.mcap"
    api.record("bullet-wall", ["detection=discrete"], mcap_path=str(path), rrd=False)
    step_1_ns = [ns for ns, _ in messages(path, fmt.TOPIC_STATE)][1]
    warnings = [(ns, m) for ns, m in messages(path, fmt.TOPIC_VIEW_LOG) if m.level == 3]
    assert any(m.message.startswith("step 1: [tunnelling] sphere 0 went through wall 'thin wall'")
               for _, m in warnings), [m.message for _, m in warnings]
    markers = [(ns, e) for ns, m in messages(path, fmt.TOPIC_VIEW_SCENE) for e in m.entities
               if e.id.startswith("finding-")]
    assert len(markers) == 1
    ns, entity = markers[0]
    assert entity.metadata[0].value == "tunnelling" and entity.spheres[0].color.r == 1.0
    assert ns == step_1_ns and all(ns == step_1_ns for ns, m in warnings if "[tunnelling]" in m.message)
