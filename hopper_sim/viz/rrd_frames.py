"""The framing of a rerun ``.rrd`` file, checked before rerun decodes it.

rerun's decoder takes the whole process down on some corrupt files: an Arrow IPC message
whose buffer lengths point past its body panics inside ``arrow_ipc::reader`` and the panic
aborts (rerun-sdk 0.41, found by ``tests/test_reader_fuzz.py``). A reader of files from
elsewhere must fail with an error instead, so :func:`check_rrd` walks the file first and
reads every Arrow payload with pyarrow's validating IPC reader:

* header: ``RRF2``, four version bytes, four option bytes;
* messages: ``kind`` (u64: 1 store info, 2 Arrow message, 3 blueprint activation, 0 end of
  stream, whose body is the footer manifest), ``length`` (u64), then ``length`` bytes of
  protobuf, every message within the file;
* Arrow messages (protobuf fields 2 compression, 3 uncompressed size, 4 encoding, 5
  payload): the payload LZ4-block decompressed to exactly its declared size (at most
  :data:`MAX_RATIO` times the compressed size) and read as an Arrow IPC stream, fully
  validated.

The checks follow the file format of the pinned rerun (``rerun-sdk>=0.41,<0.42``); a file
that passes is decoded by rerun as before.
"""

from __future__ import annotations

import mmap
import struct
from pathlib import Path

from hopper_sim.viz.recording import RecordingError

MAGIC = b"RRF2"
_HEADER = 12
_FRAME = struct.Struct("<QQ")
_KINDS = frozenset({0, 1, 2, 3})
"""End of stream, store info, Arrow message, blueprint activation."""
_ARROW_MSG = 2
_END = 0
_LZ4 = 2
_NO_COMPRESSION = (0, 1)
_ARROW_IPC = 1
MAX_RATIO = 255
"""LZ4's largest compression ratio: a declared uncompressed size beyond it is corrupt."""


def check_rrd(path: Path) -> int:
    """Raise :class:`RecordingError` (with the byte offset) if the framing of ``path`` or
    one of its Arrow payloads is corrupt; else return where the checked messages end: the
    byte offset of the end-of-stream message, or the file size where there is none.

    The end-of-stream message carries the footer manifest (an index of every chunk by byte
    offset), which is not checked: a reader hands rerun only the bytes before it, which
    rerun reads as a footer-less file (:func:`hopper_sim.viz.recording_reader.summarize_recording`).
    """
    with path.open("rb") as f:
        if path.stat().st_size < _HEADER or f.read(4) != MAGIC:
            raise RecordingError(f"{path} is not a readable rerun recording: no RRF2 header")
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return _check_messages(path, data)


def _check_messages(path: Path, data: mmap.mmap) -> int:
    pos, index = _HEADER, 0
    while pos < len(data):
        if pos + _FRAME.size > len(data):
            raise RecordingError(f"{path}: truncated message header at byte {pos}")
        kind, length = _FRAME.unpack_from(data, pos)
        start = pos + _FRAME.size
        if kind not in _KINDS:
            raise RecordingError(f"{path}: unknown message kind {kind} at byte {pos}")
        if length > len(data) - start:
            raise RecordingError(
                f"{path}: message {index} at byte {pos} declares {length} bytes, "
                f"{len(data) - start} remain (truncated or corrupt)"
            )
        body = data[start : start + length]
        if kind == _ARROW_MSG:
            try:
                _check_arrow_msg(body)
            except ValueError as err:
                raise RecordingError(
                    f"{path}: Arrow message {index} at byte {pos} is corrupt: {err}"
                ) from None
        if kind == _END:
            return pos  # the rest is the footer manifest and its trailer
        pos, index = start + length, index + 1
    return len(data)


def _check_arrow_msg(body: bytes) -> None:
    import pyarrow as pa
    import pyarrow.ipc as ipc

    fields = _fields(body)
    compression = fields.get(2, 0)
    size = fields.get(3, 0)
    encoding = fields.get(4, 0)
    payload = fields.get(5, b"")
    if not isinstance(payload, bytes) or not all(
        isinstance(v, int) for v in (compression, size, encoding)
    ):
        raise ValueError("fields of the wrong type")
    if encoding != _ARROW_IPC:
        raise ValueError(f"encoding {encoding} is not Arrow IPC")
    if compression == _LZ4:
        if size > MAX_RATIO * len(payload) + 16:
            raise ValueError(f"declares {size} bytes from {len(payload)} compressed")
        try:
            raw = pa.decompress(payload, decompressed_size=size, codec="lz4_raw")
        except (pa.ArrowException, ValueError, OSError) as err:
            raise ValueError(f"LZ4 payload: {err}") from None
        if raw.size != size:
            raise ValueError(f"decompressed to {raw.size} bytes, not {size}")
    elif compression in _NO_COMPRESSION:
        raw = pa.py_buffer(payload)
    else:
        raise ValueError(f"unknown compression {compression}")
    try:
        for message in ipc.MessageReader.open_stream(raw):
            meta = message.metadata.to_pybytes()
            _check_schema(meta)
            _check_buffers(meta, message.body.size if message.body else 0)
        table = ipc.open_stream(raw).read_all()
        table.validate(full=True)
        for column in table.columns:
            for chunk in column.chunks:
                _check_widths(chunk)
    except (pa.ArrowException, ValueError, OSError, struct.error) as err:
        raise ValueError(f"Arrow IPC payload: {err}") from None


