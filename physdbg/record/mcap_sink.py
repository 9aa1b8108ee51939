"""The MCAP recorder: an observer that writes every step losslessly to an MCAP file.

Call sequence (as the mcap library's own): ``McapRecorder(path, header)`` writes the
scene and frame 0; attach it as the world's observer; ``close()`` writes the summary.
A step's events are buffered and written together when its StepEnd arrives, so a run
stopped at any moment leaves only whole steps in the file; the file is flushed after
every step so a killed process leaves every finished chunk readable.

Chunks: the bulky channels (swept tests, broad phase, BVH nodes) go in chunks of their
own, written just before the chunk of states, stats and contacts for the same frames, so
"a frame whose state is in the file is complete" still holds and a reader of states
never decompresses swept tests. At close, one /physdbg/frame_index message lists every
frame's time, log time, dt and state hash (what ``diff`` compares first, and how a
reader finds step k's messages: their log time is frame k's simulated time in ns).

With ``view=True`` (the default) the view channels in Foxglove's schemas are written too
(:mod:`.foxglove_view`).

The observer only encodes (numpy to bytes); a writer thread hands the messages to the
mcap library, which compresses each chunk with zstd. zstd releases the GIL, so on two
cores compression overlaps the next step instead of adding to it. At most
QUEUE_STEPS steps wait for the writer, which bounds the memory this takes.
"""

from __future__ import annotations

import json
import queue
import threading
from pathlib import Path

import numpy as np

from ..events import (NO_COLLISIONS, BroadPhaseInfo, Contacts, EngineWarning, MeshSearch, StepEnd, SweptTests,
                      collision_sums)
from . import format as fmt
from .state_codec import StateEncoder
from . import proto
from .header import RecordingHeader

CHUNK_BYTES = 1 << 20  # mcap's default; chunks are the unit that survives a killed process
QUEUE_STEPS = 8
# ... and at most this many encoded bytes wait (one step more when a single step is
# larger): 8 steps of a dense pile's swept tests at --detail full are gigabytes, which
# max_memory never saw (rain 2000 with its budgets raised peaked at 6.5 GB under 4 GB)
QUEUE_BYTES = 256 << 20


