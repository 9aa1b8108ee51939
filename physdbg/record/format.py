"""The physdbg recording format: MCAP channels, schemas and the packed state codec.

Everything a reader needs to know lives here and in docs/recording-format.md (a test
checks that the document names every channel and field defined below). Nothing in this
module touches files; :mod:`.mcap_sink` writes and :mod:`.reader` reads.

Time base: an MCAP message's ``log_time`` is the **frame**: the number of steps completed
(0 = the initial state, k = after the k-th step). Messages about the k-th step (its
contacts, swept tests, ...) have ``log_time`` k, so "everything about step k" is a time
range query. ``publish_time`` is the simulated time at that frame in integer nanoseconds.
The engine's events number steps from 0 (``event.step`` = k - 1).
"""

from __future__ import annotations

import json
import struct

import numpy as np

FORMAT_NAME = "physdbg-recording"
FORMAT_VERSION = 1
PROFILE = "physdbg"

# Message encodings (MCAP allows any string; these are documented in the format doc).
ENCODING_JSON = "json"  # UTF-8 JSON object; schema encoding "jsonschema"
ENCODING_ARRAY = "physdbg.array"  # rows of a numpy structured array, little-endian, no padding
ENCODING_STATE = "physdbg.state"  # STATE_HEADER + byte-shuffled words (see encode_state)

SCHEMA_JSON = "jsonschema"
SCHEMA_ARRAY = "physdbg.dtype"  # JSON: {"fields": [[name, dtype, shape?], ...], "units": {...}}
SCHEMA_STATE = "physdbg.state"  # JSON describing the header and codecs

# Detail levels: what each level records (each includes the one before).
DETAIL_LEVELS = ("state", "contacts", "full")

# ----------------------------------------------------------------------------- channels
TOPIC_SCENE = "/physdbg/scene"  # once, frame 0: scene, settings, versions (JSON)
TOPIC_PARTICLES = "/physdbg/particles"  # once, frame 0: per-particle constants (array)
TOPIC_WALLS = "/physdbg/walls"  # once, frame 0: walls (JSON)
TOPIC_STATE = "/physdbg/state"  # every frame: positions, velocities, hash (state)
TOPIC_STATS = "/physdbg/stats"  # every step: energies, momentum, counts, timings (array, 1 row)
TOPIC_WARNINGS = "/physdbg/warnings"  # when any: one JSON message per warning
TOPIC_CONTACTS = "/physdbg/contacts"  # detail >= contacts: every contact of the step (array)
TOPIC_SWEPT = "/physdbg/swept_tests"  # detail full: every narrow-phase test (array)
TOPIC_BROAD_PHASE = "/physdbg/broad_phase"  # detail full: structure, reason, stats (JSON)
TOPIC_BVH = "/physdbg/bvh"  # detail full, BVH broad phases: node rows (array)
TOPIC_BVH_ORDER = "/physdbg/bvh_order"  # detail full, uncapped BVH: particle of each leaf slot
TOPIC_FRAME_INDEX = "/physdbg/frame_index"  # once, at the end: every frame's time, dt and state hash

# The bulky per-step channels are written in chunks of their own, so reading states,
# stats and contacts (diff, explain, a replay at detail "state") never decompresses them.
HEAVY_TOPICS = frozenset({"/physdbg/swept_tests", "/physdbg/broad_phase", "/physdbg/bvh", "/physdbg/bvh_order"})

TOPICS_BY_DETAIL = {
    "state": (TOPIC_SCENE, TOPIC_PARTICLES, TOPIC_WALLS, TOPIC_STATE, TOPIC_STATS, TOPIC_WARNINGS,
              TOPIC_FRAME_INDEX),
    "contacts": (TOPIC_CONTACTS,),
    "full": (TOPIC_SWEPT, TOPIC_BROAD_PHASE, TOPIC_BVH, TOPIC_BVH_ORDER),
}


