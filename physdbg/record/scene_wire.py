"""The view's per-frame scene (Foxglove ``SceneEntity`` spheres and contact arrows),
written in protobuf's wire format with numpy.

Every frame of ``/view/scene`` holds one entity per sphere ("sphere 17": a stable id that
Foxglove shows on a click: a ``SpherePrimitive`` of its diameter and colour at its centre)
and, at detail contacts or full, an arrow per drawn contact. Built with the protobuf
library they took ~5 µs a sphere and ~2 µs an arrow (a message object each, a Python float
per value): at 1k spheres 4.8 ms a frame for the spheres and 2 ms for a pile's arrows, most
of what the view channels cost (docs/recording.md). Here the library writes only what does
not change between rows or frames (ids, sizes, colours, the timestamp) and numpy writes
each row's varying doubles and lengths, side by side in one matrix per message list: the
library's bytes for the same messages (tests/test_scene_wire.py holds them equal: zeros,
-0.0, NaN, two-byte lengths).

The wire format as the library writes it: fields in the order of their numbers; a
length-delimited field is its tag, its length as a varint, then its bytes; a double is its
tag and 8 little-endian bytes, left out when all its bits are 0 (proto3: 0.0 is the
default; -0.0 is written); a sub-message once touched is written, even when empty.
"""

from __future__ import annotations

import numpy as np

from .proto import varint

LONGEST = 1 << 14  # a row's sub-message lengths here take at most two varint bytes


class Rows:
    """N rows of protobuf bytes built side by side: blocks of (N, w) uint8 and which of
    their bytes each row keeps ((N, w) bool); ``tobytes`` joins each row's kept bytes, row
    after row."""

    def __init__(self, count: int):
        self.count = count
        self.blocks: list[tuple[np.ndarray, np.ndarray]] = []
        self.length = np.zeros(count, dtype=np.int64)  # bytes each row keeps so far

    def _add(self, data: np.ndarray, keep: np.ndarray, length=None) -> Rows:
        self.blocks.append((data, keep))
        self.length += keep.sum(axis=1) if length is None else length
        return self

    def const(self, piece: bytes) -> Rows:
        """The same bytes in every row."""
        shape = (self.count, len(piece))
        return self._add(np.broadcast_to(np.frombuffer(piece, dtype=np.uint8), shape),
                         np.broadcast_to(True, shape), len(piece))

    def ragged(self, data: np.ndarray, keep: np.ndarray, length: np.ndarray) -> Rows:
        """Each row's own bytes (ragged_rows' triple)."""
        return self._add(data, keep, length)

    def doubles(self, first_field: int, values: np.ndarray) -> Rows:
        """Double fields first_field, first_field + 1, ... of values (N, K), each left out
        where its bits are all 0."""
        k = values.shape[1] if values.ndim == 2 else 1
        raw = np.ascontiguousarray(values, dtype="<f8").reshape(self.count, k).view(np.uint8).reshape(self.count, k, 8)
        data = np.empty((self.count, k, 9), dtype=np.uint8)
        data[:, :, 0] = [(first_field + j) << 3 | 1 for j in range(k)]
        data[:, :, 1:] = raw
        present = raw.any(axis=2)
        return self._add(data.reshape(self.count, 9 * k), np.repeat(present, 9, axis=1), 9 * present.sum(axis=1))

    def field(self, tag: int, body: Rows) -> Rows:
        """A length-delimited field of tag ``tag`` (one byte) holding each row of body."""
        length = body.length
        if self.count and int(length.max()) >= LONGEST:
            raise ValueError(f"a message of {int(length.max())} bytes: longer than this encoder writes")
        long = length >= 128
        head = np.empty((self.count, 3), dtype=np.uint8)
        head[:, 0] = tag
        head[:, 1] = np.where(long, (length & 0x7F) | 0x80, length)
        head[:, 2] = length >> 7
        keep = np.ones((self.count, 3), dtype=bool)
        keep[:, 2] = long
        self.blocks.append((head, keep))
        self.blocks += body.blocks
        self.length += 2 + long + length
        return self

    def tobytes(self) -> bytes:
        if not self.blocks or not self.count:
            return b""
        data = np.concatenate([d for d, _ in self.blocks], axis=1)
        keep = np.concatenate([k for _, k in self.blocks], axis=1)
        return data[keep].tobytes()


