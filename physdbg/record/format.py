"""The physdbg recording format: MCAP channels, schemas and the packed state codec.

Everything a reader needs to know lives here and in docs/recording-format.md (a test
checks that the document names every channel and field defined below). Nothing in this
module touches files; :mod:`.mcap_sink` writes and :mod:`.reader` reads.

Every channel uses a standard MCAP encoding, so any MCAP tool decodes every message:
``protobuf`` (the FileDescriptorSet is the schema; built from the field lists below by
:mod:`.proto`) or ``json`` with a JSON Schema that has ``properties`` for every field.

Time base: an MCAP message's ``log_time`` (and ``publish_time``) is the **simulated time**
of its frame in nanoseconds, made strictly increasing (a frame whose rounded time does not
exceed the previous frame's gets the previous one + 1 ns), so MCAP tools show the run's
real duration. The step number is a field of every message (``step``; also the MCAP
``sequence``): frame 0 is the initial state, frame k the state after the k-th step, and
every message about the k-th step has ``step`` k and frame k's ``log_time``. The
/physdbg/frame_index message maps steps to log times for random access.
"""

from __future__ import annotations

import numpy as np

from .. import events
from ..events import CONTACT_FIELDS

FORMAT_NAME = "physdbg-recording"
FORMAT_VERSION = 2
PROFILE = "physdbg"

ENCODING_PROTOBUF = "protobuf"  # message and schema encoding (schema data: a FileDescriptorSet)
ENCODING_JSON = "json"  # UTF-8 JSON object; schema encoding "jsonschema"
SCHEMA_JSON = "jsonschema"

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
TOPIC_FRAME_INDEX = "/physdbg/frame_index"  # once, at the end: every frame's time, log time, dt and hash
# a scene with meshes, detail >= contacts: the trees the engine walks (once, frame 0), and every
# step's walks of them: the boxes asked (queries) and the nodes visited (at detail contacts only
# the visits on the way to a triangle the step had a contact with)
TOPIC_MESH_TREE = "/physdbg/mesh_tree"
TOPIC_MESH_QUERIES = "/physdbg/mesh_queries"
TOPIC_MESH_SEARCH = "/physdbg/mesh_search"
MESH_TOPICS = (TOPIC_MESH_TREE, TOPIC_MESH_QUERIES, TOPIC_MESH_SEARCH)

# View channels (Foxglove's published schemas), written unless --no-view: what Foxglove's
# 3D, Plot and Log panels and rerun's MCAP importer show without knowing physdbg.
TOPIC_VIEW_SCENE = "/view/scene"  # foxglove.SceneUpdate: spheres, walls, contact arrows
TOPIC_VIEW_POINTS = "/view/points"  # foxglove.PointCloud: sphere centres (float64 x, y, z), radius, id
TOPIC_VIEW_LOG = "/view/log"  # foxglove.Log: contacts and warnings in words
TOPIC_VIEW_TRANSFORM = "/view/transform"  # foxglove.FrameTransform: the scene's frame in Foxglove's z-up world
VIEW_TOPICS = (TOPIC_VIEW_SCENE, TOPIC_VIEW_POINTS, TOPIC_VIEW_LOG, TOPIC_VIEW_TRANSFORM)
VIEW_SCHEMAS = {
    TOPIC_VIEW_SCENE: "foxglove.SceneUpdate", TOPIC_VIEW_POINTS: "foxglove.PointCloud",
    TOPIC_VIEW_LOG: "foxglove.Log", TOPIC_VIEW_TRANSFORM: "foxglove.FrameTransform",
}
VIEW_WORLD_FRAME = "world"  # Foxglove's display frame (z up)
VIEW_SCENE_FRAME = "scene"  # the engine's coordinates (y up unless gravity points down z)

# The bulky per-step channels are written in chunks of their own, so reading states,
# stats and contacts (diff, explain, a replay, every integrity check) never decompresses
# them: the swept tests and the broad phase, and the view channels (a gas of 1 000 spheres
# holds 3 bytes of /view/scene for every byte of /physdbg/state, and 21 /view/log messages a step).
HEAVY_TOPICS = frozenset({"/physdbg/swept_tests", "/physdbg/broad_phase", "/physdbg/bvh", "/physdbg/bvh_order",
                          "/physdbg/mesh_queries", "/physdbg/mesh_search", *VIEW_TOPICS})

TOPICS_BY_DETAIL = {
    "state": (TOPIC_SCENE, TOPIC_PARTICLES, TOPIC_WALLS, TOPIC_STATE, TOPIC_STATS, TOPIC_WARNINGS,
              TOPIC_FRAME_INDEX),
    "contacts": (TOPIC_CONTACTS, *MESH_TOPICS),
    "full": (TOPIC_SWEPT, TOPIC_BROAD_PHASE, TOPIC_BVH, TOPIC_BVH_ORDER),
}


