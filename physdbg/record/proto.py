"""Protobuf messages for the physdbg channels, built from the field lists in :mod:`.format`.

One schema per record type: each field list (name, numpy dtype, shape) in format.py is
both the numpy row type physdbg reads into and, through this module, the protobuf
message any MCAP tool decodes (schema encoding ``protobuf``, the FileDescriptorSet in the
file). No .proto files and no generated code: the descriptors are built here at run time
from the same lists, so the two can never disagree.

Mapping (what docs/recording-format.md documents):

* every message starts with ``uint64 step = 1``: the step number (0 = the initial state,
  k = everything about the k-th step, as everywhere in physdbg);
* a **table** (many rows per message: contacts, swept tests, ...) has one ``repeated``
  (packed) field per column; a **row** (one record: the step statistics) has plain fields,
  so Foxglove's Plot panel and rerun's reflection plot them directly;
* a (3,) vector column ``point`` becomes three fields ``point_x``, ``point_y``, ``point_z``;
  a (16,) uint8 column (a hash) becomes ``bytes``; numpy f8 → double, f4 → float,
  signed ints → sint32/sint64 (zigzag: −1 costs one byte), unsigned → uint32/uint64.
"""

from __future__ import annotations

import struct
from functools import cache

import numpy as np

from . import format as fmt

PACKAGE = "physdbg"
AXES = ("x", "y", "z")


def _scalar_type(kind: str) -> int:
    from google.protobuf.descriptor_pb2 import FieldDescriptorProto as F

    dtype = np.dtype(kind)
    if dtype.kind == "f":
        return F.TYPE_DOUBLE if dtype.itemsize == 8 else F.TYPE_FLOAT
    if dtype.kind == "i":
        return F.TYPE_SINT64 if dtype.itemsize == 8 else F.TYPE_SINT32
    if dtype.kind == "u":
        return F.TYPE_UINT64 if dtype.itemsize == 8 else F.TYPE_UINT32
    if dtype.kind == "b":
        return F.TYPE_BOOL
    raise TypeError(f"no protobuf type for numpy {kind!r}")


def proto_fields(fields) -> list[tuple[str, str, int | None, str, bool]]:
    """(protobuf field name, numpy kind, vector axis or None, source column, is bytes) of
    each protobuf field of a field list."""
    out = []
    for name, kind, shape in fields:
        if shape == (3,):
            out += [(f"{name}_{axis}", kind, i, name, False) for i, axis in enumerate(AXES)]
        elif shape == ():
            out.append((name, kind, None, name, False))
        elif np.dtype(kind) == np.uint8 and len(shape) == 1:
            out.append((name, kind, None, name, True))
        else:
            raise TypeError(f"field {name}: shape {shape} has no protobuf form")
    return out


@cache
def message_class(name: str):
    """The protobuf class of a physdbg message (``physdbg.Contacts``, ...)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    F = descriptor_pb2.FieldDescriptorProto
    short = name.split(".")[-1]
    file = descriptor_pb2.FileDescriptorProto(name=f"physdbg/{short}.proto", package=PACKAGE, syntax="proto3")
    message = file.message_type.add(name=short)
    message.field.add(name="step", number=1, type=F.TYPE_UINT64, label=F.LABEL_OPTIONAL)
    if name == fmt.STATE_MESSAGE:
        for number, (field, kind) in enumerate(fmt.STATE_MESSAGE_FIELDS, start=2):
            message.field.add(name=field, number=number, type=F.TYPE_BYTES if kind == "bytes" else _scalar_type(kind),
                              label=F.LABEL_OPTIONAL)
    else:
        fields, table = fmt.PROTOBUF_MESSAGES[name]
        label = F.LABEL_REPEATED if table else F.LABEL_OPTIONAL
        for number, (field, kind, _, _, is_bytes) in enumerate(proto_fields(fields), start=2):
            kind_type = F.TYPE_BYTES if is_bytes else _scalar_type(kind)
            message.field.add(name=field, number=number, type=kind_type, label=label)
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


def schema_data(name: str) -> bytes:
    """The FileDescriptorSet of a message: an MCAP schema's data (encoding ``protobuf``)."""
    from mcap_protobuf.schema import build_file_descriptor_set

    return build_file_descriptor_set(message_class(name)).SerializeToString()


def encode_table(name: str, step: int, column) -> bytes:
    """A table message. column(source_name) -> (R,) or (R, 3) or (R, 16) array of that column.

    A table's columns are written straight to protobuf's wire format with numpy (packed
    repeated fields: a tag, a length, then the column's little-endian values or varints;
    a bytes column as one length-delimited field per row), the bytes the protobuf library
    writes for the same message (tests/test_record_proto.py holds the two equal) at a
    fraction of the cost: the library takes a Python float per value, which was most of
    what recording the contacts of box-rain 10k cost (docs/recording.md). A row message
    (one record: the step statistics) goes through the library."""
    fields, table = fmt.PROTOBUF_MESSAGES[name]
    if not table:
        message = message_class(name)(step=step)
        for field, kind, axis, source, is_bytes in proto_fields(fields):
            values = np.asarray(column(source))
            if is_bytes:
                setattr(message, field, np.ascontiguousarray(values, dtype=np.uint8).tobytes())
            else:
                values = values[..., axis] if axis is not None else values
                setattr(message, field, values.astype(kind, copy=False).tolist())
        return message.SerializeToString()
    parts = [b"\x08" + varint(step)] if step else []
    for tag, kind, axis, source, is_bytes in _table_fields(name):
        values = np.asarray(column(source))
        if is_bytes:
            rows = np.ascontiguousarray(values, dtype=np.uint8)
            if rows.shape[0]:
                rows = rows.reshape(rows.shape[0], -1)
                head = tag + varint(rows.shape[1])
                framed = np.empty((rows.shape[0], len(head) + rows.shape[1]), dtype=np.uint8)
                framed[:, :len(head)] = np.frombuffer(head, dtype=np.uint8)
                framed[:, len(head):] = rows
                parts.append(framed.tobytes())
            continue
        values = values[..., axis] if axis is not None else values
        if values.shape[0] == 0:
            continue
        payload = _packed(values, kind)
        parts += [tag, varint(len(payload)), payload]
    return b"".join(parts)