def topics_for(detail: str) -> tuple[str, ...]:
    """Every topic a recording at ``detail`` may hold."""
    out: tuple[str, ...] = ()
    for level in DETAIL_LEVELS:
        out += TOPICS_BY_DETAIL[level]
        if level == detail:
            return out
    raise ValueError(f"unknown detail level {detail!r}")


# ----------------------------------------------------------------------------- array schemas
# (name, numpy dtype, shape) rows; units and meanings are in the format document.
PARTICLE_FIELDS = [
    ("radius", "<f8", ()), ("inverse_mass", "<f8", ()), ("restitution", "<f8", ()), ("gravity_scale", "<f8", ()),
]
STATS_FIELDS = [
    ("time", "<f8", ()), ("dt", "<f8", ()), ("kinetic", "<f8", ()), ("potential", "<f8", ()),
    ("momentum", "<f8", (3,)), ("contacts", "<i8", ()), ("swept_tests", "<i8", ()), ("events", "<i8", ()),
    ("resting", "<i8", ()), ("rapid", "<i8", ()), ("max_overlap", "<f8", ()),
    ("seconds_forces", "<f8", ()), ("seconds_broad_phase", "<f8", ()), ("seconds_narrow_phase", "<f8", ()),
    ("seconds_resolve", "<f8", ()), ("seconds_finish", "<f8", ()),
]
CONTACT_FIELDS = [
    ("time_in_step", "<f8", ()), ("kind", "i1", ()), ("resting", "i1", ()), ("a", "<i4", ()), ("other", "<i4", ()),
    ("point", "<f8", (3,)), ("normal", "<f8", (3,)), ("impulse", "<f8", ()),
    ("velocity_a_before", "<f8", (3,)), ("velocity_a_after", "<f8", (3,)),
    ("velocity_b_before", "<f8", (3,)), ("velocity_b_after", "<f8", (3,)),
    ("restitution", "<f8", ()), ("closing_speed", "<f8", ()),
]
SWEPT_FIELDS = [
    ("kind", "i1", ()), ("outcome", "i1", ()), ("a", "<i4", ()), ("other", "<i4", ()),
    ("start", "<f8", ()), ("toi", "<f8", ()),
]
BVH_FIELDS = [
    ("node", "<i4", ()), ("depth", "<i4", ()), ("left", "<i4", ()), ("right", "<i4", ()), ("parent", "<i4", ()),
    ("start", "<i4", ()), ("count", "<i4", ()), ("lo", "<f8", (3,)), ("hi", "<f8", (3,)),
]
BVH_ORDER_FIELDS = [("particle", "<i4", ())]
FRAME_INDEX_FIELDS = [("time", "<f8", ()), ("dt", "<f8", ()), ("state_hash", "u1", (16,))]

UNITS = {
    "radius": "m", "inverse_mass": "1/kg (0 = immovable)", "time": "s", "dt": "s", "kinetic": "J",
    "potential": "J", "momentum": "kg·m/s", "max_overlap": "m", "seconds_*": "s (wall clock)",
    "time_in_step": "s after the step began", "point": "m", "normal": "unit vector from b (or wall) to a",
    "impulse": "N·s", "velocity_*": "m/s", "start": "s after the step began",
    "toi": "s after the step began, NaN = no contact in the step", "lo": "m", "hi": "m",
}

ARRAY_SCHEMAS = {
    TOPIC_PARTICLES: ("physdbg.Particles", PARTICLE_FIELDS),
    TOPIC_STATS: ("physdbg.StepStats", STATS_FIELDS),
    TOPIC_CONTACTS: ("physdbg.Contacts", CONTACT_FIELDS),
    TOPIC_SWEPT: ("physdbg.SweptTests", SWEPT_FIELDS),
    TOPIC_BVH: ("physdbg.BvhNodes", BVH_FIELDS),
    TOPIC_BVH_ORDER: ("physdbg.BvhOrder", BVH_ORDER_FIELDS),
    TOPIC_FRAME_INDEX: ("physdbg.FrameIndex", FRAME_INDEX_FIELDS),
}
JSON_SCHEMAS = {
    TOPIC_SCENE: ("physdbg.Scene", {"type": "object", "required": ["format", "format_version", "scene"]}),
    TOPIC_WALLS: ("physdbg.Walls", {"type": "object", "required": ["names", "normals", "offsets"]}),
    TOPIC_WARNINGS: ("physdbg.Warning", {"type": "object", "required": ["step", "code", "message"]}),
    TOPIC_BROAD_PHASE: ("physdbg.BroadPhase", {"type": "object", "required": ["name", "reason", "stats"]}),
}