def topics_for(detail: str, view: bool = False) -> tuple[str, ...]:
    """Every topic a recording at ``detail`` may hold (with the view channels if ``view``)."""
    out: tuple[str, ...] = ()
    for level in DETAIL_LEVELS:
        out += TOPICS_BY_DETAIL[level]
        if level == detail:
            return out + (VIEW_TOPICS if view else ())
    raise ValueError(f"unknown detail level {detail!r}")


# ----------------------------------------------------------------------------- array schemas
# (name, numpy dtype, shape) rows; units and meanings are in the format document.
PARTICLE_FIELDS = [
    ("radius", "<f8", ()), ("inverse_mass", "<f8", ()), ("restitution", "<f8", ()), ("gravity_scale", "<f8", ()),
]
# /physdbg/stats: one row a step, its columns derived from the step record (events.StepEnd:
# its StepCounts and STEP_PHASES) and the collision sums. A protobuf field's number is its
# column's place in this order, which never changes (files are decoded by number); a count
# or phase the step record gains becomes a new column at the end, with no edit here, and a
# recording made before a column existed reads 0 there. ``held`` was written as
# ``resting`` (the same field number: old files read the same).
_STATS_NUMBERED = (
    "time", "dt", "kinetic", "potential", "energy", "momentum", "contacts", "swept_tests", "events", "held", "rapid",
    "max_overlap", "seconds_forces", "seconds_broad_phase", "seconds_narrow_phase", "seconds_resolve",
    "seconds_finish", "temperature", "virial", "wall_impulse", "collisions", "released", "asleep", "slept", "woken",
)
STEP_COUNTS = events.STEP_COUNTS
_STATS_COLUMNS = _STATS_NUMBERED + tuple(
    name for name in (*STEP_COUNTS, *(f"seconds_{phase}" for phase in events.STEP_PHASES))
    if name not in _STATS_NUMBERED)


def _stats_column(name: str) -> tuple[str, str, tuple]:
    if name == "momentum":
        return (name, "<f8", (3,))
    return (name, "<i8" if name in STEP_COUNTS or name == "collisions" else "<f8", ())


STATS_FIELDS = [_stats_column(name) for name in _STATS_COLUMNS]
# CONTACT_FIELDS is the engine's own contact row (imported from events: the loop's buffer,
# the event and this table are one schema). Files written before its ``how`` column was
# named hold the same column, under the same protobuf field number, as ``resting``;
# messages are decoded by field number, so they read the same.
SWEPT_FIELDS = [
    ("kind", "i1", ()), ("outcome", "i1", ()), ("a", "<i4", ()), ("other", "<i4", ()),
    ("start", "<f8", ()), ("toi", "<f8", ()),
]
BVH_FIELDS = [
    ("node", "<i4", ()), ("depth", "<i4", ()), ("left", "<i4", ()), ("right", "<i4", ()), ("parent", "<i4", ()),
    ("start", "<i4", ()), ("count", "<i4", ()), ("lo", "<f8", (3,)), ("hi", "<f8", (3,)),
]
BVH_ORDER_FIELDS = [("particle", "<i4", ())]
# the meshes' trees as the engine walks them (engine/colliders/mesh.py MeshGeometry): every
# mesh's tree in pre-order, one after another; a node's box is in its mesh's frame at run time 0
MESH_TREE_FIELDS = [
    ("node", "<i4", ()), ("mesh", "<i4", ()), ("parent", "<i4", ()), ("depth", "<i4", ()), ("triangle", "<i4", ()),
    ("skip", "<i4", ()), ("lo", "<f8", (3,)), ("hi", "<f8", (3,)), ("volume", "i1", ()),
    ("sphere_center", "<f8", (3,)), ("sphere_radius", "<f8", ()), ("obb_center", "<f8", (3,)),
    ("obb_axis_0", "<f8", (3,)), ("obb_axis_1", "<f8", (3,)), ("obb_axis_2", "<f8", (3,)), ("obb_half", "<f8", (3,)),
]
MESH_QUERY_FIELDS = [("sphere", "<i4", ()), ("after", "<i4", ()), ("lo", "<f8", (3,)), ("hi", "<f8", (3,))]
MESH_VISIT_FIELDS = [("query", "<i4", ()), ("node", "<i4", ()), ("outcome", "i1", ()), ("parent", "<i4", ())]
FRAME_INDEX_FIELDS = [("time", "<f8", ()), ("log_time", "<u8", ()), ("dt", "<f8", ()), ("state_hash", "u1", (16,))]