@cache
def _table_fields(name: str) -> list[tuple[bytes, np.dtype, int | None, str, bool]]:
    """A table's protobuf fields in order, each as (its tag's bytes (length-delimited), its
    numpy dtype, vector axis, source column, is bytes): proto_fields, worked out once."""
    return [(varint((number << 3) | 2), np.dtype(kind), axis, source, is_bytes)
            for number, (_field, kind, axis, source, is_bytes)
            in enumerate(proto_fields(fmt.PROTOBUF_MESSAGES[name][0]), start=2)]


def encode_state_message(step: int, values: dict) -> bytes:
    """The physdbg.State message of ``values`` (format.STATE_MESSAGE_FIELDS' names: floats,
    unsigned integers, bytes), written as encode_table writes a table: the protobuf
    library's bytes (proto3 leaves out a field at its default: 0, all-zero bits, empty)
    without copying the state's words twice through the library."""
    parts = [b"\x08" + varint(step)] if step else []
    for number, (field, kind) in enumerate(fmt.STATE_MESSAGE_FIELDS, start=2):
        value = values[field]
        if kind == "bytes":
            if len(value):
                parts += [varint(number << 3 | 2), varint(len(value)), value]
        elif np.dtype(kind).kind == "f":
            packed = struct.pack("<d" if np.dtype(kind).itemsize == 8 else "<f", value)
            if packed.count(0) != len(packed):
                parts += [varint(number << 3 | (1 if len(packed) == 8 else 5)), packed]
        elif value:
            parts += [varint(number << 3), varint(int(value))]
    return b"".join(parts)


def _packed(values: np.ndarray, dtype: np.dtype) -> bytes:
    """The payload of a packed repeated field of ``dtype``'s protobuf type (_scalar_type)."""
    if dtype.kind == "f":  # (a strided column is copied once, by tobytes)
        return values.astype(dtype.newbyteorder("<"), copy=False).tobytes()
    if dtype.kind == "b":
        return values.astype(np.uint8).tobytes()
    if dtype.kind == "u":
        return _varints(values.astype(dtype, copy=False).astype(np.uint64))
    if dtype.itemsize == 8:  # sint64: zigzag
        signed = values.astype(np.int64, copy=False)
        return _varints(((signed << 1) ^ (signed >> 63)).view(np.uint64))
    signed = values.astype(dtype, copy=False).astype(np.int32)  # sint32: zigzag on 32 bits
    return _varints(((signed << 1) ^ (signed >> 31)).view(np.uint32).astype(np.uint64))


def varint(value: int) -> bytes:
    """One unsigned integer's varint (a tag, a length: _varints for a column)."""
    out = bytearray()
    while value > 0x7F:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _varints(values: np.ndarray) -> bytes:
    """(R,) uint64 -> their base-128 varints, one after another (protobuf's encoding of
    unsigned integers: 7 bits a byte, low first, the top bit set on all but the last)."""
    v = np.ascontiguousarray(values, dtype=np.uint64)
    if v.size == 0:
        return b""
    width = max(1, (int(v.max()).bit_length() + 6) // 7)  # bytes of the longest
    if width == 1:
        return v.astype(np.uint8).tobytes()
    groups = ((v[:, None] >> np.arange(0, 7 * width, 7, dtype=np.uint64)[None, :]) & np.uint64(0x7F)).astype(np.uint8)
    length = np.ones(v.shape[0], dtype=np.int64)
    for b in range(1, width):
        length[v >= np.uint64(1 << (7 * b))] = b + 1
    columns = np.arange(width)[None, :]
    groups |= (columns < (length - 1)[:, None]).astype(np.uint8) << 7
    return groups[columns < length[:, None]].tobytes()


def decode_table(name: str, data: bytes) -> tuple[int, np.ndarray]:
    """(step, rows as a numpy structured array of format.dtype_of(fields)) of a message; a
    row message gives one row."""
    fields, table = fmt.PROTOBUF_MESSAGES[name]
    message = message_class(name).FromString(data)
    dtype = fmt.dtype_of(fields)
    parts = proto_fields(fields)
    if table:
        count = len(getattr(message, parts[0][0]))
    else:
        count = 1
    rows = np.zeros(count, dtype=dtype)
    for field, kind, axis, source, is_bytes in parts:
        value = getattr(message, field)
        if table and count and not len(value):  # a column newer than the file: its zeros
            continue
        if is_bytes:
            raw = b"".join(value) if table else value
            rows[source] = np.frombuffer(raw, dtype=np.uint8).reshape(count, -1) if count else rows[source]
        elif axis is not None:
            rows[source][:, axis] = np.asarray(value if table else [value], dtype=kind)
        else:
            rows[source] = np.asarray(value if table else [value], dtype=kind)
    return int(message.step), rows
