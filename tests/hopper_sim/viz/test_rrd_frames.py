"""The ``.rrd`` check that runs before rerun's decoder (hopper_sim.viz.rrd_frames).

rerun's decoder aborts the process on an Arrow buffer that points past its message body;
these files must instead give a ``RecordingError`` that names the message. The corrupt
files are built structurally (this module's own protobuf and flatbuffer walking), so the
tests do not depend on where a random bit flip lands.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import pyarrow as pa
import pytest

from hopper_sim.viz.recording import RecordingError, RerunRecorder
from hopper_sim.viz.recording_reader import summarize_recording
from hopper_sim.viz.rrd_frames import _varint as _varint_at
from hopper_sim.viz.rrd_frames import check_rrd
from planner.scenario import load_scenario
from tests.hopper_sim.synthetic_runs import feed, run_events

_FRAME = struct.Struct("<QQ")


@pytest.fixture(scope="module")
def rrd(tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("rrd") / "r.rrd"
    with RerunRecorder(path) as rec:
        feed(rec, run_events(load_scenario("a"), 0, 2))
    return path.read_bytes()


def _frames(data: bytes) -> list[tuple[int, int, bytes]]:
    """``(offset, kind, body)`` of each message up to the end of stream."""
    out, pos = [], 12
    while pos < len(data):
        kind, length = _FRAME.unpack_from(data, pos)
        out.append((pos, kind, data[pos + 16 : pos + 16 + length]))
        if kind == 0:
            break
        pos += 16 + length
    return out


def _varint(value: int) -> bytes:
    out = bytearray()
    while True:
        out.append((value & 0x7F) | (0x80 if value > 0x7F else 0))
        value >>= 7
        if not value:
            return bytes(out)


def _proto(body: bytes) -> list[tuple[int, int, int | bytes]]:
    out, pos = [], 0
    while pos < len(body):
        key, pos = _varint_at(body, pos)
        if key & 7 == 0:
            value, pos = _varint_at(body, pos)
        else:
            n, pos = _varint_at(body, pos)
            value, pos = body[pos : pos + n], pos + n
        out.append((key >> 3, key & 7, value))
    return out


def _encode(fields: list[tuple[int, int, int | bytes]]) -> bytes:
    out = b""
    for number, wire, value in fields:
        out += _varint(number << 3 | wire)
        out += _varint(value) if wire == 0 else _varint(len(value)) + value
    return out


def _with_message(data: bytes, offset: int, kind: int, body: bytes) -> bytes:
    old = _FRAME.unpack_from(data, offset)[1]
    return data[:offset] + _FRAME.pack(kind, len(body)) + body + data[offset + 16 + old :]


def _record_batch_message(data: bytes) -> tuple[int, list, bytes]:
    """The first Arrow message holding a record batch: its offset, protobuf fields and
    decompressed IPC stream."""
    for offset, kind, body in _frames(data):
        if kind != 2:
            continue
        fields = _proto(body)
        f = {n: v for n, _, v in fields}
        raw = pa.decompress(f[5], decompressed_size=f[3], codec="lz4_raw", asbytes=True)
        if len(list(pa.ipc.MessageReader.open_stream(raw))) > 1:
            return offset, fields, raw
    raise AssertionError("no record batch in the recording")


def _table(buf: bytes, pos: int, number: int) -> int:
    """Position of field ``number`` of the flatbuffer table at ``pos``."""
    vtable = pos - struct.unpack_from("<i", buf, pos)[0]
    return pos + struct.unpack_from("<H", buf, vtable + 4 + 2 * number)[0]


def _with_buffer_length(raw: bytes, buffer: int, length: int) -> bytes:
    """The IPC stream with buffer ``buffer`` of its record batch set to ``length``."""
    schema_len = struct.unpack_from("<i", raw, 4)[0]
    meta = 8 + schema_len + 8  # the record batch's flatbuffer, after its two prefixes
    root = meta + struct.unpack_from("<I", raw, meta)[0]
    header = _table(raw, root, 2)
    batch = header + struct.unpack_from("<I", raw, header)[0]
    vec_at = _table(raw, batch, 2)
    vec = vec_at + struct.unpack_from("<I", raw, vec_at)[0]
    out = bytearray(raw)
    struct.pack_into("<q", out, vec + 4 + 16 * buffer + 8, length)
    return bytes(out)


def _corrupt_buffer(data: bytes, length: int, buffer: int = 0) -> bytes:
    offset, fields, raw = _record_batch_message(data)
    bad = pa.compress(_with_buffer_length(raw, buffer, length), codec="lz4_raw", asbytes=True)
    fields = [(n, w, bad if n == 5 else v) for n, w, v in fields]
    return _with_message(data, offset, 2, _encode(fields))


def _read_back_in_a_child(path: Path) -> list[str]:
    """What the readers say of ``path``, run in a child process (an abort stays there)."""
    root = Path(__file__).resolve().parents[3]
    child = subprocess.run(
        [sys.executable, "-c", _READ_BACK, str(path)],
        capture_output=True,
        text=True,
        cwd=root,
        env={**os.environ, "PYTHONPATH": str(root)},
        timeout=120,
    )
    assert child.returncode == 0, child.stderr[-2000:]
    return child.stdout.strip().splitlines()


def _write(tmp_path: Path, data: bytes) -> Path:
    path = tmp_path / "r.rrd"
    path.write_bytes(data)
    return path


def test_a_recording_passes_and_reads_back(tmp_path, rrd):
    path = _write(tmp_path, rrd)
    check_rrd(path)
    runs = summarize_recording(path)["runs"]
    assert [r["hops"] for r in runs] == [2]


def _footerless(data: bytes) -> bytes:
    """The messages without the end of stream and the footer (as an interrupted recording
    leaves them): rerun then decodes message by message, without the footer's index."""
    return data[: next(o for o, k, _ in _frames(data) if k == 0)]


