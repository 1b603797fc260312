"""Helpers for the command-line tests: run ``hopnav`` in this process and collect what it
printed and the exit code, whether argparse exited or the command returned."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from hopnav.cli import main


@dataclass
class Result:
    code: int
    out: str
    err: str

    @property
    def err_lines(self) -> list[str]:
        return [line for line in self.err.replace("\r", "\n").splitlines() if line.strip()]


@pytest.fixture
def hopnav(capsys):
    def call(*args: str) -> Result:
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:  # argparse: --help, --version, bad arguments
            code = exc.code if isinstance(exc.code, int) else 1
        captured = capsys.readouterr()
        return Result(code, captured.out, captured.err)

    return call


def files_under(path: Path) -> list[str]:
    """Every file and folder below ``path`` (relative), hidden ones included."""
    return sorted(str(p.relative_to(path)) for p in path.rglob("*"))


def _is_progress(line: str) -> bool:
    """A progress bar (tqdm) or the kernel notice, which precede a failure after work."""
    return "%|" in line or "kernels" in line


def assert_one_line_failure(
    result: Result, code: int, *needles: str, after_work: bool = False
) -> str:
    """The convention: exit ``code``, exactly one line on stderr naming the problem (it
    contains every needle), no traceback. With ``after_work`` progress bars may precede it
    (the line is then the last). Returns that line."""
    assert result.code == code, (result.code, result.err)
    assert "Traceback" not in result.err and "Traceback" not in result.out
    lines = result.err_lines
    if after_work:
        lines = [x for x in lines if not _is_progress(x)]
        assert result.err_lines[-1] == lines[-1], result.err_lines[-3:]
    assert len(lines) == 1, lines
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]