# The protobuf message of each channel: name -> (field list, table?). A table holds many
# rows per message (repeated fields); a row message holds one record (plain fields).
MESSAGE_OF_TOPIC = {
    TOPIC_PARTICLES: "physdbg.Particles", TOPIC_STATS: "physdbg.StepStats", TOPIC_CONTACTS: "physdbg.Contacts",
    TOPIC_SWEPT: "physdbg.SweptTests", TOPIC_BVH: "physdbg.BvhNodes", TOPIC_BVH_ORDER: "physdbg.BvhOrder",
    TOPIC_FRAME_INDEX: "physdbg.FrameIndex", TOPIC_STATE: "physdbg.State",
    TOPIC_MESH_TREE: "physdbg.MeshTree", TOPIC_MESH_QUERIES: "physdbg.MeshQueries",
    TOPIC_MESH_SEARCH: "physdbg.MeshSearch",
}
PROTOBUF_MESSAGES = {
    "physdbg.Particles": (PARTICLE_FIELDS, True),
    "physdbg.StepStats": (STATS_FIELDS, False),
    "physdbg.Contacts": (CONTACT_FIELDS, True),
    "physdbg.SweptTests": (SWEPT_FIELDS, True),
    "physdbg.BvhNodes": (BVH_FIELDS, True),
    "physdbg.BvhOrder": (BVH_ORDER_FIELDS, True),
    "physdbg.FrameIndex": (FRAME_INDEX_FIELDS, True),
    "physdbg.MeshTree": (MESH_TREE_FIELDS, True),
    "physdbg.MeshQueries": (MESH_QUERY_FIELDS, True),
    "physdbg.MeshSearch": (MESH_VISIT_FIELDS, True),
}
STATE_MESSAGE = "physdbg.State"
# after ``step``: (name, numpy kind or "bytes"); ``words`` is the packed state below;
# ``asleep``: the spheres asleep after this frame's step, np.packbits of the (N,) mask
# (sphere i is bit 7 - i % 8 of byte i // 8), empty when the run does not let spheres sleep
STATE_MESSAGE_FIELDS = [("time", "<f8"), ("dt", "<f8"), ("state_hash", "bytes"), ("codec", "<u4"),
                        ("count", "<u4"), ("words", "bytes"), ("asleep", "bytes")]

# JSON channels. /physdbg/scene and /physdbg/walls are written once and their schema is
# made from the message itself (json_schema_of), so it names every field of that file's
# scene table; the per-step ones have fixed schemas. Foxglove's JSON Schema parser takes
# one "type" per field (no "null", no type lists) and no nested arrays; null values are
# therefore left out of every JSON message (a missing key reads as None).
BROAD_PHASE_STATS = {
    "pairs": "number", "cell": "number", "cells_used": "number", "rebuilt": "boolean", "build_seconds": "number",
    "sah_cost": "number", "nodes": "number", "depth": "number", "query_seconds": "number",
    "nodes_visited": "number", "box_tests": "number", "images": "number", "scanned": "boolean",
    "mesh_search": "string",
}
JSON_SCHEMAS = {
    TOPIC_WARNINGS: ("physdbg.Warning", {"type": "object", "properties": {
        "step": {"type": "number"}, "code": {"type": "string"}, "message": {"type": "string"},
        "bodies": {"type": "array", "items": {"type": "number"}}},
        "required": ["step", "code", "message"]}),
    TOPIC_BROAD_PHASE: ("physdbg.BroadPhase", {"type": "object", "properties": {
        "step": {"type": "number"}, "name": {"type": "string"}, "reason": {"type": "string"},
        "stats": {"type": "object", "properties": {k: {"type": t} for k, t in BROAD_PHASE_STATS.items()}},
        "bvh_nodes": {"type": "number"}, "bvh_depth": {"type": "number"}, "bvh_logged_depth": {"type": "number"}},
        "required": ["step", "name", "reason", "stats"]}),
}
JSON_SCHEMAS[TOPIC_WALLS] = ("physdbg.Walls", {"type": "object", "properties": {
    "step": {"type": "number"},
    "walls": {"type": "array", "items": {"type": "object", "properties": {
        "name": {"type": "string"}, "normal": {"type": "array", "items": {"type": "number"}},
        "offset": {"type": "number"}, "restitution": {"type": "number"}, "two_sided": {"type": "boolean"},
        "thickness": {"type": "number"}}}},
    # periodic axes: period (m, 0 = not periodic) and the box's lower corner on them
    "period": {"type": "array", "items": {"type": "number"}},
    "period_origin": {"type": "array", "items": {"type": "number"}},
    # meshes: corners (m, world frame, at run time 0) of each triangle, 9 numbers a
    # triangle; a kinematic mesh also its velocity (m/s), angular velocity (rad/s) and
    # pivot (m, at time 0): at time t a corner c is at R(w t)(c - pivot) + pivot + v t
    "meshes": {"type": "array", "items": {"type": "object", "properties": {
        "name": {"type": "string"}, "source": {"type": "string"}, "restitution": {"type": "number"},
        "bounding_volume": {"type": "string"},
        "corners": {"type": "array", "items": {"type": "number"}},
        "velocity": {"type": "array", "items": {"type": "number"}},
        "angular_velocity": {"type": "array", "items": {"type": "number"}},
        "pivot": {"type": "array", "items": {"type": "number"}}}}},
    # partners of a collider kind whose module declares its fields, by the kind's name:
    # one object per partner, its name and each field (docs/colliders.md)
    "partners": {"type": "object"}},
    "required": ["step", "walls"]})
