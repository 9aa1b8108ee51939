"""Damaged and altered recordings, made on purpose: what a CI artifact, a hand edit or a
careless script can do to a file. Each function copies a recording and changes one thing,
re-writing the MCAP structure (chunks, CRCs, summary) so that only the change is wrong."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from physdbg.engine.state import state_hash
from physdbg.record import format as fmt
from physdbg.record import state_codec
from physdbg.record import open_recording
from physdbg.record import proto


def copy_with(src: Path, dst: Path, change: Callable[[str, int, bytes], list[bytes] | bytes | None]) -> Path:
    """Copy ``src`` to ``dst`` message by message; change(topic, sequence, data) gives the
    data to write instead (None: as it was; a list: several messages in its place). Every
    state is re-encoded raw, so no later frame depends on a changed one."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    rec = open_recording(src, verify=False)
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        writer = Writer(out)
        writer.start(profile="physdbg")
        channels = {}
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            if channel.id not in channels:
                schema_id = writer.register_schema(schema.name, schema.encoding, schema.data)
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding, schema_id)
            data = message.data
            if channel.topic == fmt.TOPIC_STATE:
                s = rec.state(message.sequence)
                data = state_codec.encode_state(s.frame, s.time, s.dt, s.state_hash, s.positions, s.velocities,
                                        fmt.CODEC_RAW, asleep=s.asleep)
            changed = change(channel.topic, message.sequence, data)
            for item in (changed if isinstance(changed, list) else [data if changed is None else changed]):
                writer.add_message(channels[channel.id], message.log_time, item, message.publish_time,
                                   sequence=message.sequence)
        writer.finish()
    rec.close()
    return dst


def nudge_state(src: Path, dst: Path, frame: int, sphere: int = 0, by: float = 1e-3, rehash: bool = False,
                reindex: bool = False) -> Path:
    """Move one sphere of one stored state by ``by`` metres along x. rehash: write the moved
    state's own hash into its message (else the old hash stays); reindex: also into the
    frame index (a consistent forgery, which only a re-simulation can tell)."""
    rec = open_recording(src, verify=False)
    s = rec.state(frame)
    x = s.positions.copy()
    x[sphere, 0] += by
    digest = state_hash(x, s.velocities) if rehash else s.state_hash
    rec.close()

    def change(topic, sequence, data):
        if topic == fmt.TOPIC_STATE and sequence == frame:
            return state_codec.encode_state(frame, s.time, s.dt, digest, x, s.velocities, fmt.CODEC_RAW, asleep=s.asleep)
        if topic == fmt.TOPIC_FRAME_INDEX and reindex:
            name = fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_FRAME_INDEX]
            last, rows = proto.decode_table(name, data)
            rows = rows.copy()
            rows["state_hash"][frame] = np.frombuffer(bytes.fromhex(digest), np.uint8)
            return proto.encode_table(name, last, lambda column: rows[column])
        return None

    return copy_with(src, dst, change)


def swap_frames(src: Path, dst: Path, first: int) -> Path:
    """Frames ``first`` and ``first + 1`` stored in each other's place (states only)."""
    rec = open_recording(src, verify=False)
    a, b = rec.state(first), rec.state(first + 1)
    rec.close()

    def change(topic, sequence, data):
        if topic != fmt.TOPIC_STATE or sequence not in (first, first + 1):
            return None
        s = b if sequence == first else a
        return state_codec.encode_state(s.frame, s.time, s.dt, s.state_hash, s.positions, s.velocities, fmt.CODEC_RAW,
                                asleep=s.asleep)

    return copy_with(src, dst, change)


def second_scene(src: Path, dst: Path) -> Path:
    """A second /physdbg/scene message: two recordings' headers in one file."""
    return copy_with(src, dst, lambda topic, sequence, data: [data, data] if topic == fmt.TOPIC_SCENE else None)


def concatenate(parts: list[Path], dst: Path) -> Path:
    """The files one after another, as `cat a.mcap b.mcap > dst` makes them."""
    dst.write_bytes(b"".join(p.read_bytes() for p in parts))
    return dst


def edit_contact(src: Path, dst: Path, frame: int, **fields) -> Path:
    """The first contact of ``frame`` with ``fields`` changed (e.g. kind=2: a collider kind
    from a physdbg that knows more of them; impulse=...: a hand edit)."""
    name = fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_CONTACTS]

    def change(topic, sequence, data):
        if topic != fmt.TOPIC_CONTACTS or sequence != frame:
            return None
        step, rows = proto.decode_table(name, data)
        rows = rows.copy()
        for field, value in fields.items():
            rows[field][0] = value
        return proto.encode_table(name, step, lambda column: rows[column])

    return copy_with(src, dst, change)


def with_setting(src: Path, dst: Path, setting: str, value) -> Path:
    """The recording's settings say ``setting`` = ``value`` (as a newer physdbg's might)."""
    import json

    def change(topic, sequence, data):
        if topic != fmt.TOPIC_SCENE:
            return None
        meta = json.loads(data)
        meta["settings"][setting] = value
        return json.dumps(meta).encode()

    return copy_with(src, dst, change)


def damage_byte(src: Path, dst: Path, offset: int) -> Path:
    """Copy ``src`` with one bit of the byte at ``offset`` flipped (a bad disk or a bad copy:
    nothing re-written around it)."""
    data = bytearray(Path(src).read_bytes())
    data[offset] ^= 0x20
    Path(dst).write_bytes(bytes(data))
    return dst


def chunk_places(path: Path) -> list[tuple[int, set[str]]]:
    """(byte in the middle of the chunk, topics it holds) of every chunk, from the summary."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    topics = {cid: c.topic for cid, c in summary.channels.items()}
    return [(c.chunk_start_offset + c.chunk_length // 2, {topics[k] for k in c.message_index_offsets})
            for c in summary.chunk_indexes]


def summary_schema_byte(path: Path) -> int:
    """A byte of a schema name in the summary section (found from the footer)."""
    import struct

    data = Path(path).read_bytes()
    summary_start = struct.unpack("<Q", data[-8 - 20:-8 - 12])[0]
    return data.index(b"physdbg.Particle", summary_start) + 5