def _check_widths(array) -> None:
    """Every buffer of typed values (offsets, numbers, fixed-size binary) of ``array`` and
    its children holds a whole number of values. pyarrow reads a 13-byte offsets buffer of
    a list of one element (it needs 8 bytes); Arrow's Rust reader views the buffer as
    ``i32`` values and panics on the odd 5 bytes, aborting the process."""
    import pyarrow as pa

    kind = array.type
    buffers = array.buffers()
    width = 0
    t = pa.types
    if t.is_large_list(kind) or t.is_large_string(kind) or t.is_large_binary(kind):
        width = 8
    elif t.is_list(kind) or t.is_map(kind) or t.is_string(kind) or t.is_binary(kind):
        width = 4
    elif t.is_fixed_size_binary(kind):
        width = kind.byte_width
    elif t.is_integer(kind) or t.is_floating(kind) or t.is_temporal(kind):
        width = kind.bit_width // 8
    if width and len(buffers) > 1 and buffers[1] is not None and buffers[1].size % width:
        raise ValueError(
            f"a {kind} buffer of {buffers[1].size} bytes is not a whole number of "
            f"{width}-byte values"
        )
    if t.is_list(kind) or t.is_large_list(kind) or t.is_fixed_size_list(kind):
        _check_widths(array.values)
    elif t.is_struct(kind):
        for i in range(kind.num_fields):
            _check_widths(array.field(i))


_SCHEMA, _DICTIONARY_BATCH, _RECORD_BATCH = 1, 2, 3
"""``MessageHeader`` union types of Arrow's ``Message.fbs``."""

_INT, _FLOAT, _DECIMAL, _DATE, _TIME, _TIMESTAMP, _INTERVAL = 2, 3, 7, 8, 9, 10, 11
_LIST, _FIXED_LIST, _MAP, _DURATION, _LARGE_LIST = 12, 16, 17, 18, 21
_LAST_TYPE = 26
"""``Type`` union members of Arrow's ``Schema.fbs`` whose parameters Arrow's Rust reader
checks by panicking, and the last member."""

_MAX_DEPTH = 64
"""Nesting of fields beyond which a schema is refused."""


def _check_schema(meta: bytes) -> None:
    """Every field of a schema message has a known type whose parameters Arrow's Rust
    reader accepts (it panics on the rest, e.g. a timestamp unit of -1, which pyarrow read):
    integer widths 8-64, float precisions, date, time, timestamp, interval and duration
    units, decimal widths, one child for lists and maps, the type table present where it
    has parameters. Reads ``Schema`` (``fields`` field 1) and each ``Field`` (``type_type``
    2, ``type`` 3, ``children`` 5)."""
    kind, header = _header(meta)
    if kind == _SCHEMA:
        _check_fields(meta, header, 1, 0)


def _header(meta: bytes) -> tuple[int | None, int]:
    """The ``Message`` table's ``header_type`` (``None`` without a header) and the
    position of its ``header`` table."""
    root = _u32(meta, 0)
    kind = _field(meta, root, 1)
    header = _field(meta, root, 2)
    if kind is None or header is None:
        return None, 0
    return meta[kind], header + _u32(meta, header)


def _vector(meta: bytes, table: int, number: int) -> list[int]:
    """Positions of the tables in the vector field ``number`` of ``table``."""
    at = _field(meta, table, number)
    if at is None:
        return []
    vec = at + _u32(meta, at)
    return [vec + 4 + 4 * i + _u32(meta, vec + 4 + 4 * i) for i in range(_u32(meta, vec))]


def _scalar(meta: bytes, table: int | None, number: int, fmt: str, default: int) -> int:
    at = None if table is None else _field(meta, table, number)
    return default if at is None else struct.unpack_from(fmt, meta, at)[0]


def _check_fields(meta: bytes, table: int, number: int, depth: int) -> None:
    if depth > _MAX_DEPTH:
        raise ValueError(f"fields nested more than {_MAX_DEPTH} deep")
    for field in _vector(meta, table, number):
        _check_type(meta, field)
        _check_fields(meta, field, 5, depth + 1)


