"""Runs of other engines: read a trajectory file and write it as a physdbg recording.

The format (docs/foreign-runs.md) is what any language writes easily:

* **CSV** with the header ``step,time,body,x,y,z`` and optionally ``vx,vy,vz``: one row
  per body per step; step 0 is the initial state; steps count up by one; every step
  lists every body 0..N-1 once.
* **JSON Lines**, one object per step: ``{"step": k, "time": t, "positions": [[x, y, z],
  ...], "velocities": [[vx, vy, vz], ...]}`` (velocities optional).
* **MCAP**: the same objects as JSON messages on the channel ``/foreign/frames`` (schema
  ``physdbg.ForeignFrame``, FOREIGN_FRAME_SCHEMA), or a physdbg recording (its states).

Units: metres, seconds, metres per second (``in_units`` reads a run written in
milliseconds, centimetres or millimetres, and ``unit_mistakes`` names such a run read as
SI). The scene (a physdbg TOML scene) says what
the bodies are: radii, masses, restitution, walls, gravity. Without velocities, each
step's velocity is estimated as the step's displacement over its dt (energies are then
approximate, and the audit says so).

Every number may be NaN or infinite (an engine that blew up is worth explaining); what
may not be wrong is the structure: a wrong body count, a step missing or repeated, time
that does not increase. Each such error names the file, the line and the field.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ForeignRunError

MAX_RUN_BYTES = 2**31  # 2 GiB: a trajectory larger than this is refused before it is read
CSV_COLUMNS = ("step", "time", "body", "x", "y", "z")
CSV_VELOCITY = ("vx", "vy", "vz")


FOREIGN_TOPIC = "/foreign/frames"  # an MCAP run: one JSON message per step on this channel
FOREIGN_SCHEMA_NAME = "physdbg.ForeignFrame"
FOREIGN_FRAME_SCHEMA = {
    "title": FOREIGN_SCHEMA_NAME,
    "description": "One step of a run of another engine: the state after the step (step 0: the initial state)",
    "type": "object",
    "properties": {
        "step": {"type": "integer", "description": "0 for the initial state, then 1, 2, ... in order"},
        "time": {"type": "number", "description": "simulated time, s (0 at step 0, increasing)"},
        "positions": {"type": "array", "description": "each body's centre [x, y, z], m, in the scene's order",
                      "items": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}},
        "velocities": {"type": "array", "description": "optional: each body's velocity [vx, vy, vz], m/s",
                       "items": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}},
    },
    "required": ["step", "time", "positions"],
}





@dataclass
class ForeignRun:
    """A trajectory: times (F,) s; positions (F, N, 3) m; velocities (F, N, 3) m/s or None;
    source: the file; format: "csv", "jsonl", "mcap" or "physdbg" (a recording's states)."""

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None
    source: str
    format: str


# the units a run may be written in: name -> its size in SI (s, m). The time unit is the
# time column's only: velocities are in the length unit per second (a browser engine that
# writes Date.now()'s milliseconds still steps its physics in seconds)
TIME_UNITS = {"s": 1.0, "ms": 1e-3}
LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
_UNIT_SLACK = 1e-3  # a ratio within this share of a unit's factor is that unit


def in_units(run: ForeignRun, time_unit: str = "s", length_unit: str = "m") -> ForeignRun:
    """The run in seconds and metres, read as written in ``time_unit`` (TIME_UNITS: its time
    column) and ``length_unit`` (LENGTH_UNITS: positions, and velocities per second); the
    run itself when both are SI."""
    for unit, table, what in ((time_unit, TIME_UNITS, "time"), (length_unit, LENGTH_UNITS, "length")):
        if unit not in table:
            raise ForeignRunError(f"{what} unit {unit!r}: not one physdbg reads (one of {', '.join(table)})")
    seconds, metres = TIME_UNITS[time_unit], LENGTH_UNITS[length_unit]
    if seconds == 1.0 and metres == 1.0:
        return run
    velocities = None if run.velocities is None else run.velocities * metres
    return ForeignRun(run.times * seconds, run.positions * metres, velocities, run.source, run.format)


def unit_mistakes(run: ForeignRun, dt: float | None, positions: np.ndarray) -> list[str]:
    """What a run read as seconds and metres says of its units, against the scene's step
    ``dt`` (s) and initial ``positions`` (N, 3) m: a line per unit that is not SI (a time
    column that is a steady 1000 times the scene's steps: milliseconds, as JavaScript's
    Date.now() gives; initial positions 100 or 1000 times the scene's: centimetres or
    millimetres), each with the option that reads the run as it is. Empty when both look SI."""
    out = []
    steps = np.diff(run.times)
    if dt and len(steps) and np.all(np.isfinite(steps)):
        for unit, size in TIME_UNITS.items():
            ratio = 1.0 / size
            if ratio == 1.0:
                continue
            if np.all(np.abs(steps - ratio * dt) <= _UNIT_SLACK * ratio * dt):
                source = ", as JavaScript's Date.now() gives" if unit == "ms" else ""
                out.append(f"the run's time column counts {_UNIT_WORDS[unit]}: its steps are "
                           f"{float(np.median(steps)):.6g} where the scene's dt is {dt:.6g} s ({ratio:g}× "
                           f"longer{source}); divide the times by {ratio:g}, or read the run as it is with "
                           f"--time-unit {unit}")
            elif _whole_clock(run.times, steps, ratio * dt):
                counts = ", ".join(f"{int(k):g}" for k in sorted(set(steps.tolist()))[:4])
                out.append(f"the run's time column is a clock in whole {_UNIT_WORDS[unit]} (as JavaScript's "
                           f"Date.now() gives): its steps are {counts} where the scene's dt is {dt:.6g} s "
                           f"({ratio * dt:.6g} {unit}); give each frame the simulated time in seconds (the step "
                           f"number × dt) instead of a clock, or read the times as they are with --time-unit {unit}")
    first = run.positions[0]
    given = np.abs(positions) > 1e-12
    if given.any() and np.all(np.isfinite(first)):
        for unit, size in LENGTH_UNITS.items():
            ratio = 1.0 / size
            if ratio != 1.0 and np.allclose(first, ratio * positions, rtol=_UNIT_SLACK, atol=1e-9 * ratio):
                out.append(f"the run's positions are in {_UNIT_WORDS[unit]}: its first frame is the scene's initial "
                           f"positions times {ratio:g}; divide positions and velocities by {ratio:g}, or read the run "
                           f"as it is with --length-unit {unit}")
    return out


_UNIT_WORDS = {"ms": "milliseconds", "cm": "centimetres", "mm": "millimetres"}


def _whole_clock(times: np.ndarray, steps: np.ndarray, tick: float) -> bool:
    """Whether ``times`` (F,) are a clock that counts whole units read once a step of
    ``tick`` units (16.67 ms for dt = 1/60 s): every time a whole number, every step the
    tick rounded down or up (16 or 17), and the clock keeping pace with the steps."""
    if tick <= 1.0 or len(steps) < 2 or not np.all(times == np.round(times)):
        return False
    whole = (steps == np.floor(tick)) | (steps == np.ceil(tick))
    return bool(np.all(whole) and abs(float(times[-1] - times[0]) - tick * len(steps)) <= 1.0 + 1e-9 * tick)


def read_run(path: str | Path, bodies: int) -> ForeignRun:
    """Read a trajectory of ``bodies`` bodies (the scene's count) from a .csv, .jsonl or .mcap file."""
    path = Path(path)
    if not path.is_file():
        raise ForeignRunError(f"{path}: no such file (a foreign run is a .csv, .jsonl or .mcap file)")
    if path.stat().st_size > MAX_RUN_BYTES:
        raise ForeignRunError(f"{path}: {path.stat().st_size} bytes is more than a run may be "
                              f"({MAX_RUN_BYTES // 2**30} GiB)")
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        return _read_mcap(path, bodies)
    try:
        with open(path, encoding="utf-8", newline="") as f:
            if suffix == ".csv":
                return _read_csv(f, path, bodies)
            if suffix in (".jsonl", ".ndjson"):
                return _read_jsonl(f, path, bodies)
    except UnicodeDecodeError as err:
        raise ForeignRunError(f"{path}: not UTF-8 text ({err.reason})") from None
    raise ForeignRunError(f"{path}: unknown kind of file {suffix or '(no suffix)'}; give a .csv, .jsonl or .mcap "
                          "run (docs/foreign-runs.md)")


def _number(text: str, where: str, field: str, integer: bool = False):
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise ForeignRunError(f"{where}: field '{field}' is {str(text)[:40]!r}, not a number") from None
    if integer:
        if not value.is_integer():
            raise ForeignRunError(f"{where}: field '{field}' is {text!r}; expected a whole number")
        return int(value)
    return value


def _read_csv(f, path: Path, bodies: int) -> ForeignRun:
    reader = csv.reader(f)
    header = next(reader, None)
    if header is None:
        raise ForeignRunError(f"{path}: empty file; expected the header {','.join(CSV_COLUMNS)}")
    header = [h.strip() for h in header]
    missing = [c for c in CSV_COLUMNS if c not in header]
    if missing:
        raise ForeignRunError(f"{path}, line 1: the header lacks {', '.join(missing)}; expected "
                              f"{','.join(CSV_COLUMNS)}[,{','.join(CSV_VELOCITY)}]")
    has_v = all(c in header for c in CSV_VELOCITY)
    col = {name: header.index(name) for name in (*CSV_COLUMNS, *(CSV_VELOCITY if has_v else ()))}
    times: list[float] = []
    frames: list[np.ndarray] = []
    vframes: list[np.ndarray] = []
    current = -1
    seen: np.ndarray | None = None
    for line, row in enumerate(reader, start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        where = f"{path}, line {line}"
        if len(row) != len(header):
            raise ForeignRunError(f"{where}: {len(row)} fields; the header has {len(header)}")
        step = _number(row[col["step"]], where, "step", integer=True)
        body = _number(row[col["body"]], where, "body", integer=True)
        time = _number(row[col["time"]], where, "time")
        if step != current:
            if step != current + 1:
                raise ForeignRunError(f"{where}: field 'step' is {step}; expected {current + 1} (steps count up by "
                                      "one from 0, all rows of a step together)")
            _check_complete(seen, path, line - 1, current, bodies)
            current = step
            _check_time(times, time, where)
            times.append(time)
            frames.append(np.full((bodies, 3), np.nan))
            vframes.append(np.full((bodies, 3), np.nan))
            seen = np.zeros(bodies, dtype=bool)
        elif time != times[-1]:
            raise ForeignRunError(f"{where}: field 'time' is {time!r}; the other rows of step {step} say {times[-1]!r}")
        if not 0 <= body < bodies:
            raise ForeignRunError(f"{where}: field 'body' is {body}; the scene has {_bodies(bodies)} (0..{bodies - 1})")
        if seen[body]:
            raise ForeignRunError(f"{where}: body {body} appears twice in step {step}")
        seen[body] = True
        frames[-1][body] = [_number(row[col[a]], where, a) for a in "xyz"]
        if has_v:
            vframes[-1][body] = [_number(row[col[a]], where, a) for a in CSV_VELOCITY]
    _check_complete(seen, path, "end", current, bodies)
    if not frames:
        raise ForeignRunError(f"{path}: no rows after the header")
    return ForeignRun(np.array(times), np.array(frames), np.array(vframes) if has_v else None, str(path), "csv")


class _Frames:
    """Frames as JSON objects {"step", "time", "positions", "velocities"?}, one at a time
    (a JSON Lines line or an MCAP message), checked as they come."""

    def __init__(self, path: Path, bodies: int, unit: str):
        self.path, self.bodies, self.unit = path, bodies, unit
        self.times: list[float] = []
        self.frames: list[np.ndarray] = []
        self.vframes: list[np.ndarray] = []
        self.has_v: bool | None = None

    def add(self, text: str | bytes, where: str) -> None:
        try:
            record = json.loads(text)
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise ForeignRunError(f"{where}: not JSON ({getattr(err, 'msg', None) or err})") from None
        if not isinstance(record, dict):
            raise ForeignRunError(f"{where}: expected an object {{\"step\", \"time\", \"positions\"}}")
        step = _number(record.get("step"), where, "step", integer=True)
        if step != len(self.frames):
            raise ForeignRunError(f"{where}: field 'step' is {step}; expected {len(self.frames)} (one {self.unit} "
                                  f"per step, counting up from 0)")
        time = _number(record.get("time"), where, "time")
        _check_time(self.times, time, where)
        self.times.append(time)
        self.frames.append(_vectors(record.get("positions"), where, "positions", self.bodies))
        if self.has_v is None:
            self.has_v = "velocities" in record
        if self.has_v != ("velocities" in record):
            raise ForeignRunError(f"{where}: field 'velocities' is {'missing' if self.has_v else 'present'} here but "
                                  f"{'present' if self.has_v else 'missing'} in the first {self.unit}; give it in "
                                  f"every {self.unit} or none")
        if self.has_v:
            self.vframes.append(_vectors(record.get("velocities"), where, "velocities", self.bodies))

    def run(self, fmt: str) -> ForeignRun:
        if not self.frames:
            raise ForeignRunError(f"{self.path}: no steps in the file")
        return ForeignRun(np.array(self.times), np.array(self.frames),
                          np.array(self.vframes) if self.has_v else None, str(self.path), fmt)


def _read_jsonl(f, path: Path, bodies: int) -> ForeignRun:
    frames = _Frames(path, bodies, "line")
    first = True
    for line, text in enumerate(f, start=1):
        if text.strip():
            if first and _scene_line(text, f"{path}, line {line}") is not None:
                first = False
                continue  # the run's scene (run_scene reads it)
            first = False
            frames.add(text, f"{path}, line {line}")
    return frames.run("jsonl")


# A JSON Lines run may carry its scene on its first line, {"scene": NAME or a scene table}
# (physdbg-trace.js writes what start(scene) was given): run_scene reads it.
SCENE_KEY = "scene"
MAX_SCENE_LINE = 16 * 2**20  # bytes: a scene line longer than this is refused unread


def _scene_line(text: str, where: str):
    """The value of a {"scene": ...} line (no "step" field), else None; a line that begins
    as one and does not parse is refused (ForeignRunError, naming ``where``)."""
    stripped = text.lstrip()
    if not stripped.startswith("{") or f'"{SCENE_KEY}"' not in stripped[:64 + len(SCENE_KEY)]:
        return None
    try:
        record = json.loads(text)
    except RecursionError:
        raise ForeignRunError(f"{where}: the scene is nested more deeply than any scene can be") from None
    except ValueError as err:  # (not JSON, or an integer of more digits than Python reads)
        raise ForeignRunError(f"{where}: the scene line is not readable JSON ({getattr(err, 'msg', None) or err})"
                              ) from None
    if isinstance(record, dict) and SCENE_KEY in record and "step" not in record:
        return record[SCENE_KEY]
    return None


def run_scene(path: str | Path):
    """The scene a JSON Lines run carries on its first line: a built-in scene's name (str)
    or a scene table (dict, what scene.scene_from_dict reads); None when the file is not
    a .jsonl run or its first line is a frame."""
    path = Path(path)
    if not path.is_file():
        raise ForeignRunError(f"{path}: no such file (a foreign run is a .csv, .jsonl or .mcap file)")
    if path.suffix.lower() not in (".jsonl", ".ndjson"):
        return None
    try:
        with open(path, encoding="utf-8") as f:
            for text in iter(lambda: f.readline(MAX_SCENE_LINE + 1), ""):
                if len(text) > MAX_SCENE_LINE:
                    raise ForeignRunError(f"{path}, line 1: a line of more than {MAX_SCENE_LINE // 2**20} MiB; a "
                                          f"scene line is at most that")
                if text.strip():
                    value = _scene_line(text, f"{path}, line 1")
                    if value is not None and not isinstance(value, (str, dict)):
                        raise ForeignRunError(f"{path}, line 1: field 'scene' is {type(value).__name__}; expected a "
                                              f"built-in scene's name or a scene object (docs/foreign-runs.md)")
                    return value
    except UnicodeDecodeError as err:
        raise ForeignRunError(f"{path}: not UTF-8 text ({err.reason})") from None
    return None


def _read_mcap(path: Path, bodies: int) -> ForeignRun:
    """An MCAP file with the channel FOREIGN_TOPIC (JSON messages, the JSON Lines object),
    or a physdbg recording (its states are the run)."""
    import struct

    from mcap.exceptions import McapError
    from mcap.stream_reader import StreamReader
    from mcap.records import Channel, Message

    frames = _Frames(path, bodies, "message")
    channels: dict[int, Channel] = {}
    physdbg = False
    count = 0
    try:
        with open(path, "rb") as f:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Channel):
                    channels[record.id] = record
                    physdbg |= record.topic == "/physdbg/scene"
                    if record.topic == FOREIGN_TOPIC and record.message_encoding != "json":
                        raise ForeignRunError(f"{path}: channel {FOREIGN_TOPIC} has message encoding "
                                              f"{record.message_encoding!r}; expected 'json'")
                elif isinstance(record, Message) and channels[record.channel_id].topic == FOREIGN_TOPIC:
                    count += 1
                    frames.add(record.data, f"{path}, message {count} of {FOREIGN_TOPIC}")
    except (McapError, ValueError, KeyError, EOFError, struct.error) as err:
        if not (count or physdbg):
            why = "it ends early" if type(err).__name__ == "EndOfFile" else f"{type(err).__name__}: {err}"
            raise ForeignRunError(f"{path}: not a readable MCAP file ({why})") from None
    if count:
        return frames.run("mcap")
    if physdbg:
        return _read_recording(path, bodies)
    raise ForeignRunError(f"{path}: no {FOREIGN_TOPIC} channel and not a physdbg recording "
                          "(docs/foreign-runs.md gives the MCAP form of a run)")


def _read_recording(path: Path, bodies: int) -> ForeignRun:
    from . import open_recording

    with open_recording(path) as rec:
        if rec.header.count != bodies:
            raise ForeignRunError(f"{path}: a recording of {_bodies(rec.header.count)}; the scene has {bodies}")
        states = list(rec.states())
    return ForeignRun(np.array([s.time for s in states]), np.array([s.positions for s in states]),
                      np.array([s.velocities for s in states]), str(path), "physdbg")


def _vectors(value, where: str, field: str, bodies: int) -> np.ndarray:
    if not isinstance(value, list) or len(value) != bodies:
        got = f"{len(value)} entries" if isinstance(value, list) else type(value).__name__
        raise ForeignRunError(f"{where}: field '{field}' has {got}; the scene has {_bodies(bodies)}")
    out = np.empty((bodies, 3))
    for i, vec in enumerate(value):
        if not isinstance(vec, list) or len(vec) != 3:
            raise ForeignRunError(f"{where}: field '{field}' entry {i} is not [x, y, z]")
        # JavaScript writes NaN and infinities as null (JSON.stringify(NaN) is "null"): a null
        # coordinate is a non-finite one, which the checks name by step and body
        out[i] = [math.nan if x is None else float(x) if isinstance(x, (int, float)) and not isinstance(x, bool)
                  else _number(x, where, f"{field}[{i}]") for x in vec]
    return out


def _bodies(n: int) -> str:
    return f"{n} body" if n == 1 else f"{n} bodies"


def _check_time(times: list[float], time: float, where: str) -> None:
    if not math.isfinite(time):
        raise ForeignRunError(f"{where}: field 'time' is {time}; times must be finite seconds")
    if not times and time != 0.0:
        raise ForeignRunError(f"{where}: field 'time' is {time!r}; step 0 is the initial state at time 0")
    if times and time == times[-1] and float(time).is_integer():
        raise ForeignRunError(f"{where}: field 'time' is {time!r}, the same as the step before; time must increase. "
                              "A clock that counts whole milliseconds (JavaScript's Date.now()) reads the same time "
                              "for steps taken faster than it ticks: give each frame the simulated time in seconds "
                              "(the step number × dt), not a clock")
    if times and time <= times[-1]:
        raise ForeignRunError(f"{where}: field 'time' is {time!r}, not after the step before ({times[-1]!r}); "
                              "time must increase (seconds, not milliseconds or frames?)")


def _check_complete(seen, path: Path, line, step: int, bodies: int) -> None:
    if seen is not None and not seen.all():
        lost = np.flatnonzero(~seen)
        raise ForeignRunError(f"{path}, line {line}: step {step} lists {int(seen.sum())} of the scene's "
                              f"{_bodies(bodies)} (missing: {', '.join(map(str, lost[:5]))}{' ...' if len(lost) > 5 else ''})")


def import_run(run: ForeignRun, scene, out: Path, notes: list[str] | None = None) -> int:
    """Write a foreign run as a physdbg recording (detail state, no view) of ``scene``;
    returns the frames written. The recording's scene keeps the scene's table and marks
    the run as foreign, so ``verify`` says it cannot be re-simulated. notes: how the run
    was made (a peer adapter's translation), kept in the recording."""
    from ..engine import energies, state_hash
    from ..events import StepCounts, StepEnd
    from .header import RecordingHeader
    from .mcap_sink import McapRecorder

    st = scene.state
    if run.positions.shape[1] != st.count:
        raise ForeignRunError(f"{run.source}: {_bodies(run.positions.shape[1])}; the scene has {st.count}")
    velocities = run.velocities
    if velocities is None:  # each step's displacement over its dt; the first step's for step 0
        dts = np.diff(run.times)[:, None, None]
        velocities = np.empty_like(run.positions)
        velocities[1:] = (run.positions[1:] - run.positions[:-1]) / dts if len(dts) else 0.0
        velocities[0] = velocities[1] if len(run.times) > 1 else st.velocities
    header = RecordingHeader.from_scene(scene, "state", None)
    header.positions, header.velocities = run.positions[0].copy(), velocities[0].copy()
    header.state_hash = state_hash(header.positions, header.velocities)
    header.meta["foreign"] = {"source": Path(run.source).name, "format": run.format,
                              "velocities": "given" if run.velocities is not None else "estimated",
                              "notes": list(notes or [])}
    gravity = np.asarray(scene.settings.gravity, dtype=float)
    state = st.copy()  # the scene's bodies, at the run's positions and velocities step by step
    with McapRecorder(out, header, view=False) as recorder:
        for k in range(1, len(run.times)):
            state.positions, state.velocities = run.positions[k].copy(), velocities[k].copy()
            kinetic, potential, momentum = energies(state, gravity)
            recorder.on_event(StepEnd(k, float(run.times[k]), float(run.times[k] - run.times[k - 1]),
                                      state.positions, state.velocities, kinetic, potential, momentum, StepCounts(),
                                      _max_overlap(state.positions, st.radius, scene.walls), {},
                                      state_hash(state.positions, state.velocities)))
        return recorder.frames


def _max_overlap(x: np.ndarray, radius: np.ndarray, walls) -> float:
    """Deepest sphere–sphere or sphere–wall penetration (m, 0 when none), from positions
    alone: the engine's own measure (colliders.max_overlap) over the grid's candidate pairs;
    a sphere past a thin wall's middle went through it (the audit's tunnelling), not into it."""
    from ..engine import make_broad_phase
    from ..engine.broadphase.periodic import PeriodicBroadPhase
    from ..engine.periodic import wrap_positions
    from ..engine.colliders import max_overlap
    from ..engine.colliders import geometry_of

    finite = np.all(np.isfinite(x), axis=1)
    x, r = np.ascontiguousarray(x[finite]), np.ascontiguousarray(radius[finite])
    broad = make_broad_phase("grid")
    if walls.periodic:
        broad = PeriodicBroadPhase(broad, walls.period_origin, walls.period)
        x = x.copy()
        wrap_positions(x, walls.period_origin, walls.period)
    pairs = broad.pairs(x - r[:, None], x + r[:, None]) if len(x) > 1 else np.zeros((0, 2), np.int64)
    return float(max_overlap(x, r, pairs, geometry_of(walls), True))


def write_mcap_run(path: str | Path, times, positions, velocities=None) -> None:
    """Write a trajectory as an MCAP run (FOREIGN_TOPIC, JSON): times (F,) s, positions
    (F, N, 3) m, velocities (F, N, 3) m/s or None. What docs/foreign-runs.md shows, as used
    by the peer adapters."""
    from mcap.writer import Writer

    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="physdbg")
        schema = writer.register_schema(FOREIGN_SCHEMA_NAME, "jsonschema", json.dumps(FOREIGN_FRAME_SCHEMA).encode())
        channel = writer.register_channel(FOREIGN_TOPIC, "json", schema)
        for k, t in enumerate(times):
            frame = {"step": k, "time": float(t), "positions": np.asarray(positions[k], dtype=float).tolist()}
            if velocities is not None:
                frame["velocities"] = np.asarray(velocities[k], dtype=float).tolist()
            ns = round(float(t) * 1e9) + k  # strictly increasing even where steps are under 1 ns
            writer.add_message(channel, log_time=ns, publish_time=ns, sequence=k, data=json.dumps(frame).encode())
        writer.finish()
