"""MCAP recordings: the state codec, writing and reading back, plain-mcap readers,
damaged files, interrupted and killed recorders, verification."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from typer.testing import CliRunner

from physdbg import api, open_recording
from physdbg.cli import app
from physdbg.engine import state_hash
from physdbg.engine.state import Walls
from physdbg.events import BroadPhaseInfo, Contacts, StepEnd, SweptTests
from physdbg.observe import FanOut, ListObserver
from physdbg.record import DETAIL_LEVELS, RecordingError, RecordingHeader
from physdbg.record.reader import RecordingIntegrityError
from physdbg.record import format as fmt
from physdbg.record import state_codec
from physdbg.record.mcap_sink import McapRecorder
from physdbg.api import load_scene

from . import tamper

ROOT = Path(__file__).resolve().parents[1]


def record_with_events(tmp_path, scene_name, overrides=(), detail="full", **kw):
    """Record a scene while also keeping every live event; returns (path, ListObserver)."""
    scene = load_scene(scene_name, list(overrides))
    path = tmp_path / f"{scene_name}.mcap"
    live = ListObserver()
    recorder = McapRecorder(path, RecordingHeader.from_scene(scene, detail, **kw))
    api.run(scene, observer=FanOut(recorder, live))
    recorder.close()
    return path, live


# ----------------------------------------------------------------------------- codec
floats = hnp.arrays(np.float64, (7, 3), elements=st.floats(allow_nan=True, allow_infinity=True, width=64))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(floats, floats), min_size=1, max_size=5),
       st.floats(min_value=1e-9, max_value=1.0), st.integers(0, 200))
def test_state_codec_is_lossless_for_any_floats_and_any_codec(frames, dt, first_frame):
    """NaNs, infinities, -0.0 and denormals survive every codec bit for bit; the recorder's
    encoder of successive frames (StateEncoder) writes the same bytes as encode_state."""
    history: list[np.ndarray] = []
    encoder = state_codec.StateEncoder()
    for offset, (x, v) in enumerate(frames):
        frame = first_frame + offset
        codec = state_codec.codec_for(frame, len(history))
        # a run without sleeping stores no mask; with it, any mask survives (odd counts too)
        mask = None if offset % 2 else (np.arange(len(x)) + frame) % 3 == 0
        data = state_codec.encode_state(frame, frame * dt, dt, state_hash(x, v), x, v, codec,
                                history[-1] if history else None, history[-2] if len(history) > 1 else None,
                                mask)
        assert encoder.encode(frame, frame * dt, dt, state_hash(x, v), x, v, mask) == data
        back, frame_no, _, dt_back, digest, asleep = state_codec.decode_state(
            data, history[-1] if history else None, history[-2] if len(history) > 1 else None)
        assert back[:, :3].tobytes() == x.tobytes() and back[:, 3:].tobytes() == v.tobytes()
        assert (frame_no, dt_back, digest) == (frame, dt, state_hash(x, v))
        assert (asleep is None) if mask is None else (asleep.dtype == bool and np.array_equal(asleep, mask))
        history = [*history[-1:], back]


def test_key_frames_come_every_interval_and_need_nothing_before_them():
    assert state_codec.codec_for(0, 0) == fmt.CODEC_RAW
    assert state_codec.codec_for(fmt.KEYFRAME_INTERVAL, 2) == fmt.CODEC_RAW
    assert state_codec.codec_for(fmt.KEYFRAME_INTERVAL + 1, 2) == fmt.CODEC_PREVIOUS
    assert state_codec.codec_for(fmt.KEYFRAME_INTERVAL + 2, 2) == fmt.CODEC_TWO_PREVIOUS
    x = np.ones((2, 3))
    data = state_codec.encode_state(5, 0.1, 0.01, state_hash(x, x), x, x, fmt.CODEC_TWO_PREVIOUS, np.zeros((2, 6)),
                            np.zeros((2, 6)))
    with pytest.raises(ValueError, match="needs the frames before"):
        state_codec.decode_state(data)


def test_an_asleep_mask_of_the_wrong_length_is_a_damaged_state():
    x = np.ones((9, 3))  # 9 spheres: a mask of 2 bytes
    good = state_codec.encode_state(1, 0.1, 0.1, state_hash(x, x), x, x, fmt.CODEC_RAW, asleep=np.arange(9) % 2 == 0)
    assert state_codec.decode_state(good)[5].tolist() == [True, False] * 4 + [True]
    from physdbg.record.proto import message_class

    bad = message_class(fmt.STATE_MESSAGE).FromString(good)
    bad.asleep = b"\x01"
    with pytest.raises(ValueError, match="asleep mask of 1 bytes, expected 2"):
        state_codec.decode_state(bad.SerializeToString())


def test_ballistic_states_compress_to_a_fraction_of_their_raw_size():
    """Free flight is what the predictor predicts: residuals are mostly zero bytes."""
    import zstandard

    n, dt = 1000, 1 / 240
    rng = np.random.default_rng(3)
    x, v = rng.uniform(0, 1, (n, 3)), rng.normal(0, 2, (n, 3))
    g = np.array([0, -9.81, 0])
    history: list[np.ndarray] = []
    sizes = []
    for frame in range(10):
        codec = state_codec.codec_for(frame, len(history))
        data = state_codec.encode_state(frame, frame * dt, dt, state_hash(x, v), x, v, codec,
                                history[-1] if history else None, history[-2] if len(history) > 1 else None)
        sizes.append(len(zstandard.compress(data)) / n)
        history = [*history[-1:], np.hstack([x, v])]
        x, v = x + v * dt + 0.5 * g * dt * dt, v + g * dt
    assert sizes[0] > 40  # a key frame: random float64 bits barely compress
    assert max(sizes[2:]) < 24  # predicted frames: well under half the raw 48 bytes


# ----------------------------------------------------------------------------- write + read
@pytest.mark.slow
def test_reader_gives_back_every_state_hash_and_event_of_the_live_run(tmp_path):
    path, live = record_with_events(tmp_path, "cradle")
    rec = open_recording(path)
    ends = live.step_ends
    assert rec.steps == len(ends) == 180 and not rec.truncated
    assert rec.header.name == "cradle" and rec.header.count == 5
    for k in (1, 2, 63, 64, 65, 100, 180):
        state = rec.state(k)
        assert state.positions.tobytes() == ends[k - 1].positions.tobytes()
        assert state.velocities.tobytes() == ends[k - 1].velocities.tobytes()
        assert state.state_hash == ends[k - 1].state_hash and state.time == ends[k - 1].time
    assert rec.state(-1).state_hash == ends[-1].state_hash
    for k, events in enumerate(rec.iter_step_events(), start=1):
        live_step = [e for e in live.events if e.step == k]
        assert [type(e) for e in events] == [type(e) for e in live_step]
        for mine, theirs in zip(events, live_step, strict=True):
            if isinstance(mine, Contacts):  # the row the loop wrote, to the bit
                assert mine.rows.tobytes() == theirs.rows.tobytes()
            if isinstance(mine, SweptTests):
                for name in mine.__dataclass_fields__:
                    np.testing.assert_array_equal(getattr(mine, name), getattr(theirs, name))
            if isinstance(mine, StepEnd):
                assert (mine.kinetic, mine.potential, mine.counts, mine.timings) == \
                       (theirs.kinetic, theirs.potential, theirs.counts, theirs.timings)
            if isinstance(mine, BroadPhaseInfo):
                assert (mine.name, mine.reason) == (theirs.name, theirs.reason)
    assert [c.a for c in live.contacts] == [c.a for k in range(1, rec.frames) for c in rec.contacts(k)]
    with pytest.raises(IndexError):
        rec.state(181)


@pytest.mark.slow
def test_random_access_reads_only_the_chunks_it_needs(tmp_path):
    """state(k) on a long recording decodes at most one key-frame interval of states."""
    path, live = record_with_events(tmp_path, "bounce", ["steps=2000"], detail="state")
    rec = open_recording(path)
    calls = []
    original = rec._messages

    def counting(topics, first, last):
        for item in original(topics, first, last):
            calls.append(item[1])
            yield item

    rec._messages = counting
    assert rec.state(1999).state_hash == live.step_ends[1998].state_hash
    assert len(calls) <= fmt.KEYFRAME_INTERVAL and min(calls) >= 1999 - fmt.KEYFRAME_INTERVAL


def test_detail_levels_record_only_what_they_say(tmp_path):
    path, _ = record_with_events(tmp_path, "cradle", detail="state")
    rec = open_recording(path)
    topics = {c.topic for c in rec.channels()}
    assert fmt.TOPIC_CONTACTS not in topics and fmt.TOPIC_SWEPT not in topics
    assert rec.state(50).positions.shape == (5, 3)
    with pytest.raises(RecordingError, match="--detail contacts"):
        rec.contacts(50)
    path, live = record_with_events(tmp_path, "cradle", detail="contacts")
    rec = open_recording(path)
    impact = live.contacts[0].step  # the frame the step ends in
    assert len(rec.contacts(impact)) == 4
    with pytest.raises(RecordingError, match="--detail full"):
        rec.swept_tests(impact)


def test_only_detail_full_asks_the_engine_for_the_swept_tests(tmp_path):
    # Below "full" the recording stores no swept test, so the engine logs only the hits
    # (engine.world.wants_swept_tests); the audit reads none either. The states are the same.
    from physdbg.analysis.audit import Auditor

    scene = load_scene("rain", ["steps=20", "generate.count=40"])
    hashes = {}
    for detail in DETAIL_LEVELS:
        header = RecordingHeader.from_scene(scene, detail)
        recorder = McapRecorder(tmp_path / f"{detail}.mcap", header)
        assert recorder.wants_swept_tests == (detail == "full")
        assert FanOut(recorder, Auditor(header)).wants_swept_tests == (detail == "full")
        api.run(scene, observer=recorder)
        recorder.close()
        rec = open_recording(tmp_path / f"{detail}.mcap")
        hashes[detail] = [rec.state(k).state_hash for k in range(scene.steps + 1)]
    assert hashes["state"] == hashes["contacts"] == hashes["full"]
    assert Auditor.wants_swept_tests is False


def test_bvh_nodes_are_recorded_and_a_big_tree_is_capped_by_whole_levels(tmp_path):
    path, live = record_with_events(tmp_path, "rain", ["broad_phase=bvh-sah", "steps=3"])
    events = open_recording(path).step_events(2)
    info = [e for e in events if isinstance(e, BroadPhaseInfo)][0]
    truth = [e for e in live.events if isinstance(e, BroadPhaseInfo) and e.step == 2][0]
    for name in ("lo", "hi", "left", "right", "depth", "order"):
        np.testing.assert_array_equal(info.nodes[name], truth.nodes[name])
    path, _ = record_with_events(tmp_path, "rain", ["broad_phase=bvh-sah", "steps=3"], bvh_max_nodes=40)
    capped = [e for e in open_recording(path).step_events(2) if isinstance(e, BroadPhaseInfo)][0]
    depth = capped.stats["bvh_logged_depth"]
    assert len(capped.nodes["depth"]) <= 40 and capped.nodes["depth"].max() == depth
    assert np.count_nonzero(truth.nodes["depth"] <= depth) == len(capped.nodes["depth"])  # whole levels
    assert "order" not in capped.nodes


# ----------------------------------------------------------------------------- plain mcap
PLAIN_READER = textwrap.dedent('''
    """Reads every channel of a physdbg recording with standard decoders only: the mcap
    library, its protobuf decoder (mcap-protobuf-support), json and numpy; the packed
    state's words as docs/recording-format.md describes them."""
    import hashlib, json, sys
    import numpy as np
    from mcap.reader import make_reader
    from mcap.decoder import DecoderFactory as McapDecoderFactory
    from mcap_protobuf.decoder import DecoderFactory

    class JsonDecoderFactory(McapDecoderFactory):
        def decoder_for(self, message_encoding, schema):
            return json.loads if message_encoding == "json" and schema.encoding == "jsonschema" else None

    def zigzag_decode(z):
        return ((z >> np.uint64(1)).view(np.int64)) ^ (-(z & np.uint64(1)).view(np.int64))

    def undescribed(value, schema, path):
        """Fields of a JSON value that its JSON Schema does not describe (Foxglove's subset)."""
        kind = schema.get("type")
        if isinstance(value, dict):
            if kind != "object" or "properties" not in schema:
                return [path]
            return [p for k, v in value.items() for p in (undescribed(v, schema["properties"][k], path + "." + k)
                                                          if k in schema["properties"] else [path + "." + k])]
        if isinstance(value, list):
            return [path] if kind != "array" else [p for v in value for p in undescribed(v, schema["items"], path + "[]")]
        want = {bool: "boolean", str: "string", int: "number", float: "number"}[type(value)]
        return [] if kind == want else [path]

    out = {"hashes": [], "recomputed": [], "positions_at_5": None, "points_at_5": None, "contacts": [],
           "kinetic": [], "energy": [], "encodings": {}, "undescribed": [], "steps_match": True, "log_times": []}
    prev = prev2 = None
    with open(sys.argv[1], "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            out["encodings"][channel.topic] = [channel.message_encoding, schema.encoding]
            if channel.message_encoding == "json":
                out["undescribed"] += undescribed(decoded, json.loads(schema.data), channel.topic)
                step = decoded.get("step")
            else:
                step = getattr(decoded, "step", None)
            if channel.topic.startswith("/physdbg/") and channel.topic != "/physdbg/frame_index":
                out["steps_match"] &= step == message.sequence
            if channel.topic == "/physdbg/state":
                n, codec, dt = decoded.count, decoded.codec, decoded.dt
                planes = np.frombuffer(decoded.words, np.uint8).reshape(8, 6 * n)
                words = np.ascontiguousarray(planes.T).view("<u8").reshape(n, 6)
                if codec == 0:
                    state = words.view(np.float64).copy()
                else:
                    r = zigzag_decode(words)
                    vp = prev[:, 3:] if codec == 1 else 2.0 * prev[:, 3:] - prev2[:, 3:]
                    state = np.empty((n, 6))
                    state[:, 3:] = (vp.view(np.int64) + r[:, 3:]).view(np.float64)
                    xp = prev[:, :3] + (dt * 0.5) * (prev[:, 3:] + state[:, 3:])
                    state[:, :3] = (xp.view(np.int64) + r[:, :3]).view(np.float64)
                prev2, prev = prev, state
                h = hashlib.blake2b(digest_size=16)
                h.update(np.ascontiguousarray(state[:, :3]).tobytes()); h.update(np.ascontiguousarray(state[:, 3:]).tobytes())
                out["hashes"].append(decoded.state_hash.hex()); out["recomputed"].append(h.hexdigest())
                out["log_times"].append([message.log_time, message.publish_time, decoded.time])
                if decoded.step == 5:
                    out["positions_at_5"] = state[:, :3].tolist()
            elif channel.topic == "/view/points" and message.sequence == 5:
                fields = {fl.name: fl.offset for fl in decoded.fields}
                raw = np.frombuffer(decoded.data, np.uint8).reshape(-1, decoded.point_stride)
                out["points_at_5"] = np.stack([raw[:, fields[a]:fields[a] + 4].copy().view("<f4")[:, 0]
                                               for a in "xyz"], axis=1).tolist()  # FLOAT32 fields
            elif channel.topic == "/physdbg/stats":
                out["kinetic"].append(decoded.kinetic); out["energy"].append(decoded.energy)
            elif channel.topic == "/physdbg/contacts":
                for i in range(len(decoded.a)):
                    out["contacts"].append([decoded.step, decoded.a[i], decoded.other[i], decoded.time_in_step[i],
                                            decoded.impulse[i], [decoded.normal_x[i], decoded.normal_y[i],
                                                                 decoded.normal_z[i]]])
    assert "physdbg" not in sys.modules
    print(json.dumps(out))
''')


@pytest.mark.slow
def test_a_program_with_standard_decoders_only_reads_every_channel(tmp_path):
    """Every channel decodes with the mcap protobuf decoder or JSON (whose schemas describe
    every field in the subset Foxglove parses), and gives the engine's states, hashes,
    stats and contacts without importing physdbg."""
    path, live = record_with_events(tmp_path, "billiards")
    script = tmp_path / "plain_reader.py"
    script.write_text(PLAIN_READER)
    done = subprocess.run([sys.executable, str(script), str(path)], capture_output=True, text=True,
                          cwd=tmp_path, check=True)
    got = json.loads(done.stdout)
    assert set(got["encodings"]) == set(fmt.topics_for("full", view=True)) - {
        fmt.TOPIC_BVH, fmt.TOPIC_BVH_ORDER, fmt.TOPIC_WARNINGS, *fmt.MESH_TOPICS}  # a grid, no warning, no mesh
    assert all(enc in (["protobuf", "protobuf"], ["json", "jsonschema"]) for enc in got["encodings"].values())
    assert got["undescribed"] == [] and got["steps_match"]
    initial = load_scene("billiards").state
    expected = [state_hash(initial.positions, initial.velocities)] + [e.state_hash for e in live.step_ends]
    assert got["hashes"] == expected and got["recomputed"] == expected
    assert got["positions_at_5"] == live.step_ends[4].positions.tolist()
    assert got["points_at_5"] == live.step_ends[4].positions.astype(np.float32).tolist()
    assert got["kinetic"] == [e.kinetic for e in live.step_ends]
    assert got["energy"] == [e.kinetic + e.potential for e in live.step_ends]
    want = [[c.step, c.a, c.other, c.time_in_step, c.impulse, c.normal.tolist()] for c in live.contacts]
    assert got["contacts"] == want and len(want) > 0
    # time is simulated time: log and publish time are the frame's time in ns, increasing
    log_ns = [row[0] for row in got["log_times"]]
    assert all(row[0] == row[1] == round(row[2] * 1e9) for row in got["log_times"])
    assert all(b > a for a, b in zip(log_ns, log_ns[1:]))
    # the other channels: a BVH run whose budget warns
    path, _ = record_with_events(tmp_path, "rain", ["steps=3", "broad_phase=bvh-sah", "max_swept_tests_per_step=20"])
    done = subprocess.run([sys.executable, str(script), str(path)], capture_output=True, text=True,
                          cwd=tmp_path, check=True)
    got = json.loads(done.stdout)
    assert set(got["encodings"]) == set(fmt.topics_for("full", view=True)) - set(fmt.MESH_TOPICS)
    assert got["undescribed"] == [] and got["steps_match"]
    # and a scene with a mesh: its trees and every step's search of them
    path, _ = record_with_events(tmp_path, "paddle", ["duration=0.1"])
    done = subprocess.run([sys.executable, str(script), str(path)], capture_output=True, text=True,
                          cwd=tmp_path, check=True)
    got = json.loads(done.stdout)
    assert set(fmt.MESH_TOPICS) <= set(got["encodings"])
    assert got["undescribed"] == [] and got["steps_match"]


# ----------------------------------------------------------------------------- damage
def test_a_foreign_file_and_an_mcap_of_something_else_are_refused_clearly(tmp_path):
    text = tmp_path / "notes.mcap"
    text.write_text("hello")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        open_recording(text)
    from mcap.writer import Writer

    other = tmp_path / "other.mcap"
    with open(other, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/x", "json", sid)
        w.add_message(cid, log_time=0, data=b"{}", publish_time=0)
        w.finish()
    with pytest.raises(RecordingError, match="not a physdbg recording"):
        open_recording(other)
    with pytest.raises(RecordingError, match="cannot open"):
        open_recording(tmp_path / "missing.mcap")


def test_a_truncated_file_reads_up_to_its_last_whole_chunk(tmp_path):
    scene = load_scene("rain", ["steps=120"])
    path = tmp_path / "rain.mcap"
    live = ListObserver()
    recorder = McapRecorder(path, RecordingHeader.from_scene(scene, "state"), chunk_bytes=16_000)
    api.run(scene, observer=FanOut(recorder, live))
    recorder.close()
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    rec = open_recording(cut)
    assert rec.truncated and 10 < rec.steps < 120
    assert rec.state(rec.steps).state_hash == live.step_ends[rec.steps - 1].state_hash
    assert sum(1 for _ in rec.iter_step_events()) == rec.steps
    cut.write_bytes(data[:200])
    with pytest.raises(RecordingError, match="truncated before its first complete chunk"):
        open_recording(cut)


def _start_recording(tmp_path, extra=()):
    out = tmp_path / "long.mcap"
    args = [sys.executable, "-m", "physdbg.cli", "record", "rain", "--set", "generate.count=2000",
            "--set", "steps=100000", "-o", str(out), "--no-rrd", "--detail", "state", "--no-view", *extra]  # size below: state chunks
    proc = subprocess.Popen(args, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while time.time() < deadline:  # wait until a few chunks are on disk
        if out.exists() and out.stat().st_size > 1_500_000:
            return proc, out
        time.sleep(0.2)
    proc.kill()
    pytest.fail("the recording did not grow")


@pytest.mark.slow
def test_a_recorder_killed_outright_leaves_a_readable_file(tmp_path):
    proc, out = _start_recording(tmp_path)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    rec = open_recording(out)
    assert rec.truncated and rec.steps > 10
    scene = load_scene("rain", ["generate.count=2000", "steps=100000"])
    world = scene.build_world()
    for frame in rec.states(1, 11):
        assert world.step(frame.dt).state_hash == frame.state_hash
    last = rec.state(rec.steps)
    assert state_hash(last.positions, last.velocities) == last.state_hash


@pytest.mark.slow
def test_ctrl_c_finishes_a_valid_file_up_to_the_last_step(tmp_path):
    proc, out = _start_recording(tmp_path)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted" in err and "Traceback" not in err
    rec = open_recording(out)
    assert not rec.truncated and rec.steps > 10  # closed properly: it has its summary
    assert f"steps 1..{rec.steps}" in err


# ----------------------------------------------------------------------------- api
def test_record_never_overwrites_without_force(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    first = api.record("bounce", ["steps=10"], rrd=False)
    assert first.mcap == str(Path("recordings") / "bounce.mcap") and first.frames == 11
    before = Path(first.mcap).read_bytes()
    with pytest.raises(api.PhysdbgError, match="already exists; pass --force"):
        api.record("bounce", ["steps=20"], rrd=False)
    assert Path(first.mcap).read_bytes() == before
    again = api.record("bounce", ["steps=20"], rrd=False, force=True)
    assert again.frames == 21


@pytest.mark.parametrize("force", [False, True])
@pytest.mark.slow
def test_two_writers_racing_on_one_path_leave_one_whole_recording(tmp_path, force):
    """Two `physdbg record` started together on one output: without --force one wins and
    the other exits 2 (the file is claimed exclusively before the run); with --force both
    finish and the file is the whole recording of one of them (written aside, renamed)."""
    out = tmp_path / "race.mcap"
    command = [sys.executable, "-m", "physdbg", "record", "bounce", "-s", "steps=2000", "-o", str(out), "--no-rrd"]
    procs = [subprocess.Popen(command + (["--force"] if force else []), cwd=tmp_path, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [(p.wait(timeout=120), p.stderr.read()) for p in procs]
    codes = sorted(code for code, _ in results)
    if force:
        assert codes == [0, 0]
    else:
        assert codes == [0, 2], results
        loser = next(err for code, err in results if code == 2)
        assert f"{out} already exists" in loser and "Traceback" not in loser
    assert api.verify(out).ok
    with open_recording(out) as rec:
        assert rec.steps == 2000 and not rec.truncated
    assert sorted(p.name for p in tmp_path.iterdir()) == ["race.mcap"]  # no partial file left behind


def test_ctrl_c_before_the_first_step_leaves_no_file_to_block_the_next_run(tmp_path, monkeypatch):
    """An interrupt while the recorders start (rerun's import takes a second) used to leave a
    0-byte .mcap that refused the next run without --force."""
    from physdbg.record import mcap_sink

    monkeypatch.chdir(tmp_path)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(mcap_sink.McapRecorder, "__init__", interrupted)
    with pytest.raises(api.RecordingInterrupted, match="nothing was written"):
        api.record("bounce", ["steps=10"])
    assert not Path("recordings/bounce.mcap").exists() and not Path("recordings/bounce.rrd").exists()
    monkeypatch.undo()
    monkeypatch.chdir(tmp_path)
    assert api.record("bounce", ["steps=10"], rrd=False).frames == 11


@pytest.fixture(scope="module")
def full_recording(tmp_path_factory):
    """billiards at detail full with the view channels: every channel kind a recording has."""
    folder = tmp_path_factory.mktemp("full")
    path = folder / "billiards.mcap"
    # a BVH broad phase (its nodes are a channel) and a contact budget it hits (warnings)
    api.record("billiards", ["steps=60", "broad_phase=bvh-sah", "max_contacts_per_step=1"], mcap_path=str(path),
               rrd=False, detail="full", view=True)
    return path


def _every_reader_refuses(path, good, words):
    for read in (api.info, api.verify, api.explain, lambda p: api.diff(good, p), lambda p: api.diff(p, good)):
        with pytest.raises(RecordingIntegrityError) as info:
            read(path)
        assert words in str(info.value) and str(path) in str(info.value)


def test_a_damaged_chunk_of_every_channel_is_found_by_info_verify_explain_and_diff(full_recording, tmp_path):
    """One flipped bit in any chunk, the swept tests' that info never decodes as well as the
    states': every reader checks the data section's CRC on opening and names the damaged
    chunk and its channels."""
    places = tamper.chunk_places(full_recording)
    covered = set().union(*(topics for _, topics in places))
    with open_recording(full_recording) as rec:
        assert covered == {c.topic for c in rec.channels()}  # every channel lies in some chunk damaged below
    for k, (offset, topics) in enumerate(places):
        damaged = tamper.damage_byte(full_recording, tmp_path / f"chunk{k}.mcap", offset)
        _every_reader_refuses(damaged, full_recording, "damaged: its chunk at byte")
        with pytest.raises(RecordingIntegrityError) as info:
            open_recording(damaged)
        assert all(topic in str(info.value) for topic in topics) and "its CRC does not match" in str(info.value)


def test_a_damaged_summary_and_a_damaged_record_between_chunks_are_found(full_recording, tmp_path):
    summary = tamper.damage_byte(full_recording, tmp_path / "summary.mcap", tamper.summary_schema_byte(full_recording))
    _every_reader_refuses(summary, full_recording, "its summary section does not match its CRC")
    header = tamper.damage_byte(full_recording, tmp_path / "header.mcap", 20)  # the MCAP header record
    _every_reader_refuses(header, full_recording, "damaged: its data section does not match its CRC")


def test_a_damaged_chunk_is_found_by_the_command_line_with_exit_2(full_recording, tmp_path):
    offset, _ = tamper.chunk_places(full_recording)[-1]
    damaged = tamper.damage_byte(full_recording, tmp_path / "damaged.mcap", offset)
    for args in (["info", str(damaged)], ["replay", str(damaged), "--verify"], ["explain", str(damaged)],
                 ["diff", str(full_recording), str(damaged)]):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        assert "damaged: its chunk at byte" in result.output and "Traceback" not in result.output


@pytest.mark.slow
def test_verify_passes_on_a_good_file_and_names_the_first_bad_step_of_a_tampered_one(tmp_path):
    path, live = record_with_events(tmp_path, "billiards")
    assert api.verify(path).ok
    k = 40
    # A state moved by a nanometre, its old hash kept: the file contradicts itself (exit 2).
    with pytest.raises(RecordingIntegrityError, match="frame 40: the stored state does not give its stored hash"):
        api.verify(tamper.nudge_state(path, tmp_path / "kept.mcap", k, sphere=2, by=1e-9))
    # Its hash rewritten, the frame index not: the file still contradicts itself.
    with pytest.raises(RecordingIntegrityError, match="frame 40: the frame index and the stored state disagree"):
        api.verify(tamper.nudge_state(path, tmp_path / "rehashed.mcap", k, sphere=2, by=1e-9, rehash=True))
    # A consistent forgery (state, its hash and the index all rewritten): only the
    # re-simulation can tell, and it names the step.
    forged = tamper.nudge_state(path, tmp_path / "forged.mcap", k, sphere=2, by=1e-9, rehash=True, reindex=True)
    result = api.verify(forged)
    assert not result.ok and result.first_bad_step == k and "re-simulated" in result.reason
    # --no-verify reads the contradictory file anyway: then the re-simulation finds it.
    result = api.verify(tmp_path / "kept.mcap", check_file=False)
    assert not result.ok and result.first_bad_step == k


def test_the_recorded_scene_repeats_the_run(tmp_path):
    path, live = record_with_events(tmp_path, "gas", ["steps=30"])
    scene = open_recording(path).scene
    world = scene.build_world()
    for end in live.step_ends:
        assert world.step(end.dt).state_hash == end.state_hash


def test_the_format_document_names_every_channel_and_field():
    doc = (ROOT / "docs" / "recording-format.md").read_text()
    for topic in fmt.topics_for("full", view=True):
        assert f"`{topic}`" in doc, topic
    for fields, _ in fmt.PROTOBUF_MESSAGES.values():
        for name, _, _ in fields:
            assert f"`{name}`" in doc, name
    for name, _ in fmt.STATE_MESSAGE_FIELDS:
        assert f"`{name}`" in doc, name
    for name in [*fmt.MESSAGE_OF_TOPIC.values(), *fmt.VIEW_SCHEMAS.values()]:
        assert f"`{name}`" in doc, name
    for name in fmt.BROAD_PHASE_STATS:
        assert f"`{name}`" in doc, name
    assert str(fmt.KEYFRAME_INTERVAL) in doc


@pytest.mark.parametrize("name", ["bounce", "cradle"])
def test_golden_recordings_still_read_and_still_match_the_engine(name):
    """recordings/golden/*.mcap were written by an earlier physdbg: the format still reads,
    and today's engine still gives every recorded state hash."""
    rec = open_recording(ROOT / "recordings" / "golden" / f"{name}.mcap")
    assert rec.header.name == name and not rec.truncated
    result = api.verify(rec.path)
    assert result.ok and result.checked == rec.steps, result.reason


def test_a_real_time_run_is_recorded_with_its_step_lengths_and_verifies(tmp_path):
    result = api.record("bounce", ["dt=real", "duration=0.2"], mcap_path=str(tmp_path / "rt.mcap"), rrd=False)
    rec = open_recording(result.mcap)
    dts = [rec.state(k).dt for k in range(1, rec.frames)]
    assert len(set(dts)) > 1  # real elapsed times, not a fixed dt
    assert rec.meta["dt"] is None and api.verify(result.mcap).ok


@pytest.mark.slow
def test_the_contact_row_is_one_schema_from_the_loop_to_the_file():
    """The loop's buffer, the Contacts event and the recording's table are one dtype, and a
    file written while the ``how`` column was still named ``resting`` (the golden bounce)
    gives the engine's own rows back to the bit: held contacts included."""
    from physdbg.events import CONTACT_FIELDS, CONTACT_ROW, HOW_RESTING

    assert fmt.PROTOBUF_MESSAGES["physdbg.Contacts"][0] is CONTACT_FIELDS
    assert fmt.dtype_of(CONTACT_FIELDS) == CONTACT_ROW
    assert all(isinstance(getattr(Contacts, name), property) for name, _, _ in CONTACT_FIELDS)  # every column
    rec = open_recording(ROOT / "recordings" / "golden" / "bounce.mcap")
    schema = next(s for s in rec._reader.get_summary().schemas.values() if s.name == "physdbg.Contacts")
    assert b"resting" in schema.data and b"how" not in schema.data  # the old name, in the file
    obs = ListObserver()
    world = rec.scene.build_world()
    world.observer = obs
    assert world._buf.contacts.dtype == CONTACT_ROW
    held = 0
    for k in range(1, rec.frames):
        world.step(rec.state(k).dt)
        live = [e for e in obs.of_type(Contacts) if e.step == k]
        recorded = rec.contacts(k)
        assert recorded.rows.dtype == CONTACT_ROW
        assert recorded.rows.tobytes() == (live[0].rows.tobytes() if live else b"")
        held += int(np.count_nonzero(recorded.how == HOW_RESTING))
    assert held > 0 and np.array_equal(recorded.resting, recorded.how == HOW_RESTING)


def test_the_contact_log_names_each_partner_and_how_it_was_met():
    """The viewer's text log (record/view.describe_contacts): the partner in the words every
    report uses (events.partner_words), impacts at INFO, held contacts at DEBUG."""
    from physdbg.events import HOW_IMPULSE, HOW_RESTING, KIND_PAIR, KIND_WALL
    from physdbg.record.view import describe_contacts

    c = Contacts.empty(3, 2)
    c.kind[:], c.a[:], c.other[:], c.how[:] = [KIND_PAIR, KIND_WALL], [0, 2], [1, 0], [HOW_IMPULSE, HOW_RESTING]
    c.time_in_step[:] = [0.005, 0.0]
    names = Walls(["floor"], np.array([[0.0, 1.0, 0.0]]), np.zeros(1), np.ones(1), np.zeros(1, dtype=bool),
                  np.zeros(1)).partner_names()
    (first, level_1), (second, level_2) = describe_contacts(3, c, 0.01, names)
    assert first.startswith("step 3: sphere 0 hit sphere 1 at 0.500·dt") and level_1 == "INFO"
    assert second.startswith("step 3: sphere 2 rests on wall 'floor' at 0.000·dt") and level_2 == "DEBUG"


def test_verify_of_a_file_without_its_summary_says_it_is_incomplete(full_recording, tmp_path):
    """A file still being written (or whose writer was killed) has no summary: verify checks
    the whole steps it holds and says the file is incomplete."""
    data = full_recording.read_bytes()
    cut = tmp_path / "being-written.mcap"
    cut.write_bytes(data[: len(data) * 3 // 4])
    result = CliRunner().invoke(app, ["replay", str(cut), "--verify"])
    assert result.exit_code == 0, result.output
    assert f"INCOMPLETE: {cut} has no summary" in result.output