def dtype_of(fields) -> np.dtype:
    """The packed (no padding) little-endian numpy dtype of a field list."""
    return np.dtype([(name, kind, shape) if shape else (name, kind) for name, kind, shape in fields])


def array_schema_data(fields) -> bytes:
    """Schema data of an ENCODING_ARRAY channel: the field list as JSON."""
    return json.dumps({"fields": [[name, kind, list(shape)] for name, kind, shape in fields],
                       "byte_order": "little", "units": UNITS}).encode()


def dtype_from_schema(data: bytes) -> np.dtype:
    """Rebuild the row dtype from schema data (what any reader of the format does)."""
    fields = json.loads(data)["fields"]
    return np.dtype([(name, kind, tuple(shape)) if shape else (name, kind) for name, kind, shape in fields])


# ----------------------------------------------------------------------------- state codec
# Header of every /physdbg/state message, little-endian, 52 bytes:
#   magic b"PDST", version u16, codec u8, reserved u8, count u32 (N), frame u64,
#   time f64 (s, simulated, at this frame), dt f64 (s, of the step that led here; 0 at frame 0),
#   state_hash 16 bytes (BLAKE2b-128 of positions bytes then velocities bytes).
STATE_HEADER = struct.Struct("<4sHBBIQdd16s")
STATE_MAGIC = b"PDST"
STATE_VERSION = 1
# Codecs: which prediction the stored words are residuals from.
CODEC_RAW = 0  # words are the float64 bits themselves (a key frame)
CODEC_PREVIOUS = 1  # v_pred = v[k-1]; x_pred = x[k-1] + (dt*0.5)*(v[k-1] + v[k])
CODEC_TWO_PREVIOUS = 2  # v_pred = 2*v[k-1] - v[k-2]; x_pred as above
KEYFRAME_INTERVAL = 64  # a raw frame every this many frames, so frame k decodes from <= 63 back

STATE_SCHEMA = {
    "header": {"struct": "<4sHBBIQdd16s", "fields": ["magic", "version", "codec", "reserved", "count",
                                                      "frame", "time", "dt", "state_hash"]},
    "words": "6N uint64, particle-major: x, y, z, vx, vy, vz of particle 0, then particle 1, ...",
    "shuffle": "byte plane b (0..7) holds byte b (little-endian) of every word, planes in order",
    "codecs": {
        "0": "raw: word = bits of the float64",
        "1": "word = zigzag(int64(bits(value)) - int64(bits(prediction))), v_pred = v[k-1], "
             "x_pred = x[k-1] + (dt*0.5)*(v[k-1] + v[k])",
        "2": "as 1 with v_pred = 2*v[k-1] - v[k-2]",
    },
    "zigzag": "z = (r << 1) ^ (r >> 63); r = (z >> 1) ^ -(z & 1)  (64-bit, wrapping)",
}


def _zigzag(r: np.ndarray) -> np.ndarray:
    return ((r << 1) ^ (r >> 63)).view(np.uint64)


def _unzigzag(z: np.ndarray) -> np.ndarray:
    return ((z >> np.uint64(1)).view(np.int64)) ^ (-(z & np.uint64(1)).view(np.int64))


def _shuffle(words: np.ndarray) -> bytes:
    return words.view(np.uint8).reshape(-1, 8).T.tobytes()


def _unshuffle(data: bytes | memoryview, count: int) -> np.ndarray:
    planes = np.frombuffer(data, dtype=np.uint8, count=8 * count).reshape(8, count)
    return np.ascontiguousarray(planes.T).view("<u8").reshape(count)