def _check_type(meta: bytes, field: int) -> None:
    tag = _scalar(meta, field, 2, "<B", 0)
    at = _field(meta, field, 3)
    kind = None if at is None else at + _u32(meta, at)
    if not 1 <= tag <= _LAST_TYPE:
        raise ValueError(f"a field of unknown type {tag}")
    unit = _scalar(meta, kind, 0, "<h", 1 if tag in (_DATE, _TIME, _DURATION) else 0)
    if tag == _INT:
        ok = _scalar(meta, kind, 0, "<i", 0) in (8, 16, 32, 64)
    elif tag == _FLOAT:
        ok = unit in (0, 1, 2)
    elif tag == _DECIMAL:
        ok = _scalar(meta, kind, 2, "<i", 128) in (32, 64, 128, 256)
    elif tag == _DATE:
        ok = unit in (0, 1)
    elif tag == _TIME:
        ok = (_scalar(meta, kind, 1, "<i", 32), unit) in ((32, 0), (32, 1), (64, 2), (64, 3))
    elif tag in (_TIMESTAMP, _DURATION):
        ok = unit in (0, 1, 2, 3)
    elif tag == _INTERVAL:
        ok = unit in (0, 1, 2)
    elif tag in (_LIST, _FIXED_LIST, _MAP, _LARGE_LIST):
        ok = len(_vector(meta, field, 5)) == 1
    else:
        ok = True
    needs_table = tag in (_INT, _FLOAT, _DECIMAL, _DATE, _TIME, _TIMESTAMP, _INTERVAL)
    if not ok or (needs_table and kind is None):
        raise ValueError(f"a field of type {tag} with parameters Arrow does not support")


def _check_buffers(meta: bytes, body_size: int) -> None:
    """Every buffer ``(offset, length)`` of a record or dictionary batch message lies in
    its body, and every field node has ``0 <= null_count <= length``. pyarrow does not
    look at the buffers an array does not need (the validity buffer of an array without
    nulls); Arrow's Rust reader slices them all and panics on one past the body. Reads
    the flatbuffer ``Message`` table (``header_type`` field 1, ``header`` field 2), the
    ``RecordBatch`` (``nodes`` field 1, ``buffers`` field 2), or a ``DictionaryBatch``'s
    ``data`` (field 1)."""
    kind, batch = _header(meta)
    if kind == _DICTIONARY_BATCH:
        data = _field(meta, batch, 1)
        if data is None:
            return
        batch = data + _u32(meta, data)
    elif kind != _RECORD_BATCH:
        return
    for number, check in (
        (1, _node_ok),
        (2, lambda a, b: a >= 0 and b >= 0 and a + b <= body_size),
    ):
        at = _field(meta, batch, number)
        if at is None:
            continue
        vec = at + _u32(meta, at)
        for k in range(_u32(meta, vec)):
            a, b = struct.unpack_from("<qq", meta, vec + 4 + 16 * k)
            if not check(a, b):
                what = "field node" if number == 1 else "buffer"
                raise ValueError(f"{what} {k} ({a}, {b}) out of range (body {body_size} bytes)")


def _node_ok(length: int, null_count: int) -> bool:
    return 0 <= null_count <= length


def _u32(buf: bytes, pos: int) -> int:
    return struct.unpack_from("<I", buf, pos)[0]


def _field(buf: bytes, table: int, number: int) -> int | None:
    """Position of field ``number`` of the flatbuffer table at ``table`` (``None`` when
    absent): the table starts with the signed offset back to its vtable, whose entries
    after two ``u16`` sizes are the fields' offsets in the table."""
    vtable = table - struct.unpack_from("<i", buf, table)[0]
    size = struct.unpack_from("<H", buf, vtable)[0]
    entry = 4 + 2 * number
    if entry + 2 > size:
        return None
    off = struct.unpack_from("<H", buf, vtable + entry)[0]
    return table + off if off else None


def _fields(body: bytes) -> dict[int, int | bytes]:
    """The top-level fields of a protobuf message, by number (the last one wins; varints
    and length-delimited values, fixed-width ones skipped)."""
    out: dict[int, int | bytes] = {}
    pos = 0
    while pos < len(body):
        key, pos = _varint(body, pos)
        number, wire = key >> 3, key & 7
        if wire == 0:
            out[number], pos = _varint(body, pos)
        elif wire == 2:
            length, pos = _varint(body, pos)
            if length > len(body) - pos:
                raise ValueError(f"field {number} runs past the message")
            out[number], pos = body[pos : pos + length], pos + length
        elif wire in (1, 5):
            pos += 8 if wire == 1 else 4
        else:
            raise ValueError(f"protobuf wire type {wire}")
    if pos > len(body):
        raise ValueError("a field runs past the message")
    return out


def _varint(body: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if pos >= len(body) or shift > 63:
            raise ValueError("unterminated varint")
        byte = body[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, pos
