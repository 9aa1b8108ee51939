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
    """A table message. column(source_name) -> (R,) or (R, 3) or (R, 16) array of that column."""
    fields, table = fmt.PROTOBUF_MESSAGES[name]
    message = message_class(name)(step=step)
    for field, kind, axis, source, is_bytes in proto_fields(fields):
        values = np.asarray(column(source))
        if is_bytes:
            values = np.ascontiguousarray(values, dtype=np.uint8)
            data = [row.tobytes() for row in values] if table else values.tobytes()
        else:
            values = values[..., axis] if axis is not None else values
            data = values.astype(kind, copy=False).tolist()  # one C loop; extend() of numpy is slower
        if table:
            getattr(message, field).extend(data)
        else:
            setattr(message, field, data)
    return message.SerializeToString()


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
