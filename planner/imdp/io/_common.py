"""Helpers shared by the model file formats: strict reading and the size limits.

Files are read as UTF-8 (a bad byte is a :class:`ModelFormatError` naming the file, the byte
offset and the line), one line of at most :data:`MAX_LINE_BYTES` at a time. Counts that a
reader allocates for (states declared in a header, actions, transitions) are checked
against :data:`MAX_STATES`, :data:`MAX_ACTIONS` and :data:`MAX_ENTRIES` before anything is
allocated, and every index against the model's range, so a hostile header fails at once.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from typing import TextIO

from planner._util.atomic import atomic_write as atomic_text
from planner._util.textfile import decoded_lines
from planner.errors import ModelFormatError


def atomic_write(path: str | os.PathLike[str], fill: Callable[[TextIO], None]) -> None:
    """Write a text file through a temporary file in the same folder and ``os.replace``."""
    with atomic_text(path, "w") as f:
        fill(f)


def number(x: float) -> str:
    """Shortest text that reads back to the same float."""
    return repr(float(x))


#: Most states of a model read from a file.
MAX_STATES = 1 << 20
#: Most actions (choices per state) of a model read from a file.
MAX_ACTIONS = 1 << 16
#: Most transitions (intervals) of a model read from a file.
MAX_ENTRIES = 1 << 22
#: Longest line of a model file [bytes].
MAX_LINE_BYTES = 1 << 20


def lines(path: str | os.PathLike[str]) -> Iterator[tuple[int, str]]:
    """``(line number, stripped text)`` of the non-empty lines of a UTF-8 file.

    Raises:
        ModelFormatError: the file cannot be opened, a line is not UTF-8 (names the byte
            offset) or longer than :data:`MAX_LINE_BYTES`.
    """
    try:
        f = open(path, "rb")
    except OSError as e:
        raise ModelFormatError(f"cannot open {path}: {e.strerror or e}") from None

    def raw_lines() -> Iterator[bytes]:
        while True:
            try:
                raw = f.readline(MAX_LINE_BYTES + 1)
            except OSError as e:  # a folder opens on some systems and fails here
                raise ModelFormatError(f"cannot read {path}: {e.strerror or e}") from None
            if not raw:
                return
            if len(raw) > MAX_LINE_BYTES:
                raise ModelFormatError(f"{path}: a line longer than {MAX_LINE_BYTES} bytes")
            yield raw

    with f:
        for no, raw in decoded_lines(raw_lines(), path, ModelFormatError):
            text = raw.strip()
            if text:
                yield no, text


def check_count(path: str | os.PathLike[str], line: int, what: str, value: int, limit: int) -> int:
    """``value`` if ``0 <= value <= limit``, else a :class:`ModelFormatError` naming the
    quantity and the limit (before anything of that size is allocated)."""
    if value < 0:
        raise fail(path, line, f"the {what} must not be negative, got {value}")
    if value > limit:
        raise fail(path, line, f"{value} {what}, more than the limit of {limit}")
    return value


def check_index(path: str | os.PathLike[str], line: int, what: str, value: int, n: int) -> int:
    """``value`` if it is an index in ``[0, n)``, else a :class:`ModelFormatError`."""
    if not 0 <= value < n:
        raise fail(path, line, f"{what} {value} is not in [0, {n})")
    return value


def fail(path: str | os.PathLike[str], line: int, what: str) -> ModelFormatError:
    return ModelFormatError(f"{path}, line {line}: {what}")
