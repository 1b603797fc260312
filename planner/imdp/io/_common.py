"""Helpers shared by the model file formats."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TextIO

from planner.errors import ModelFormatError


def atomic_write(path: str | os.PathLike[str], fill: Callable[[TextIO], None]) -> None:
    """Write a text file through a temporary file in the same folder and ``os.replace``."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            fill(f)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def number(x: float) -> str:
    """Shortest text that reads back to the same float."""
    return repr(float(x))


def lines(path: str | os.PathLike[str]) -> Iterator[tuple[int, str]]:
    """``(line number, stripped text)`` of the non-empty lines of a file."""
    try:
        f = open(path, encoding="utf-8")
    except OSError as e:
        raise ModelFormatError(f"cannot open {path}: {e.strerror}") from e
    with f:
        for no, raw in enumerate(f, start=1):
            text = raw.strip()
            if text:
                yield no, text


def fail(path: str | os.PathLike[str], line: int, what: str) -> ModelFormatError:
    return ModelFormatError(f"{path}, line {line}: {what}")