_READ_BACK = """
import sys
from hopper_sim.viz.recording import RecordingError
from hopper_sim.viz.recording_reader import read_runs, summarize_recording
for read in (summarize_recording, read_runs):
    try:
        read(sys.argv[1])
    except RecordingError as err:
        print(err)
"""


def test_a_buffer_past_the_body_is_an_error_not_an_abort(tmp_path, rrd):
    # the first buffer of a record batch is the validity bitmap of its first column, which
    # pyarrow skips without nulls and Arrow's Rust reader slices: without the check rerun
    # aborts the process on this file (SIGABRT), so the readers run in a child process
    path = _write(tmp_path, _corrupt_buffer(_footerless(rrd), 2**62))
    with pytest.raises(RecordingError, match=r"Arrow message \d+ at byte \d+ .*buffer 0"):
        check_rrd(path)
    lines = _read_back_in_a_child(path)
    assert len(lines) == 2 and all("buffer 0" in line for line in lines)


def test_an_offsets_buffer_with_a_partial_value_is_an_error_not_an_abort(tmp_path, rrd):
    # found by the reader fuzz test: a bit flip made a list's offsets buffer 13 bytes
    # long; pyarrow reads and validates it (8 bytes are needed), Arrow's Rust reader views
    # it as i32 values and panics on the 5 odd bytes (SIGABRT)
    _, _, raw = _record_batch_message(rrd)
    batch = pa.ipc.open_stream(raw).read_next_batch()
    index = 0
    for column in batch.columns:
        if pa.types.is_list(column.type):
            target, size = index + 1, column.buffers()[1].size
            break
        index += len(column.buffers())
    data = _footerless(_corrupt_buffer(rrd, size + 1, target))
    path = _write(tmp_path, data)
    _, _, bad = _record_batch_message(data)
    pa.ipc.open_stream(bad).read_all().validate(full=True)  # pyarrow alone accepts it
    with pytest.raises(RecordingError, match=r"of \d+ bytes is not a whole number of 4-byte"):
        check_rrd(path)
    lines = _read_back_in_a_child(path)
    assert len(lines) == 2 and all("4-byte values" in line for line in lines)


def _time_unit_position(raw: bytes) -> int | None:
    """Position in an IPC stream of the stored unit of its schema's first timestamp or
    duration field, or ``None``."""
    from hopper_sim.viz.rrd_frames import _field, _u32, _vector

    meta = 8  # the schema's flatbuffer, after its continuation marker and length
    root = meta + _u32(raw, meta)
    header = _field(raw, root, 2)
    schema = header + _u32(raw, header)
    for field in _vector(raw, schema, 1):
        tag = _field(raw, field, 2)
        kind = _field(raw, field, 3)
        if tag is not None and raw[tag] in (10, 18) and kind is not None:
            unit = _field(raw, kind + _u32(raw, kind), 0)
            if unit is not None:
                return unit
    return None