def _velocity_prediction(codec: int, previous: np.ndarray, before_previous: np.ndarray | None) -> np.ndarray:
    if codec == CODEC_TWO_PREVIOUS:
        with np.errstate(over="ignore", invalid="ignore"):  # a poor prediction is still lossless
            return 2.0 * previous[:, 3:] - before_previous[:, 3:]
    return previous[:, 3:].copy()


def codec_for(frame: int, have_previous: int) -> int:
    """Which codec the writer uses at ``frame`` given how many earlier frames it holds."""
    if frame % KEYFRAME_INTERVAL == 0 or have_previous == 0:
        return CODEC_RAW
    if frame % KEYFRAME_INTERVAL == 1 or have_previous == 1:
        return CODEC_PREVIOUS
    return CODEC_TWO_PREVIOUS


def encode_state(frame: int, time: float, dt: float, state_hash: str, positions: np.ndarray,
                 velocities: np.ndarray, codec: int, previous: np.ndarray | None = None,
                 before_previous: np.ndarray | None = None) -> bytes:
    """One /physdbg/state message. positions, velocities: (N, 3) float64; previous,
    before_previous: (N, 6) float64 states of frames k-1 and k-2 (as codec needs)."""
    n = positions.shape[0]
    state = np.empty((n, 6))
    state[:, :3] = positions
    state[:, 3:] = velocities
    words = state.view(np.int64).copy()
    if codec != CODEC_RAW:
        v_pred = _velocity_prediction(codec, previous, before_previous)
        with np.errstate(over="ignore", invalid="ignore"):
            x_pred = previous[:, :3] + (dt * 0.5) * (previous[:, 3:] + velocities)
        words[:, :3] -= x_pred.view(np.int64)
        words[:, 3:] -= v_pred.view(np.int64)
        words = _zigzag(words)
    header = STATE_HEADER.pack(STATE_MAGIC, STATE_VERSION, codec, 0, n, frame, time, dt, bytes.fromhex(state_hash))
    return header + _shuffle(words.reshape(-1))


def decode_state_header(data: bytes) -> tuple[int, int, int, float, float, str]:
    """(codec, count, frame, time, dt, state_hash hex) of a state message."""
    if len(data) < STATE_HEADER.size:
        raise ValueError("state message shorter than its header")
    magic, version, codec, _, count, frame, time, dt, digest = STATE_HEADER.unpack_from(data)
    if magic != STATE_MAGIC or version != STATE_VERSION or codec > CODEC_TWO_PREVIOUS:
        raise ValueError("not a physdbg state message (bad magic, version or codec)")
    if len(data) != STATE_HEADER.size + 48 * count:
        raise ValueError(f"state message of {len(data)} bytes, expected {STATE_HEADER.size + 48 * count}")
    return codec, count, frame, time, dt, digest.hex()


def decode_state(data: bytes, previous: np.ndarray | None = None,
                 before_previous: np.ndarray | None = None) -> tuple[np.ndarray, int, float, float, str]:
    """(state (N, 6) float64, frame, time, dt, state_hash) of a state message.

    previous / before_previous: decoded (N, 6) states of the frames before, as the
    message's codec needs (ValueError if missing).
    """
    codec, count, frame, time, dt, digest = decode_state_header(data)
    words = _unshuffle(memoryview(data)[STATE_HEADER.size:], 6 * count).reshape(count, 6)
    if codec == CODEC_RAW:
        return words.view(np.float64).copy(), frame, time, dt, digest
    if previous is None or (codec == CODEC_TWO_PREVIOUS and before_previous is None):
        raise ValueError(f"frame {frame} needs the frames before it to decode")
    residual = _unzigzag(words)
    v_pred = _velocity_prediction(codec, previous, before_previous)
    state = np.empty((count, 6))
    state[:, 3:] = (v_pred.view(np.int64) + residual[:, 3:]).view(np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        x_pred = previous[:, :3] + (dt * 0.5) * (previous[:, 3:] + state[:, 3:])
    state[:, :3] = (x_pred.view(np.int64) + residual[:, :3]).view(np.float64)
    return state, frame, time, dt, digest