def ragged_rows(pieces: list[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows.ragged's arguments for rows holding these pieces: (R, W) uint8 rows, each piece
    left-aligned; (R, W) bool, which bytes are the piece's; (R,) each piece's length."""
    width = max((len(p) for p in pieces), default=0)
    data = np.zeros((len(pieces), width), dtype=np.uint8)
    keep = np.zeros((len(pieces), width), dtype=bool)
    for r, piece in enumerate(pieces):
        data[r, :len(piece)] = np.frombuffer(piece, dtype=np.uint8)
        keep[r, :len(piece)] = True
    return data, keep, np.array([len(p) for p in pieces], dtype=np.int64)


def _pick(pieces: list[bytes], which: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ragged_rows of rows r = pieces[which[r]]."""
    return tuple(part[which] for part in ragged_rows(pieces))


def _oriented(points: np.ndarray, rotations: np.ndarray | None, orientation: bytes = b"") -> Rows:
    """Pose rows: position (N, 3) and orientation (N, 4) quaternions (x, y, z, w), or the
    bytes of one orientation for every row."""
    count = len(points)
    pose = Rows(count).field(0x0A, Rows(count).doubles(1, points))
    if rotations is None:
        return pose.const(orientation)
    return pose.field(0x12, Rows(count).doubles(1, rotations))


class SphereEntities:
    """The spheres' entities of one run.

    frame_id: the entities' frame; diameters (N,) m; colors: (N, 4) RGBA in [0, 1] (set
    again with ``set_colors`` when they change: a sphere falls asleep)."""

    def __init__(self, frame_id: str, diameters: np.ndarray, colors: np.ndarray):
        from foxglove_schemas_protobuf.Pose_pb2 import Pose
        from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
        from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive

        self._entity, self._sphere = SceneEntity, SpherePrimitive
        self.frame_id = frame_id
        self.count = len(diameters)
        self._ids = ragged_rows([SceneEntity(id=f"sphere {i}").SerializeToString() for i in range(self.count)])
        pose = Pose()
        pose.orientation.w = 1.0
        self._orientation = pose.SerializeToString()[len(Pose().SerializeToString()):]  # 0x12 len, w = 1
        sizes, self._size_of = np.unique(np.asarray(diameters, dtype=np.float64), return_inverse=True)
        self._sizes = []
        for d in sizes.tolist():
            primitive = SpherePrimitive()
            primitive.size.x = primitive.size.y = primitive.size.z = d
            self._sizes.append(primitive.SerializeToString())
        self.set_colors(colors)

    def set_colors(self, colors: np.ndarray) -> None:
        """(N, 4) RGBA in [0, 1]: each sphere's colour from now on."""
        unique, which = np.unique(np.asarray(colors, dtype=np.float64).reshape(-1, 4), axis=0, return_inverse=True)
        tails = {}
        for c, color in enumerate(unique.tolist()):
            primitive = self._sphere()
            primitive.color.r, primitive.color.g, primitive.color.b, primitive.color.a = color
            for s, size in enumerate(self._sizes):
                tails[(s, c)] = size + primitive.SerializeToString()  # size, then colour
        keys = list(tails)
        index = {key: i for i, key in enumerate(keys)}
        which = np.array([index[(s, c)] for s, c in zip(self._size_of.tolist(), which.reshape(-1).tolist())],
                         dtype=np.int64)
        self._tails = _pick([tails[key] for key in keys], which)

    def encode(self, ns: int, positions: np.ndarray) -> bytes:
        """SceneUpdate's ``entities`` (field 2) of every sphere at ``positions`` (N, 3) m,
        each stamped ``ns`` (nanoseconds)."""
        head = self._entity(frame_id=self.frame_id)
        head.timestamp.FromNanoseconds(ns)
        n = self.count
        pose = _oriented(np.asarray(positions, dtype=np.float64).reshape(n, 3), None, self._orientation)
        sphere = Rows(n).field(0x0A, pose).ragged(*self._tails)
        entity = Rows(n).const(head.SerializeToString()).ragged(*self._ids).field(0x4A, sphere)
        return Rows(n).field(0x12, entity).tobytes()


# the arrows' colours (RGBA): a contact resolved as it came, and one held or resting
ARROW_COLOR = (0.3, 0.86, 0.47, 1.0)
RESTING_ARROW_COLOR = (0.5, 0.5, 0.9, 1.0)


def arrows(points: np.ndarray, rotations: np.ndarray, lengths: np.ndarray, resting: np.ndarray) -> bytes:
    """SceneEntity's ``arrows`` (field 7) of M contacts: ArrowPrimitives at points (M, 3)
    turned by rotations (M, 4) (x, y, z, w) from +x, of lengths (M,) m (shaft 0.7, head
    0.3, shaft diameter 0.08, head diameter 0.2 of it), coloured by resting (M,) bool."""
    from foxglove_schemas_protobuf.ArrowPrimitive_pb2 import ArrowPrimitive

    m = len(points)
    colors = []
    for rgba in (ARROW_COLOR, RESTING_ARROW_COLOR):
        arrow = ArrowPrimitive()
        arrow.color.r, arrow.color.g, arrow.color.b, arrow.color.a = rgba
        colors.append(arrow.SerializeToString())
    length = np.asarray(lengths, dtype=np.float64)
    # ArrowPrimitive fields 2-5: shaft_length, shaft_diameter, head_length, head_diameter
    sizes = np.stack([0.7 * length, 0.08 * length, 0.3 * length, 0.2 * length], axis=1)
    arrow = (Rows(m).field(0x0A, _oriented(np.asarray(points, dtype=np.float64), np.asarray(rotations, np.float64)))
             .doubles(2, sizes).ragged(*_pick(colors, np.asarray(resting, dtype=bool).astype(np.int64))))
    return Rows(m).field(0x3A, arrow).tobytes()


def entity_field(entity: bytes) -> bytes:
    """One SceneEntity's bytes as SceneUpdate's ``entities`` field: its tag, length and
    the bytes."""
    return b"\x12" + varint(len(entity)) + entity
