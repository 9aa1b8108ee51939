"""Reading recordings back: ``open_recording(path)``.

>>> rec = open_recording("recordings/bounce.mcap")          # doctest: +SKIP
>>> rec.steps, rec.state(120).positions[0]                  # doctest: +SKIP

Frames count steps completed: frame 0 is the initial state, frame k the state after the
k-th step (see :mod:`.format`). Every message carries its step number (the MCAP
``sequence``) and frame k's simulated time as its log time; the /physdbg/frame_index
message maps one to the other, so ``state(k)`` reads only the chunks holding frames from
the key frame before k up to k. A file whose writer was killed (no summary) is read
sequentially up to its last complete chunk and its last complete step; ``truncated`` says so.

Integrity (docs/recording.md, "Integrity"). A file is one recording: its summary's CRC
must match (a damaged summary, or two files joined into one, fails it) and it holds one
scene message. With ``verify`` (the default), every state the reader decodes is checked
as it streams by: its decoded positions and velocities must give the hash stored with
them, that hash must be the frame index's for the frame, and frames must arrive in order
(0, 1, 2, ...). A mismatch raises RecordingIntegrityError naming the file and the frame.
``checked_frames`` counts the frames so checked (each once).
"""

from __future__ import annotations

import json
import re
import sys
from contextlib import ExitStack, contextmanager
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..engine.state import state_hash
from ..errors import RecordingError, RecordingIntegrityError
from ..events import (STEP_COUNTS, BroadPhaseInfo, check_kinds, Contacts, EngineWarning, MeshSearch, StepBegin,
                      StepCounts, StepEnd, SweptTests)
from . import format as fmt
from . import proto
from .state_codec import decode_state, decode_state_header
from .header import RecordingHeader, current_name

MCAP_MAGIC = b"\x89MCAP0\r\n"
FOOTER_BYTES = 1 + 8 + 8 + 8 + 4  # opcode, record length, summary_start, summary_offset_start, summary_crc
OPCODE_FOOTER = 0x02
OPCODE_DATA_END = 0x0F
OPCODE_CHUNK = 0x06
DATA_END_BYTES = 1 + 8 + 4  # opcode, record length, data_section_crc

@dataclass(frozen=True)
class FrameState:
    """The state at one frame. positions, velocities: (N, 3) float64, m and m/s; time: s;
    dt: s of the step that led here (0 at frame 0); state_hash: as the engine computed it;
    asleep: (N,) bool, the spheres asleep, or None when the run did not let spheres sleep
    (and at frame 0)."""

    frame: int
    time: float
    dt: float
    positions: np.ndarray
    velocities: np.ndarray
    state_hash: str
    asleep: np.ndarray | None = None


class StateStream:
    """Decodes one recording's state messages in order, as they stream by (each state is
    coded against the one or two before it), checking each as the recording's ``verify``
    says. ``share`` takes a state another stream decoded from the same bytes, when this
    file's message is byte for byte that one: ``diff`` of two equivalent runs decodes
    each state once, not twice."""

    def __init__(self, rec: Recording):
        self.rec = rec
        self.history: list[np.ndarray] = []  # the (N, 6) states of the last two frames
        self.expected: int | None = None
        self.shared = 0  # how many of the latest frames are another stream's states

    def decode(self, frame: int, data: bytes, check: bool = True) -> FrameState:
        """The FrameState of message ``data`` (MCAP sequence ``frame``)."""
        rec, history = self.rec, self.history
        try:
            state, frame_no, time, dt, digest, asleep = decode_state(
                data, history[-1] if history else None, history[-2] if len(history) > 1 else None)
        except ValueError as err:
            raise RecordingError(f"{rec.path}: frame {frame}: damaged state message ({err})") from None
        self._in_order(frame, frame_no)
        self.history = [*history[-1:], state]
        self.shared = 0
        out = FrameState(frame_no, time, dt, state[:, :3].copy(), state[:, 3:].copy(), digest, asleep)
        if rec.verify and check:
            rec._check_state(out)
        return out

    def can_share(self, frame: int, other: StateStream) -> bool:
        """Whether a message byte for byte the other stream's at ``frame`` decodes, here, to
        the other's state: the frames it is coded against were shared too (a key frame
        needs none, the frame after it one)."""
        needs = 0 if frame % fmt.KEYFRAME_INTERVAL == 0 else 1 if frame % fmt.KEYFRAME_INTERVAL == 1 else 2
        return self.shared >= needs and self.expected == other.expected - 1

    def share(self, frame: int, state: FrameState, other: StateStream) -> FrameState:
        """Take the other stream's just-decoded ``state`` for this file's frame (whose message
        is the same bytes): it gives its hash already; the index is checked against it."""
        self._in_order(frame, state.frame)
        self.history = list(other.history)
        self.shared += 1
        if self.rec.verify:
            self.rec._check_state(state, hashed=False)
        return state

    def _in_order(self, frame: int, frame_no: int) -> None:
        if self.expected is None:
            self.expected = frame
        if self.rec.verify and not frame == frame_no == self.expected:
            raise RecordingIntegrityError(f"{self.rec.path}: frames out of order: frame {frame_no} (MCAP sequence "
                                          f"{frame}) where frame {self.expected} belongs")
        self.expected += 1