def _arrow_messages(data: bytes):
    """``(offset, protobuf fields, IPC stream, time unit position)`` of each Arrow message."""
    for offset, kind, body in _frames(data):
        if kind == 2:
            fields = _proto(body)
            f = {n: v for n, _, v in fields}
            raw = pa.decompress(f[5], decompressed_size=f[3], codec="lz4_raw", asbytes=True)
            yield offset, fields, raw, _time_unit_position(raw)


def test_an_unknown_time_unit_is_an_error_not_an_abort(tmp_path, rrd):
    # found by the reader fuzz test: a bit flip made a timestamp's unit -1; pyarrow read
    # the schema, Arrow's Rust reader panics on the unit (SIGABRT)
    offset, fields, raw, at = next(m for m in _arrow_messages(rrd) if m[3] is not None)
    bad = bytearray(raw)
    struct.pack_into("<h", bad, at, -1)
    packed = pa.compress(bytes(bad), codec="lz4_raw", asbytes=True)
    fields = [(n, w, packed if n == 5 else v) for n, w, v in fields]
    path = _write(tmp_path, _footerless(_with_message(rrd, offset, 2, _encode(fields))))
    with pytest.raises(RecordingError, match=r"type 1[08] with parameters Arrow does not"):
        check_rrd(path)
    lines = _read_back_in_a_child(path)
    assert len(lines) == 2 and all("Arrow does not support" in line for line in lines)


def test_a_footerless_recording_reads_back(tmp_path, rrd):
    path = _write(tmp_path, _footerless(rrd))
    check_rrd(path)
    assert [r["hops"] for r in summarize_recording(path)["runs"]] == [2]


def test_check_rrd_ends_at_the_end_of_stream(tmp_path, rrd):
    end = next(o for o, k, _ in _frames(rrd) if k == 0)
    assert check_rrd(_write(tmp_path, rrd)) == end
    assert check_rrd(_write(tmp_path, _footerless(rrd))) == end


def test_the_footer_manifest_is_not_trusted(tmp_path, rrd):
    # the footer indexes every chunk by byte offset and check_rrd does not check it: the
    # readers hand rerun only the checked messages, so even a garbled footer reads back
    # the same runs (with rerun trusting it, a corrupt offset is a decode of whatever it
    # points at)
    end = next(o for o, k, _ in _frames(rrd) if k == 0)
    body = end + 16
    garbled = rrd[:body] + bytes(b ^ 0x5A for b in rrd[body:-12]) + rrd[-12:]
    assert len(garbled) == len(rrd)
    path = _write(tmp_path, garbled)
    assert check_rrd(path) == end
    assert summarize_recording(path)["runs"] == summarize_recording(_write(tmp_path, rrd))["runs"]


def test_an_intact_rebuilt_message_still_reads(tmp_path, rrd):
    # the rebuilding itself keeps a valid file valid (the corruption is the only change)
    offset, fields, raw = _record_batch_message(rrd)
    same = pa.compress(raw, codec="lz4_raw", asbytes=True)
    fields = [(n, w, same if n == 5 else v) for n, w, v in fields]
    check_rrd(_write(tmp_path, _with_message(rrd, offset, 2, _encode(fields))))


def test_a_message_longer_than_the_file_is_an_error(tmp_path, rrd):
    offset, kind, _ = _frames(rrd)[2]
    data = rrd[:offset] + _FRAME.pack(kind, 2**40) + rrd[offset + 16 :]
    with pytest.raises(RecordingError, match=f"at byte {offset} declares {2**40} bytes"):
        check_rrd(_write(tmp_path, data))


def test_an_unknown_message_kind_is_an_error(tmp_path, rrd):
    offset, _, body = _frames(rrd)[1]
    with pytest.raises(RecordingError, match=f"unknown message kind 9 at byte {offset}"):
        check_rrd(_write(tmp_path, _with_message(rrd, offset, 9, body)))


def test_an_impossible_uncompressed_size_is_an_error(tmp_path, rrd):
    offset, fields, _ = _record_batch_message(rrd)
    fields = [(n, w, 2**50 if n == 3 else v) for n, w, v in fields]
    with pytest.raises(RecordingError, match="declares 1125899906842624 bytes from"):
        check_rrd(_write(tmp_path, _with_message(rrd, offset, 2, _encode(fields))))


@pytest.mark.parametrize("data", [b"", b"RRF", b"PK\x03\x04" + bytes(20)])
def test_a_file_without_the_header_is_an_error(tmp_path, data):
    with pytest.raises(RecordingError, match="no RRF2 header"):
        check_rrd(_write(tmp_path, data))
