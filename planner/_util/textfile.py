"""Reading text files strictly: UTF-8 only, size-limited, errors naming the file and byte.

Every text input of the project (model and label files, scenarios, sweep CSVs, JSON lines on
stdin) is decoded here, so a binary or Latin-1 file fails with one message, ``FILE: not UTF-8
text at byte N (line L)``, in the caller's own error type, instead of a
``UnicodeDecodeError`` from deep inside a reader.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator

_NOT_UTF8 = "not UTF-8 text at byte {offset} (line {line}): {reason}"


def decode(
    data: bytes, source: str | os.PathLike[str], error: type[Exception], start: int = 0
) -> str:
    """``data`` decoded as UTF-8; on a bad byte ``error(message)`` naming ``source``, the
    byte offset (``start`` is the offset of ``data`` in its file) and the line."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        offset = start + err.start
        line = data.count(b"\n", 0, err.start) + 1
        raise error(
            f"{source}: " + _NOT_UTF8.format(offset=offset, line=line, reason=err.reason)
        ) from None


def read_text(path: str | os.PathLike[str], error: type[Exception], limit: int) -> str:
    """The text of file ``path`` (UTF-8, at most ``limit`` bytes).

    Raises:
        error: the file cannot be opened or read (missing, a folder, no permission), is
            larger than ``limit`` bytes, or is not UTF-8 (names the byte offset).
    """
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if size > limit:
                raise error(f"{path}: the file holds {size} bytes, more than the limit of {limit}")
            data = f.read(limit + 1)
    except OSError as err:
        raise error(f"{path}: cannot read: {err.strerror or err}") from None
    if len(data) > limit:
        raise error(f"{path}: the file holds more than the limit of {limit} bytes")
    return decode(data, path, error)


def decoded_lines(
    raw_lines: Iterable[bytes], source: str | os.PathLike[str], error: type[Exception]
) -> Iterator[tuple[int, str]]:
    """``(1-based line number, text)`` of byte lines (a binary file, ``sys.stdin.buffer``),
    each decoded as UTF-8; a bad byte raises ``error`` naming its offset in the stream."""
    offset = 0
    for no, raw in enumerate(raw_lines, start=1):
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as err:
            raise error(
                f"{source}: "
                + _NOT_UTF8.format(offset=offset + err.start, line=no, reason=err.reason)
            ) from None
        offset += len(raw)
        yield no, text