class McapRecorder:
    """Writes a recording. path: the .mcap file (created; the caller checks overwriting).

    header: scene constants and initial state; chunk_bytes: uncompressed chunk size.
    Attributes after close(): frames (states written, incl. frame 0), bvh_capped_steps,
    bvh_logged_depth (deepest level written when capped, else None), bytes_written.
    """

    def __init__(self, path: str | Path, header: RecordingHeader, chunk_bytes: int = CHUNK_BYTES,
                 view: bool = True):
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self.header = header
        self.detail = header.detail
        self.bvh_max_nodes = header.meta.get("bvh_max_nodes")
        self._file = open(self.path, "wb")
        self._good_size = 0  # file size after the last successful flush: whole records only
        # data CRCs: every reader checks the whole data section against it on opening (reader.py)
        self._writer = Writer(self._file, chunk_size=chunk_bytes, compression=CompressionType.ZSTD,
                              enable_data_crcs=True)
        self._writer.start(profile=fmt.PROFILE, library=f"physdbg {header.meta['physdbg_version']}")
        self._channels: dict[str, int] = {}
        self.view = None
        if view:
            from .foxglove_view import FoxgloveView

            self.view = FoxgloveView(header, self.detail)
        scene_json = fmt.foxglove_json(header.scene_json())
        meshes = len(header.walls.meshes) > 0
        for topic in fmt.topics_for(self.detail, view=view):
            if meshes or topic not in fmt.MESH_TOPICS:
                self._register(topic, scene_json)
        self._writer.add_metadata("physdbg", {
            "format": fmt.FORMAT_NAME, "format_version": str(fmt.FORMAT_VERSION),
            "physdbg_version": header.meta["physdbg_version"], "scene": header.name,
            "detail": self.detail, "particles": str(header.count), "view": str(view).lower()})
        self._pending: list[tuple[str, bytes]] = []
        self._queue: queue.Queue = queue.Queue(maxsize=QUEUE_STEPS)
        self._queued_bytes = 0  # encoded bytes handed to the writer and not yet written
        self._room = threading.Condition()
        self._error: BaseException | None = None
        self._outbox: list[tuple[int, int, int, bytes]] = []
        self._states = StateEncoder()  # the frames before each, for the codecs
        self._chunk_bytes = chunk_bytes
        self._heavy = {self._channels[t] for t in fmt.HEAVY_TOPICS if t in self._channels}
        self._index_rows: list[tuple[float, int, float, bytes]] = []  # (time, log ns, dt, hash) of every frame
        self._last_ns = -1  # log time of the last frame: the next is later by at least 1 ns
        self._contacts: Contacts | None = None
        self._search: MeshSearch | None = None  # the step's, as written
        self._warnings: list[EngineWarning] = []
        self._collisions = NO_COLLISIONS  # virial, wall impulse and collisions of the step so far
        movable = int(np.count_nonzero(header.inverse_mass > 0))
        self._kT_per_kinetic = 2.0 / (3.0 * movable) if movable else 0.0  # kT = 2 KE / (3 N), J
        self._sent_frames = 0
        self.frames = 0
        self.bvh_capped_steps = 0
        self.bvh_logged_depth: int | None = None
        self.closed = False
        self._thread = threading.Thread(target=self._drain, name="physdbg-mcap-writer", daemon=True)
        self._thread.start()
        ns = self._frame_time(0.0)
        self._write(fmt.TOPIC_SCENE, 0, ns, json.dumps(scene_json).encode())
        self._write(fmt.TOPIC_PARTICLES, 0, ns, self._table(fmt.TOPIC_PARTICLES, 0, header))
        self._write(fmt.TOPIC_WALLS, 0, ns, json.dumps(fmt.foxglove_json(header.walls_json())).encode())
        self._leaf_triangle = None
        if fmt.TOPIC_MESH_TREE in self._channels:  # the trees the engine walks, as it builds them
            from . import mesh_view

            table = mesh_view.tree_table(header.walls.meshes.mesh_set)
            self._leaf_triangle = table["triangle"]
            self._write(fmt.TOPIC_MESH_TREE, 0, ns, proto.encode_table(
                fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_MESH_TREE], 0, table.__getitem__))
        if self.view is not None:
            for topic, data in self.view.first(ns):
                self._write(topic, 0, ns, data)
        self._write_state(0, 0.0, 0.0, header.state_hash, header.positions, header.velocities, ns)
        self._send()

    # ------------------------------------------------------------------ observer
    @property
    def wants_swept_tests(self) -> bool:
        """Only detail "full" records the swept tests (observe.py)."""
        return fmt.TOPIC_SWEPT in self._channels

    @property
    def wants_mesh_search(self) -> bool:
        """A scene with meshes at detail contacts or full records the search (observe.py)."""
        return fmt.TOPIC_MESH_SEARCH in self._channels

    def on_event(self, event) -> None:
        frame = event.step
        if isinstance(event, StepEnd):
            self._end_step(event)
        elif isinstance(event, Contacts):
            self._collisions = collision_sums(event, self.header.radius)
            if fmt.TOPIC_CONTACTS in self._channels:
                self._contacts = event
                self._pending.append((fmt.TOPIC_CONTACTS, self._table(fmt.TOPIC_CONTACTS, frame, event)))
        elif isinstance(event, SweptTests):
            if fmt.TOPIC_SWEPT in self._channels:
                self._pending.append((fmt.TOPIC_SWEPT, self._table(fmt.TOPIC_SWEPT, frame, event)))
        elif isinstance(event, MeshSearch):
            if fmt.TOPIC_MESH_SEARCH in self._channels:
                self._mesh_search(event, frame)
        elif isinstance(event, BroadPhaseInfo):
            if fmt.TOPIC_BROAD_PHASE in self._channels:
                self._broad_phase(event, frame)
        elif isinstance(event, EngineWarning):
            self._warnings.append(event)
            self._pending.append((fmt.TOPIC_WARNINGS, json.dumps(fmt.foxglove_json(
                {"step": frame, "code": event.code, "message": event.message, "bodies": list(event.bodies)})).encode()))

    def _end_step(self, end: StepEnd) -> None:
        frame = end.step
        ns = self._frame_time(end.time)
        for topic, data in self._pending:
            self._write(topic, frame, ns, data)
        self._pending.clear()
        stats = {"time": end.time, "dt": end.dt, "kinetic": end.kinetic, "potential": end.potential,
                 "energy": end.kinetic + end.potential, "momentum": np.asarray(end.momentum),
                 "max_overlap": end.max_overlap}
        for name in fmt.STEP_COUNTS:
            stats[name] = getattr(end.counts, name)
        for name, _, _ in fmt.STATS_FIELDS:
            if name.startswith("seconds_"):
                stats[name] = end.timings.get(name[len("seconds_"):], 0.0)
        stats["virial"], stats["wall_impulse"], stats["collisions"] = self._collisions
        stats["temperature"] = self._kT_per_kinetic * end.kinetic
        self._collisions = NO_COLLISIONS
        self._write(fmt.TOPIC_STATS, frame, ns, proto.encode_table(
            fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_STATS], frame, stats.__getitem__))
        if self.view is not None:
            for topic, data in self.view.step(frame, ns, end, self._contacts, self._warnings, self._search):
                self._write(topic, frame, ns, data)
        self._contacts, self._warnings, self._search = None, [], None
        # The state goes last: a frame whose state is in the file is a complete step.
        self._write_state(frame, end.time, end.dt, end.state_hash, end.positions, end.velocities, ns, end.asleep)
        self._send()

    def mark_finding(self, finding) -> None:
        """An audit finding (analysis.audit.Finding) into the view channels at its step: a
        warning on /view/log and a red marker on /view/scene where it happened, so Foxglove
        and `rerun mcap convert` users see what Rerun users see. Written when it is made
        (just after its step, or at the end for what the audit judges then)."""
        if self.view is None or self.closed or not self._index_rows:
            return
        frame = min(finding.step, len(self._index_rows) - 1)
        ns = int(self._index_rows[frame][1])
        for topic, data in self.view.finding(ns, finding):
            self._write(topic, frame, ns, data)
        self._send()

    def _frame_time(self, seconds: float) -> int:
        """The log time (ns) of the next frame: its simulated time, strictly after the last."""
        self._last_ns = fmt.frame_nanoseconds(seconds, self._last_ns)
        return self._last_ns

    # ------------------------------------------------------------------ pieces
    def _register(self, topic: str, scene_json: dict) -> None:
        w = self._writer
        if topic in fmt.MESSAGE_OF_TOPIC:
            name = fmt.MESSAGE_OF_TOPIC[topic]
            schema = w.register_schema(name, fmt.ENCODING_PROTOBUF, proto.schema_data(name))
            encoding = fmt.ENCODING_PROTOBUF
        elif topic in fmt.VIEW_SCHEMAS:
            from mcap_protobuf.schema import register_schema

            schema = register_schema(w, self.view.classes[topic])
            encoding = fmt.ENCODING_PROTOBUF
        else:
            if topic == fmt.TOPIC_SCENE:
                name, jsonschema = fmt.SCENE_SCHEMA_NAME, fmt.json_schema_of(scene_json)
            else:
                name, jsonschema = fmt.JSON_SCHEMAS[topic]
            schema = w.register_schema(name, fmt.SCHEMA_JSON, json.dumps(jsonschema).encode())
            encoding = fmt.ENCODING_JSON
        self._channels[topic] = w.register_channel(topic, encoding, schema)

    def _write(self, topic: str, frame: int, publish_ns: int, data: bytes) -> None:
        self._outbox.append((self._channels[topic], frame, publish_ns, data))

    def _send(self) -> None:
        """Hand one whole step to the writer thread."""
        if self._error is not None:
            raise OSError(f"writing {self.path} failed: {self._error}") from self._error
        size = sum(len(message[3]) for message in self._outbox)
        with self._room:  # wait while the writer holds QUEUE_BYTES (always let one step through)
            while self._queued_bytes and self._queued_bytes + size > QUEUE_BYTES and self._error is None:
                self._room.wait(timeout=0.5)
            self._queued_bytes += size
        self._queue.put(self._outbox)
        self._outbox = []
        self._sent_frames = self.frames

    def _drain(self) -> None:
        """The writer thread: gather steps into a bulky and a light batch; when either is a
        chunk's worth (or at the end), write the bulky chunk, then the light one, then flush."""
        batches: tuple[list, list] = ([], [])  # (bulky, light) messages
        sizes = [0, 0]
        first = True  # frame 0 (scene, particles, walls, initial state) gets a chunk at once
        while True:
            step = self._queue.get()
            if self._error is not None:
                if step is None:
                    return
                continue
            try:
                if step is not None:
                    for message in step:
                        light = message[0] not in self._heavy
                        batches[light].append(message)
                        sizes[light] += len(message[3])
                if step is None or first or max(sizes) >= self._chunk_bytes:
                    first = False
                    for batch in batches:
                        for channel, frame, ns, data in batch:
                            self._writer.add_message(channel, log_time=ns, data=data, publish_time=ns,
                                                     sequence=frame)
                        self._writer.flush()  # finish this chunk: bulky and light never share one
                        batch.clear()
                    sizes = [0, 0]
                    self._good_size = self._file.tell()
            except BaseException as err:  # reported by the next _send or close
                self._error = err
            if step is not None:
                with self._room:
                    self._queued_bytes -= sum(len(message[3]) for message in step)
                    self._room.notify_all()
            if step is None:
                return

    def _write_state(self, frame: int, time: float, dt: float, digest: str, x: np.ndarray, v: np.ndarray,
                     ns: int, asleep: np.ndarray | None = None) -> None:
        self._write(fmt.TOPIC_STATE, frame, ns, self._states.encode(frame, time, dt, digest, x, v, asleep))
        self._index_rows.append((time, ns, dt, bytes.fromhex(digest)))
        self.frames = frame + 1

    def _table(self, topic: str, frame: int, source) -> bytes:
        """The channel's table message, each column taken from the attribute of that name."""
        return proto.encode_table(fmt.MESSAGE_OF_TOPIC[topic], frame, lambda name: getattr(source, name))

    def _mesh_search(self, search: MeshSearch, frame: int) -> None:
        """The step's walks of the meshes' trees: all of them at detail full, those that
        led to a contact at detail contacts (mesh_view.led_to_contacts)."""
        if self.detail != "full":
            from . import mesh_view

            search = mesh_view.led_to_contacts(search, self._contacts, self._leaf_triangle)
        self._search = search
        columns = {"sphere": search.query_sphere, "after": search.query_after, "lo": search.query_lo,
                   "hi": search.query_hi}
        self._pending.append((fmt.TOPIC_MESH_QUERIES, proto.encode_table(
            fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_MESH_QUERIES], frame, columns.__getitem__)))
        self._pending.append((fmt.TOPIC_MESH_SEARCH, proto.encode_table(
            fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_MESH_SEARCH], frame,
            lambda name: getattr(search, f"visit_{name}"))))

    def _broad_phase(self, info: BroadPhaseInfo, frame: int) -> None:
        meta = {"name": info.name, "reason": info.reason, "stats": _plain_stats(info.stats)}
        nodes = info.nodes
        if nodes is not None and fmt.TOPIC_BVH in self._channels:
            depth = nodes["depth"]
            keep = np.ones(len(depth), dtype=bool)
            meta["bvh_nodes"] = int(len(depth))
            meta["bvh_depth"] = int(depth.max()) if len(depth) else 0
            if self.bvh_max_nodes is not None and len(depth) > self.bvh_max_nodes:
                per_level = np.cumsum(np.bincount(depth))
                logged = max(int(np.searchsorted(per_level, self.bvh_max_nodes, side="right")) - 1, 0)
                keep = depth <= logged
                meta["bvh_logged_depth"] = logged
                self.bvh_capped_steps += 1
                self.bvh_logged_depth = logged
            index = np.nonzero(keep)[0]
            self._pending.append((fmt.TOPIC_BVH, proto.encode_table(
                fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_BVH], frame, lambda name: index if name == "node" else nodes[name][index])))
            if keep.all():
                self._pending.append((fmt.TOPIC_BVH_ORDER, proto.encode_table(
                    fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_BVH_ORDER], frame, lambda name: nodes["order"])))
        meta["step"] = frame
        self._pending.append((fmt.TOPIC_BROAD_PHASE, json.dumps(fmt.foxglove_json(meta)).encode()))

    # ------------------------------------------------------------------ end
    def close(self) -> None:
        """Write the summary and close the file (events of an unfinished step are dropped)."""
        if self.closed:
            return
        self.closed = True
        self._pending.clear()
        self._outbox = []
        self.frames = self._sent_frames  # a state encoded but never sent is not in the file
        del self._index_rows[self.frames:]
        if self._error is None and fmt.TOPIC_FRAME_INDEX in self._channels and self._index_rows:
            times, log_ns, dts, digests = zip(*self._index_rows, strict=True)
            columns = {"time": np.array(times), "log_time": np.array(log_ns, dtype=np.uint64), "dt": np.array(dts),
                       "state_hash": np.frombuffer(b"".join(digests), dtype=np.uint8).reshape(-1, 16)}
            last = len(times) - 1
            data = proto.encode_table(fmt.MESSAGE_OF_TOPIC[fmt.TOPIC_FRAME_INDEX], last, columns.__getitem__)
            with self._room:
                self._queued_bytes += len(data)
            self._queue.put([(self._channels[fmt.TOPIC_FRAME_INDEX], last, int(log_ns[-1]), data)])
        self._queue.put(None)
        self._thread.join()
        try:
            if self._error is None:
                self._writer.finish()
        except OSError as err:
            self._error = err
        try:
            self._file.close()
        except OSError as err:  # the buffered tail could not be written either
            self._error = self._error or err
        if self._error is not None:
            self._cut_to_whole_records()
            raise OSError(f"writing {self.path} failed: {self._error}") from self._error
        self.bytes_written = self.path.stat().st_size

    def _cut_to_whole_records(self) -> None:
        """After a write error (a full disk), cut the file back to what the last successful
        flush left: whole chunks, which a reader reads as a truncated recording."""
        import os

        try:
            with open(self.path, "r+b") as f:
                os.ftruncate(f.fileno(), self._good_size)
        except OSError:
            pass  # not a regular file, or gone: nothing to keep

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _plain_stats(stats: dict) -> dict:
    out = {}
    for key, value in stats.items():
        if isinstance(value, (np.generic,)):
            value = value.item()
        if isinstance(value, float) and not np.isfinite(value):
            value = None
        out[key] = value
    return out
