"""physdbg.record.proto: the table messages written with numpy are the protobuf library's bytes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physdbg.record import format as fmt
from physdbg.record import proto

TABLES = sorted(name for name, (_, table) in fmt.PROTOBUF_MESSAGES.items() if table)


def _library_bytes(name: str, step: int, rows: np.ndarray) -> bytes:
    """The same table through the protobuf library, a field per value (what encode_table
    wrote before it wrote the wire format itself)."""
    fields, _ = fmt.PROTOBUF_MESSAGES[name]
    message = proto.message_class(name)(step=step)
    for field, kind, axis, source, is_bytes in proto.proto_fields(fields):
        values = rows[source]
        if is_bytes:
            getattr(message, field).extend(row.tobytes() for row in np.ascontiguousarray(values, dtype=np.uint8))
        else:
            values = values[..., axis] if axis is not None else values
            getattr(message, field).extend(values.astype(kind, copy=False).tolist())
    return message.SerializeToString()


def _random_rows(name: str, count: int, seed: int) -> np.ndarray:
    """``count`` rows of table ``name`` with values across each type's range: zeros, the
    extremes, negatives, NaN and infinities, -0.0, and ordinary ones."""
    rng = np.random.default_rng(seed)
    rows = np.zeros(count, dtype=fmt.dtype_of(fmt.PROTOBUF_MESSAGES[name][0]))
    for column in rows.dtype.names:
        target = rows[column]
        base = target.dtype.base
        if base.kind == "f":
            pool = np.array([0.0, -0.0, 1.5, -2.25e-300, 1e308, np.nan, np.inf, -np.inf], dtype=base)
            values = np.where(rng.random(target.shape) < 0.5, rng.normal(size=target.shape) * 1e3,
                              rng.choice(pool, size=target.shape))
        elif base.kind in "iu":
            info = np.iinfo(base)
            pool = np.array([v for v in (0, 1, info.max, info.min, info.max // 3, 127, 128, 16383, 16384)
                             if info.min <= v <= info.max], dtype=base)
            values = np.where(rng.random(target.shape) < 0.5, rng.integers(info.min, info.max, size=target.shape,
                                                                           dtype=base, endpoint=True),
                              rng.choice(pool, size=target.shape))
        else:
            values = rng.random(target.shape) < 0.5
        target[...] = values
    return rows


@pytest.mark.parametrize("name", TABLES)
@given(count=st.integers(0, 40), step=st.integers(0, 2**40), seed=st.integers(0, 2**32 - 1))
@settings(max_examples=30, deadline=None)
def test_every_table_is_written_as_the_protobuf_library_writes_it(name, count, step, seed):
    rows = _random_rows(name, count, seed)
    data = proto.encode_table(name, step, lambda column: rows[column])
    assert data == _library_bytes(name, step, rows)
    decoded_step, decoded = proto.decode_table(name, data)
    assert decoded_step == step and decoded.tobytes() == rows.tobytes()  # NaN payloads and -0.0 kept


def test_the_engines_contact_rows_are_written_as_the_library_writes_them():
    """A real step's contacts (box-rain's first steps), as the recorder writes them."""
    from physdbg.analysis.engines import box_rain_scene
    from physdbg.observe import ListObserver

    scene = box_rain_scene(300, 40)
    observer = ListObserver()
    world = scene.build_world(observer)
    for _ in range(scene.steps):
        world.step(scene.dt)
    contacts = [e for e in observer.events if type(e).__name__ == "Contacts" and len(e.rows)]
    assert contacts
    for event in contacts[-3:]:
        data = proto.encode_table("physdbg.Contacts", event.step, lambda column: event.rows[column])
        assert data == _library_bytes("physdbg.Contacts", event.step, event.rows)


@given(step=st.integers(0, 2**40), time=st.floats(allow_nan=True), dt=st.floats(allow_nan=True),
       codec=st.integers(0, 2), count=st.integers(0, 2**32 - 1), words=st.binary(max_size=64),
       asleep=st.binary(max_size=8), digest=st.binary(min_size=16, max_size=16))
@settings(max_examples=200, deadline=None)
def test_the_state_message_is_written_as_the_protobuf_library_writes_it(step, time, dt, codec, count, words, asleep,
                                                                          digest):
    values = {"time": time, "dt": dt, "state_hash": digest, "codec": codec, "count": count, "words": words,
              "asleep": asleep}
    library = proto.message_class(fmt.STATE_MESSAGE)(step=step, **values).SerializeToString()
    assert proto.encode_state_message(step, values) == library
    assert proto.encode_state_message(step, {**values, "time": 0.0, "dt": -0.0, "codec": 0, "asleep": b""}) == \
        proto.message_class(fmt.STATE_MESSAGE)(step=step, **{**values, "time": 0.0, "dt": -0.0, "codec": 0,
                                                                "asleep": b""}).SerializeToString()