SCENE_SCHEMA_NAME = "physdbg.Scene"  # its JSON Schema is json_schema_of(the message)


def foxglove_json(value):
    """``value`` as a JSON message for Foxglove: every None (and non-finite float) dict
    entry left out, recursively (its schema subset has no null)."""
    if isinstance(value, dict):
        return {k: foxglove_json(v) for k, v in value.items()
                if v is not None and not (isinstance(v, float) and not np.isfinite(v))}
    if isinstance(value, list):
        return [foxglove_json(v) for v in value]
    return value


def json_schema_of(value) -> dict:
    """A JSON Schema with ``properties`` for every field of ``value`` (a JSON object with
    no nulls), in the subset Foxglove parses: objects, arrays of one item type, strings,
    numbers (every number is "number": Foxglove reads "integer" as uint32), booleans.
    Lists of objects get the union of their items' properties. Foxglove cannot show a list
    of lists, so none is written (the scene's table, which may hold them, is a string)."""
    if isinstance(value, bool):
        return {"type": "boolean"}
    if isinstance(value, (int, float)):
        return {"type": "number"}
    if isinstance(value, str):
        return {"type": "string"}
    if isinstance(value, dict):
        return {"type": "object", "properties": {k: json_schema_of(v) for k, v in value.items()}}
    if isinstance(value, list):
        objects = [v for v in value if isinstance(v, dict)]
        if objects:
            merged: dict = {}
            for item in objects:
                merged.update(item)
            return {"type": "array", "items": json_schema_of(merged)}
        if any(isinstance(v, list) for v in value):
            raise TypeError("a list of lists has no schema Foxglove can read")
        return {"type": "array", "items": json_schema_of(value[0]) if value else {"type": "string"}}
    raise TypeError(f"no JSON Schema for {type(value).__name__}")


def dtype_of(fields) -> np.dtype:
    """The packed (no padding) little-endian numpy dtype of a field list."""
    return np.dtype([(name, kind, shape) if shape else (name, kind) for name, kind, shape in fields])


MAX_NANOSECONDS = 2**64 - 1


def frame_nanoseconds(seconds: float, previous: int) -> int:
    """The log time (ns) of a frame at ``seconds`` after a frame logged at ``previous`` ns
    (-1 for the first frame): the rounded time, saturating, and at least previous + 1."""
    try:
        ns = int(round(float(seconds) * 1e9))
    except (ValueError, OverflowError):  # NaN or infinite time: keep the order, nothing else
        ns = previous + 1
    return min(max(ns, previous + 1, 0), MAX_NANOSECONDS)


# ----------------------------------------------------------------------------- state codec
# A /physdbg/state message is a protobuf physdbg.State: step, time (s, simulated, at this
# frame), dt (s, of the step that led here; 0 at frame 0), state_hash (16 bytes, BLAKE2b-128
# of positions bytes then velocities bytes), codec, count (N) and words: the 6N 64-bit
# words below, byte-shuffled.
# Codecs: which prediction the stored words are residuals from.
CODEC_RAW = 0  # words are the float64 bits themselves (a key frame)
CODEC_PREVIOUS = 1  # v_pred = v[k-1]; x_pred = x[k-1] + (dt*0.5)*(v[k-1] + v[k])
CODEC_TWO_PREVIOUS = 2  # v_pred = 2*v[k-1] - v[k-2]; x_pred as above
KEYFRAME_INTERVAL = 64  # a raw frame every this many frames, so frame k decodes from <= 63 back
# (encoded and decoded by :mod:`.state_codec`)