@dataclass(frozen=True)
class FrameTable:
    """Per frame (F = frames): time (F,) s; dt (F,) s of the step that led there (0 at
    frame 0); hashes (F, 16) uint8, the stored state hash (BLAKE2b-128) of each frame."""

    time: np.ndarray
    dt: np.ndarray
    hashes: np.ndarray

    def hash_hex(self, frame: int) -> str:
        return self.hashes[frame].tobytes().hex()


@dataclass(frozen=True)
class ChannelInfo:
    topic: str
    message_encoding: str
    schema_name: str
    messages: int


def open_recording(path: str | Path, verify: bool = True) -> Recording:
    """Open a .mcap recording for reading (RecordingError if it is not one). verify: check
    every state read against its stored hash and the frame index (see the module doc)."""
    return Recording(path, verify=verify)


@contextmanager
def opened(*sources, verify: bool = True) -> Iterator[list[Recording]]:
    """The recordings of ``sources`` (paths, or Recordings used as given), in order; the
    ones opened here are closed on leaving, also when opening a later one fails."""
    with ExitStack() as stack:
        yield [source if isinstance(source, Recording) else stack.enter_context(open_recording(source, verify))
               for source in sources]


class Recording:
    """A physdbg recording. Attributes: path, header (RecordingHeader), meta (dict),
    frames (states held, frame 0 included), steps (= frames - 1), detail, truncated,
    verify (states are checked as they are read), checked_frames (how many were)."""

    def __init__(self, path: str | Path, verify: bool = True):
        self.path = Path(path)
        self.verify = verify
        try:
            # a FIFO or device would block or never end: only regular files are recordings
            if self.path.exists() and not self.path.is_file():
                raise RecordingError(f"{path}: not a regular file (a recording is an .mcap file)")
            self._file = open(self.path, "rb")
        except OSError as err:
            raise RecordingError(f"{path}: cannot open ({err.strerror or err})") from None
        try:
            self._open()
        except RecordingError:
            self._file.close()
            raise
        except Exception as err:  # anything the mcap library raises on a damaged file
            self._file.close()
            raise RecordingError(f"{path}: not a readable physdbg recording ({type(err).__name__}: {err})") from None

    # ------------------------------------------------------------------ opening
    def _open(self) -> None:
        from mcap.reader import SeekingReader

        if self._file.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise RecordingError(f"{self.path}: not an MCAP file (a physdbg recording starts with the MCAP magic bytes)")
        self._file.seek(0)
        self._reader = SeekingReader(self._file, validate_crcs=True)
        self._recovered: list[tuple[int, dict[str, list[int]]]] | None = None  # a file without summary
        self._last_chunk: tuple[int, list] = (-1, [])  # _chunk_records' one-chunk cache
        self._frame_table: FrameTable | None = None
        self._index_checked = False  # the frame index's hashes are the states' (set as states are read)
        self.truncated = False
        summary = None
        if self._footer_is_whole():
            try:
                summary = self._reader.get_summary()
            except Exception:
                summary = None
        if summary is None or not summary.chunk_indexes:
            self._recover()
        else:
            self._channels = {c.topic: c for c in summary.channels.values()}
            self._schemas = summary.schemas
            counts = summary.statistics.channel_message_counts if summary.statistics else {}
            self._counts = {c.topic: counts.get(cid, 0) for cid, c in summary.channels.items()}
            if fmt.TOPIC_STATE not in self._channels:
                raise RecordingError(f"{self.path}: an MCAP file, but not a physdbg recording (no {fmt.TOPIC_STATE} channel)")
            self.frames = self._counts[fmt.TOPIC_STATE]
            self._check_data_section(summary)
            self._check_one_recording()
            self._check_version(self._first(fmt.TOPIC_SCENE))
            self._read_log_times()
        self._checked = np.zeros(self.frames, dtype=bool)
        self._read_header()

    def _footer_is_whole(self) -> bool:
        """Whether the file ends in an MCAP footer whose summary CRC matches (then its
        summary can be used). False when it has no footer (its writer was killed: read it
        sequentially); RecordingIntegrityError when the footer is there but the summary
        does not match it (damaged, or two files joined, whose last footer points into the
        first)."""
        import os
        import struct
        import zlib

        size = os.fstat(self._file.fileno()).st_size
        if size < 2 * len(MCAP_MAGIC) + FOOTER_BYTES:
            return False
        self._file.seek(size - len(MCAP_MAGIC) - FOOTER_BYTES)
        tail = self._file.read(FOOTER_BYTES + len(MCAP_MAGIC))
        if tail[-len(MCAP_MAGIC):] != MCAP_MAGIC or tail[0] != OPCODE_FOOTER:
            return False
        length, summary_start, _, summary_crc = struct.unpack("<QQQI", tail[1:FOOTER_BYTES])
        footer_at = size - len(MCAP_MAGIC) - FOOTER_BYTES
        if length != FOOTER_BYTES - 9 or summary_start > footer_at:
            raise RecordingIntegrityError(f"{self.path}: its MCAP footer is damaged (it points past itself)")
        self._summary_start = summary_start or footer_at
        if summary_crc != 0:  # 0: the writer did not compute one
            start = self._summary_start
            self._file.seek(start)
            crc = zlib.crc32(self._file.read(size - len(MCAP_MAGIC) - 4 - start))
            if crc != summary_crc:
                raise RecordingIntegrityError(
                    f"{self.path}: its summary section does not match its CRC: the file was damaged, or it is "
                    f"two or more files joined together (a recording is one MCAP file)")
        self._file.seek(0)
        return True

    def _check_data_section(self, summary) -> None:
        """Every byte before the summary against the data section's CRC (the DataEnd
        record's, which physdbg writes), in one streaming pass: a flipped byte in any
        chunk of any channel is found when the file is opened, not only when (or if) that
        chunk is read. On a mismatch, or in a file written without a data CRC, each chunk
        is checked against its own CRC to name the damaged one."""
        import struct
        import zlib

        end = self._summary_start - DATA_END_BYTES
        self._file.seek(end)
        data_end = self._file.read(DATA_END_BYTES)
        expected = None
        if len(data_end) == DATA_END_BYTES and data_end[0] == OPCODE_DATA_END:
            length, expected = struct.unpack("<QI", data_end[1:])
            expected = expected if length == 4 and expected != 0 else None
        if expected is not None:
            self._file.seek(0)
            crc, left = 0, end
            while left > 0:
                block = self._file.read(min(left, 1 << 22))
                if not block:
                    break
                crc = zlib.crc32(block, crc)
                left -= len(block)
            if crc == expected and left == 0:
                return
        damaged = self._damaged_chunk(summary)
        if damaged is not None:
            raise RecordingIntegrityError(f"{self.path}: damaged: {damaged}")
        if expected is not None:
            raise RecordingIntegrityError(
                f"{self.path}: damaged: its data section does not match its CRC (the damage is outside the "
                f"chunks of messages); the file was changed after it was written: record the run again")

    def _chunk_records(self, offset: int) -> list:
        """The records of the chunk at byte ``offset``, its CRC checked (mcap raises on a
        mismatch). The last chunk read is kept: a recovered file's batches of 64 frames
        ask for the same chunk again and again."""
        from mcap.data_stream import ReadDataStream
        from mcap.reader import breakup_chunk
        from mcap.records import Chunk

        if self._last_chunk[0] == offset:
            return self._last_chunk[1]
        self._file.seek(offset)
        if self._file.read(1) != bytes([OPCODE_CHUNK]):
            raise ValueError(f"no chunk at byte {offset}")
        self._file.seek(8, 1)  # the record's length
        records = list(breakup_chunk(Chunk.read(ReadDataStream(self._file)), validate_crc=True))
        self._last_chunk = (offset, records)
        return records

    def _damaged_chunk(self, summary) -> str | None:
        """The first chunk whose records do not match its CRC, described; None if all match."""
        topics = {cid: c.topic for cid, c in summary.channels.items()}
        for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            try:
                self._chunk_records(index.chunk_start_offset)
            except Exception as err:
                held = sorted({topics.get(cid, f"channel {cid}") for cid in index.message_index_offsets})
                why = "its CRC does not match" if type(err).__name__ == "CRCValidationError" else \
                    f"{type(err).__name__}: {err}"
                return (f"its chunk at byte {index.chunk_start_offset} ({', '.join(held)}; messages of simulated "
                        f"time {index.message_start_time / 1e9:g} s to {index.message_end_time / 1e9:g} s) does not "
                        f"read back as written ({why}); the file was changed after it was written: record the run "
                        f"again")
        return None

    def _check_one_recording(self) -> None:
        """A file holds one run: one scene, one set of particles and walls, one index."""
        for topic in (fmt.TOPIC_SCENE, fmt.TOPIC_PARTICLES, fmt.TOPIC_WALLS, fmt.TOPIC_FRAME_INDEX):
            if self._counts.get(topic, 0) > 1:
                raise RecordingIntegrityError(
                    f"{self.path}: holds {self._counts[topic]} {topic} messages: more than one recording in one "
                    f"file (a recording has one)")

    def _first(self, topic: str) -> bytes | None:
        """The first message of a topic, found by the summary's index (no time range)."""
        if self._recovered is not None:
            rows = self._recovered_messages([topic], 0, sys.maxsize)
            return rows[0][3] if rows else None
        if topic not in self._channels:
            return None
        for _, _, message in self._reader.iter_messages(topics=[topic]):
            return message.data
        return None

    def _check_version(self, scene: bytes | None) -> None:
        if scene is None:
            raise RecordingError(f"{self.path}: an MCAP file, but its physdbg scene is missing")
        meta = json.loads(scene)
        if meta.get("format") != fmt.FORMAT_NAME:
            raise RecordingError(f"{self.path}: an MCAP file, but not a physdbg recording")
        if meta.get("format_version") != fmt.FORMAT_VERSION:
            raise RecordingError(f"{self.path}: recording format version {meta.get('format_version')}; "
                                 f"this physdbg reads version {fmt.FORMAT_VERSION} (record the run again)")

    def _read_log_times(self) -> None:
        """Every frame's MCAP log time, from the frame index (one small read); a file whose
        index is missing or short is scanned (log times and step numbers of its states)."""
        data = self._first(fmt.TOPIC_FRAME_INDEX)
        if data is not None:
            _, rows = proto.decode_table(fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_FRAME_INDEX], data)
            if len(rows) != self.frames:
                raise RecordingIntegrityError(f"{self.path}: its frame index lists {len(rows)} frames and the file "
                                              f"holds {self.frames} states")
            log_ns = rows["log_time"]
            if len(log_ns) > 1 and not np.all(log_ns[1:] > log_ns[:-1]):
                k = int(np.flatnonzero(log_ns[1:] <= log_ns[:-1])[0]) + 1
                raise RecordingIntegrityError(f"{self.path}: frames out of order: the frame index puts frame {k} "
                                              f"no later than frame {k - 1}")
            self._log_ns = log_ns.copy()
            self._frame_table = FrameTable(rows["time"].copy(), rows["dt"].copy(), rows["state_hash"].copy())
            return
        log_ns = np.zeros(self.frames, dtype=np.uint64)
        seen = 0
        for _, _, message in self._reader.iter_messages(topics=[fmt.TOPIC_STATE]):
            if message.sequence != seen:
                raise RecordingError(f"{self.path}: frame {seen} is missing (found frame {message.sequence})")
            log_ns[seen] = message.log_time
            seen += 1
        self._log_ns = log_ns

    def _recover(self) -> None:
        """Read a file with no summary (its writer was killed, or is still writing) as far
        as it is whole: its records are walked one by one, each whole chunk decompressed
        once (its CRC checked) to list which frames of which topics it holds, and only that
        list is kept (a killed 543 MB recording took 1.75 GB to open when every message was
        held in memory). Messages are read again from their chunks when asked for."""
        import os
        import struct

        from mcap.records import Channel, Message, Schema

        self.truncated = True
        size = os.fstat(self._file.fileno()).st_size
        channels: dict[int, Channel] = {}
        self._schemas: dict[int, Schema] = {}
        chunks: list[tuple[int, dict[str, list[int]]]] = []
        position = len(MCAP_MAGIC)
        while position + 9 <= size:
            self._file.seek(position)
            opcode, length = struct.unpack("<BQ", self._file.read(9))
            end = position + 9 + length
            if end > size:
                break  # the torn end of the file: keep what came before it
            if opcode == OPCODE_FOOTER:  # a whole MCAP file, and yet its footer is not the file's end
                raise RecordingIntegrityError(f"{self.path}: more data follows the end of its MCAP file: two or "
                                              f"more files joined together (a recording is one MCAP file)")
            if opcode == OPCODE_CHUNK:
                try:
                    records = self._chunk_records(position)
                except Exception as err:  # a whole chunk that does not read back: damage, not a torn end
                    raise RecordingIntegrityError(
                        f"{self.path}: damaged: its chunk at byte {position} does not read back as written "
                        f"({type(err).__name__}); the file was changed after it was written") from None
                held: dict[str, list[int]] = defaultdict(list)
                for record in records:
                    if isinstance(record, Schema):
                        self._schemas[record.id] = record
                    elif isinstance(record, Channel):
                        channels[record.id] = record
                    elif isinstance(record, Message) and record.channel_id in channels:
                        held[channels[record.channel_id].topic].append(record.sequence)
                chunks.append((position, dict(held)))
            position = end
        self._channels = {c.topic: c for c in channels.values()}
        states = [f for _, held in chunks for f in held.get(fmt.TOPIC_STATE, ())]
        if fmt.TOPIC_STATE not in self._channels or not states:
            raise RecordingError(f"{self.path}: truncated before its first complete chunk; no steps can be read")
        if states != list(range(len(states))):
            k = next(i for i, f in enumerate(states) if f != i)
            raise RecordingIntegrityError(f"{self.path}: frames out of order: state {k} of the file is frame "
                                          f"{states[k]}")
        last = states[-1]
        # A frame is complete when its state arrived (the writer puts the state last).
        self._recovered = [(offset, {t: [f for f in frames if f <= last] for t, frames in held.items()})
                           for offset, held in chunks]
        counts: dict[str, int] = defaultdict(int)
        for _, held in self._recovered:
            for topic, frames in held.items():
                counts[topic] += len(frames)
        self._counts = dict(counts)
        self._check_one_recording()
        self.frames = last + 1
        self._check_version(self._first(fmt.TOPIC_SCENE))

    def _recovered_messages(self, topics: list[str], first: int, last: int) -> list[tuple[int, int, str, bytes]]:
        """(frame, topic's place in topics, topic, data) of a recovered file's messages of
        ``topics`` for frames first..last, in frame order: their chunks read again."""
        from mcap.records import Message

        place = {t: i for i, t in enumerate(topics)}
        ids = {c.id: c.topic for c in self._channels.values() if c.topic in place}
        merged = []
        for offset, held in self._recovered:
            if not any(held.get(t) and held[t][0] <= last and held[t][-1] >= first for t in topics):
                continue  # the chunk holds none of these frames (frames come in order in a chunk)
            for record in self._chunk_records(offset):
                if isinstance(record, Message) and record.channel_id in ids and first <= record.sequence <= last:
                    topic = ids[record.channel_id]
                    merged.append((record.sequence, place[topic], topic, record.data))
        merged.sort(key=lambda row: (row[0], row[1]))
        return merged

    def _read_header(self) -> None:
        scene = self._one(fmt.TOPIC_SCENE)
        particles = self._one(fmt.TOPIC_PARTICLES)
        walls = self._one(fmt.TOPIC_WALLS)
        if scene is None or particles is None or walls is None:
            raise RecordingError(f"{self.path}: an MCAP file, but its physdbg scene, particles or walls are missing")
        meta = RecordingHeader.meta_from_json(json.loads(scene))
        rows = self._table(fmt.TOPIC_PARTICLES, particles)
        first = self._decode_states(0, 0)[0]
        self.header = RecordingHeader(meta, rows["radius"].copy(), rows["inverse_mass"].copy(),
                                      rows["restitution"].copy(), rows["gravity_scale"].copy(),
                                      RecordingHeader.walls_from_json(json.loads(walls)),
                                      first.positions, first.velocities, first.state_hash)
        self.meta = meta
        self.detail = meta["detail"]
        self.steps = self.frames - 1

    # ------------------------------------------------------------------ raw access
    def _messages(self, topics: list[str], first: int, last: int) -> Iterator[tuple[str, int, bytes]]:
        """(topic, frame, data) of the given topics for frames first..last, in frame order."""
        topics = [t for t in topics if t in self._channels]
        if not topics:
            return
        if self._recovered is not None:
            for f, _, t, d in self._recovered_messages(topics, first, last):
                yield t, f, d
            return
        end = int(self._log_ns[last + 1]) if last + 1 < self.frames else int(self._log_ns[last]) + 1
        messages = self._reader.iter_messages(topics=topics, starting_at=int(self._log_ns[first]), ending_before=end)
        while True:
            try:
                _, channel, message = next(messages)
            except StopIteration:
                return
            except Exception as err:  # a damaged chunk: say where, never a traceback
                raise RecordingError(f"{self.path}: damaged between frames {first} and {last} "
                                     f"({type(err).__name__}: {err})") from None
            yield channel.topic, message.sequence, message.data

    @property
    def records_contacts(self) -> bool:
        """Whether the file has a contacts channel (detail contacts or full)."""
        return fmt.TOPIC_CONTACTS in self._channels

    def raw_messages(self, topic: str, first: int = 1, last: int | None = None) -> Iterator[tuple[int, bytes]]:
        """(frame, message bytes) of one topic for frames first..last, in frame order,
        undecoded (to compare two files' records byte for byte)."""
        last = self.frames - 1 if last is None else last
        for _, frame, data in self._messages([topic], first, last):
            yield frame, data

    def _one(self, topic: str) -> bytes | None:
        for _, _, data in self._messages([topic], 0, 0):
            return data
        return None

    def _table(self, topic: str, data: bytes) -> np.ndarray:
        """The rows of a protobuf table (or row) message, as a numpy structured array."""
        try:
            return proto.decode_table(fmt.MESSAGE_OF_TOPIC[topic], data)[1]
        except Exception as err:  # a damaged message: say which, never a traceback
            raise RecordingError(f"{self.path}: damaged {topic} message ({type(err).__name__}: {err})") from None

    def _check_frame(self, k: int) -> int:
        k = int(k)
        if k < 0:
            k += self.frames
        if not 0 <= k < self.frames:
            raise IndexError(f"frame {k} is not in the recording (frames 0..{self.frames - 1})")
        return k

    # ------------------------------------------------------------------ states
    def _decode_states(self, first: int, last: int) -> list[FrameState]:
        """Decode frames first..last, starting from the key frame at or before ``first``."""
        start = first - first % fmt.KEYFRAME_INTERVAL
        out: list[FrameState] = []
        decoder = StateStream(self)
        for frame, data in self.state_messages(start, last + 1):
            state = decoder.decode(frame, data, check=frame >= first)
            if frame >= first:
                out.append(state)
        if len(out) != last - first + 1:
            raise RecordingError(f"{self.path}: frames {first}..{last} are not all in the file")
        return out

    def state_messages(self, start: int, stop: int) -> Iterator[tuple[int, bytes]]:
        """(frame, raw /physdbg/state message) of frames start..stop-1 as stored, in order."""
        for _, frame, data in self._messages([fmt.TOPIC_STATE], start, stop - 1):
            yield frame, data

    def _check_state(self, s: FrameState, hashed: bool = True) -> None:
        """The integrity rule for one decoded state (module doc): its own hash (unless it
        is ``hashed`` already, as a state another file holds byte for byte), the index's."""
        if self._checked[s.frame]:
            return
        if hashed and state_hash(s.positions, s.velocities) != s.state_hash:
            raise RecordingIntegrityError(
                f"{self.path}: frame {s.frame}: the stored state does not give its stored hash: the file was altered "
                f"or damaged (--no-verify reads it anyway)")
        table = self._frame_table
        if table is not None and (table.hash_hex(s.frame) != s.state_hash or table.time[s.frame] != s.time
                                  or table.dt[s.frame] != s.dt):
            raise RecordingIntegrityError(
                f"{self.path}: frame {s.frame}: the frame index and the stored state disagree: the file was altered "
                f"(--no-verify reads it anyway)")
        self._checked[s.frame] = True

    @property
    def checked_frames(self) -> int:
        """How many frames' states have been checked (each counted once)."""
        return int(self._checked.sum())

    def state(self, k: int) -> FrameState:
        """The state at frame k (negative k counts from the end)."""
        k = self._check_frame(k)
        return self._decode_states(k, k)[0]

    def states(self, start: int = 0, stop: int | None = None, batch: int = 256) -> Iterator[FrameState]:
        """Every state from frame ``start`` up to (not including) ``stop``, in one pass."""
        stop = self.frames if stop is None else min(stop, self.frames)
        for first in range(start, stop, batch):
            yield from self._decode_states(first, min(first + batch, stop) - 1)

    def frame_table(self) -> FrameTable:
        """Every frame's time, dt and stored state hash, without decoding a state.

        From the /physdbg/frame_index message written at close (one small read); a file
        without it (its writer was killed) is scanned: state headers only, no decoding.
        """
        if self._frame_table is None:
            self._frame_table = self._read_frame_table()
        return self._frame_table

    def _read_frame_table(self) -> FrameTable:
        times, dts, hashes = np.empty(self.frames), np.empty(self.frames), np.empty((self.frames, 16), np.uint8)
        seen = 0
        for _, frame, data in self._messages([fmt.TOPIC_STATE], 0, self.frames - 1):
            try:
                m = decode_state_header(data)
            except ValueError as err:
                raise RecordingError(f"{self.path}: frame {frame}: damaged state message ({err})") from None
            if m.step != seen:
                raise RecordingError(f"{self.path}: frame {seen} is missing (found frame {m.step})")
            times[seen], dts[seen] = m.time, m.dt
            hashes[seen] = np.frombuffer(m.state_hash, dtype=np.uint8)
            seen += 1
        if seen != self.frames:
            raise RecordingError(f"{self.path}: frames {seen}..{self.frames - 1} are not in the file")
        return FrameTable(times, dts, hashes)

    def stats(self, start: int = 1, stop: int | None = None) -> np.ndarray:
        """The step statistics of steps start..stop-1 (frames), one row each: a numpy
        structured array with the fields of /physdbg/stats (time, dt, kinetic, potential,
        energy, momentum (3,), counts, max_overlap, timings, temperature, virial,
        wall_impulse; see docs/recording-format.md)."""
        rows = list(self.iter_stats(start, stop))
        return np.concatenate(rows) if rows else np.zeros(0, dtype=fmt.dtype_of(fmt.STATS_FIELDS))

    def iter_stats(self, start: int = 1, stop: int | None = None) -> Iterator[np.ndarray]:
        """The step statistics of steps start..stop-1, one single-row array at a time (as
        stats(), streamed: stop reading when you have what you need)."""
        stop = self.frames if stop is None else min(stop, self.frames)
        if stop <= max(start, 1):
            return
        for _, _, data in self._messages([fmt.TOPIC_STATS], max(start, 1), stop - 1):
            yield self._table(fmt.TOPIC_STATS, data)

    # ------------------------------------------------------------------ step events
    def step_events(self, k: int) -> list:
        """The engine events of the k-th step (frame k >= 1), in the engine's order."""
        k = self._check_frame(k)
        if k == 0:
            raise IndexError("frame 0 is the initial state; steps are frames 1..frames-1")
        return next(self.iter_step_events(k, k + 1))

    def iter_step_events(self, start: int = 1, stop: int | None = None, detail: str = "full") -> Iterator[list]:
        """For each step start..stop-1: the list of its events (StepBegin, BroadPhaseInfo,
        EngineWarning..., Contacts, SweptTests, StepEnd), as the engine emitted them —
        what a replay feeds to the sinks. detail: read no more than this level ("state"
        skips contacts, "contacts" skips swept tests and the broad phase: much faster)."""
        stop = self.frames if stop is None else min(stop, self.frames)
        wanted = fmt.topics_for(detail)
        topics = [t for t in (fmt.TOPIC_STATS, fmt.TOPIC_WARNINGS, fmt.TOPIC_CONTACTS, fmt.TOPIC_SWEPT,
                              fmt.TOPIC_BROAD_PHASE, fmt.TOPIC_BVH, fmt.TOPIC_BVH_ORDER, fmt.TOPIC_MESH_QUERIES,
                              fmt.TOPIC_MESH_SEARCH) if t in wanted]
        batch = 64
        for first in range(max(start, 1), stop, batch):
            last = min(first + batch, stop) - 1
            per_frame: dict[int, dict[str, list[bytes]]] = defaultdict(lambda: defaultdict(list))
            for topic, frame, data in self._messages(topics, first, last):
                per_frame[frame][topic].append(data)
            states = self._decode_states(first - 1, last)
            for k in range(first, last + 1):
                yield self._events_of(k, per_frame.get(k, {}), states[k - first], states[k - first + 1], topics)

    def _events_of(self, k: int, parts: dict, before: FrameState, after: FrameState, topics) -> list:
        step = k
        events: list = [StepBegin(step, before.time, after.dt)]
        if parts.get(fmt.TOPIC_BROAD_PHASE):
            meta = json.loads(parts[fmt.TOPIC_BROAD_PHASE][0])
            nodes = None
            if parts.get(fmt.TOPIC_BVH):
                rows = self._table(fmt.TOPIC_BVH, parts[fmt.TOPIC_BVH][0])
                nodes = {name: rows[name].copy() for name in ("lo", "hi", "left", "right", "parent", "depth",
                                                              "start", "count", "node")}
                if parts.get(fmt.TOPIC_BVH_ORDER):
                    nodes["order"] = self._table(fmt.TOPIC_BVH_ORDER, parts[fmt.TOPIC_BVH_ORDER][0])["particle"].copy()
            stats = dict(meta["stats"])
            for key in ("bvh_nodes", "bvh_depth", "bvh_logged_depth"):
                if key in meta:
                    stats[key] = meta[key]
            events.append(BroadPhaseInfo(step, meta["name"], meta["reason"], stats, nodes))
        warnings = [json.loads(w) for w in parts.get(fmt.TOPIC_WARNINGS, [])]
        events.extend(EngineWarning(step, current_name(w["code"]), w["message"], _warning_bodies(w))
                      for w in warnings)
        if fmt.TOPIC_CONTACTS in self._channels and fmt.TOPIC_CONTACTS in topics:
            events.append(self._contacts(step, parts.get(fmt.TOPIC_CONTACTS, [b""])[0]))
        if fmt.TOPIC_SWEPT in self._channels and fmt.TOPIC_SWEPT in topics:
            rows = self._table(fmt.TOPIC_SWEPT, parts.get(fmt.TOPIC_SWEPT, [b""])[0])
            check_kinds(rows["kind"], str(self.path))
            events.append(SweptTests(step, rows["kind"].copy(), rows["a"].copy(), rows["other"].copy(),
                                     rows["start"].copy(), rows["toi"].copy(), rows["outcome"].copy()))
        if fmt.TOPIC_MESH_SEARCH in self._channels and fmt.TOPIC_MESH_SEARCH in topics:
            events.append(self._mesh_search(step, parts))
        stats_data = parts.get(fmt.TOPIC_STATS)
        if not stats_data:
            raise RecordingError(f"{self.path}: step {k} has a state but no stats message")
        s = self._table(fmt.TOPIC_STATS, stats_data[0])[0]
        counts = StepCounts(**{name: int(s[name]) for name in STEP_COUNTS})
        timings = {name[len("seconds_"):]: float(s[name]) for name in s.dtype.names if name.startswith("seconds_")}
        events.append(StepEnd(step, after.time, after.dt, after.positions, after.velocities, float(s["kinetic"]),
                              float(s["potential"]), s["momentum"].copy(), counts, float(s["max_overlap"]),
                              timings, after.state_hash, tuple(e for e in events if isinstance(e, EngineWarning)),
                              after.asleep))
        return events

    def _mesh_search(self, step: int, parts: dict) -> MeshSearch:
        queries = self._table(fmt.TOPIC_MESH_QUERIES, parts.get(fmt.TOPIC_MESH_QUERIES, [b""])[0])
        visits = self._table(fmt.TOPIC_MESH_SEARCH, parts.get(fmt.TOPIC_MESH_SEARCH, [b""])[0])
        return MeshSearch(step, queries["sphere"].copy(), queries["after"].copy(), queries["lo"].copy(),
                          queries["hi"].copy(), visits["query"].copy(), visits["node"].copy(),
                          visits["outcome"].copy(), visits["parent"].copy())

    def mesh_search(self, k: int) -> MeshSearch:
        """The walks of the meshes' trees in the k-th step (a scene with meshes, detail
        contacts: those that led to a contact; full: all)."""
        if fmt.TOPIC_MESH_SEARCH not in self._channels:
            raise RecordingError(f"{self.path}: no mesh search recorded (" + (
                "the scene has no meshes" if not len(self.header.walls.meshes) else
                f"recorded with --detail {self.detail}; it needs --detail contacts or full") + ")")
        return self._of_type(k, MeshSearch, "contacts")

    def mesh_tree(self) -> np.ndarray | None:
        """The meshes' trees as the engine walked them (format.MESH_TREE_FIELDS rows), or
        None when the recording has none (no meshes, or detail state)."""
        data = self._one(fmt.TOPIC_MESH_TREE) if fmt.TOPIC_MESH_TREE in self._channels else None
        return None if data is None else self._table(fmt.TOPIC_MESH_TREE, data)

    def _contacts(self, step: int, data: bytes) -> Contacts:
        rows = self._table(fmt.TOPIC_CONTACTS, data)
        check_kinds(rows["kind"], str(self.path))  # every reader may then ask the kinds table
        return Contacts(step, rows)

    def contacts(self, k: int) -> Contacts:
        """Contacts of the k-th step (detail contacts or full)."""
        return self._of_type(k, Contacts, "contacts")

    def swept_tests(self, k: int) -> SweptTests:
        """Swept tests of the k-th step (detail full)."""
        return self._of_type(k, SweptTests, "full")

    def step_end(self, k: int) -> StepEnd:
        """State, energies, momentum, counts and timings after the k-th step."""
        return self._of_type(k, StepEnd, "state")

    def _of_type(self, k: int, kind: type, level: str):
        for event in self.step_events(k):
            if isinstance(event, kind):
                return event
        raise RecordingError(f"{self.path}: recorded with --detail {self.detail}; "
                             f"{kind.__name__} needs --detail {level} or more")

    # ------------------------------------------------------------------ description
    def channels(self) -> list[ChannelInfo]:
        out = []
        for topic, channel in sorted(self._channels.items()):
            schema = self._schemas.get(channel.schema_id)
            out.append(ChannelInfo(topic, channel.message_encoding, schema.name if schema else "",
                                   self._counts.get(topic, 0)))
        return out

    @property
    def scene(self):
        """The recorded scene, rebuilt from the table kept in the file (to repeat the run)."""
        from ..engine.state import Settings
        from ..scene import scene_from_dict

        info = self.meta["scene"]
        scene = scene_from_dict(info["table"], f"{info['source']} (from {self.path.name})",
                                self.header.walls.meshes if len(self.header.walls.meshes) else None)
        # settings the table left "auto" take the values the run used (kept in the file),
        # so the rebuilt scene repeats the run even if the advisor would now decide otherwise
        # (a file made before a setting existed ran with the engine's own default for it)
        recorded = self.meta.get("settings", {})
        decided = scene.settings.undecided()
        for name in decided:
            setattr(scene.settings, name, recorded.get(name, Settings.__dataclass_fields__[name].default))
        if "sleep_speed" in decided and "sleep_time" in recorded:
            scene.settings.sleep_time = recorded["sleep_time"]
        from ..advisor import Decision

        scene.auto = {name: Decision(getattr(scene.settings, name), "as recorded") for name in decided}
        return scene

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"Recording({str(self.path)!r}, scene={self.header.name!r}, steps={self.steps}, "
                f"detail={self.detail!r}{', truncated' if self.truncated else ''})")


def _warning_bodies(warning: dict) -> tuple[int, ...]:
    """A recorded warning's spheres: its ``bodies``; in a file made before warnings named
    them, a pinned warning's sphere as its message names it first ("sphere 3 is pinned ...")."""
    if "bodies" in warning:
        return tuple(int(b) for b in warning["bodies"])
    named = re.match(r"sphere (\d+) ", warning["message"]) if warning["code"] == "pinned" else None
    return (int(named.group(1)),) if named else ()


__all__ = ["ChannelInfo", "FrameState", "FrameTable", "Recording", "RecordingError", "RecordingIntegrityError",
           "StateStream", "open_recording"]

