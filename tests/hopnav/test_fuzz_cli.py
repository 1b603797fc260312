"""Hostile command lines (:mod:`tests.hopnav.hostile`): each ends in exit code 1 or 2 with
one line on stderr, no traceback, within 30 s and 2 GiB, and leaves nothing on disk.

Most cases run in this process (:func:`hopnav.cli.main`, stderr captured, memory measured
with ``tracemalloc``, which sees Python's and numpy's allocations); the hangs of the issue run
as subprocesses with a time limit and their peak resident memory read from ``wait4``.
"""

from __future__ import annotations

import importlib
import io
import os
import subprocess
import sys
import threading
import time
import tracemalloc
from pathlib import Path

import pytest

from hopnav.cli import COMMANDS, main
from tests.hopnav.conftest import files_under
from tests.hopnav.hostile import FOLDER, Case, all_cases

ROOT = Path(__file__).resolve().parents[2]
TIME_LIMIT_S = 30.0
MEMORY_LIMIT = 2 * 2**30
CASES = all_cases()

#: The inputs listed in the issue, by class: 47 tracebacks, 4 hangs, 7 wrong successes.
ISSUE_CASES = (
    # tracebacks: RecursionError
    "issue-recursion-parens-400",
    "issue-recursion-not-1000",
    "issue-recursion-next-1000",
    "issue-recursion-until-2000",
    "issue-recursion-and-20000",
    "issue-recursion-scenario-formula-500",
    "issue-recursion-toml-array-3000",
    "issue-recursion-jsonl-array-100000",
    # UnicodeDecodeError in PRISM/DRN/bmdp files, .lab files and sweep CSVs
    "issue-unicode-prism-latin1",
    "issue-unicode-prism-binary",
    "issue-unicode-drn-latin1",
    "issue-unicode-drn-binary",
    "issue-unicode-bmdp-latin1",
    "issue-unicode-bmdp-binary",
    "issue-unicode-lab-latin1",
    "issue-unicode-sweep-csv-resume",
    "issue-unicode-sweep-csv-table-i",
    # UnboundLocalError in the bmdp reader
    "issue-unbound-bmdp-binary",
    "issue-unbound-bmdp-directory",
    # MemoryError
    "issue-memory-prism-states-1e11",
    "issue-memory-bmdp-states-2e10",
    "issue-memory-bmdp-actions-1e10",
    "issue-memory-world-1e6m",
    "issue-memory-cell-1e-4",
    "issue-memory-world-1000m",
    # OverflowError, ProductError, the process pool, sweep destinations and resume
    "issue-overflow-successor-prism",
    "issue-overflow-successor-drn",
    "issue-overflow-successor-bmdp",
    "issue-product-reward-sums-to-inf",
    "issue-sweep-cs-empty",
    "issue-sweep-out-existing-file",
    "issue-sweep-resume-meta-list",
    "issue-sweep-resume-meta-null",
    "issue-sweep-resume-meta-string",
    # writers given a directory or a folder that cannot be made
    "issue-writer-imdp-export-directory",
    "issue-writer-imdp-export-missing-folder",
    "issue-writer-scenario-png-directory",
    "issue-writer-scenario-png-missing-folder",
    "issue-writer-run-rrd-directory",
    "issue-writer-run-rrd-missing-folder",
    "issue-writer-run-png-directory",
    "issue-writer-run-png-missing-folder",
    # a corrupt checkpoint printed with a traceback
    "issue-checkpoint-corrupt",
    # hangs
    "issue-hang-automaton-24-props",
    "issue-hang-automaton-100-props",
    "issue-hang-automaton-12-F",
    "issue-hang-drn-nr-states-2e10",
    # wrong successes
    "issue-success-ap-keyword-U",
    "issue-success-ap-empty-name",
    "issue-success-ap-quote",
    "issue-success-ap-newline",
    "issue-success-dotted-identifier",
    "issue-success-bmdp-n-terminal-negative",
    "issue-success-ap-42-names",
)


def test_the_issue_cases_are_all_here_and_enough_cases():
    names = {c.name for c in CASES}
    assert set(ISSUE_CASES) <= names, sorted(set(ISSUE_CASES) - names)
    assert len(CASES) >= 300, len(CASES)
    commands = {c.argv[0] for c in CASES}
    assert set(COMMANDS) <= commands, sorted(set(COMMANDS) - commands)


@pytest.fixture(scope="module")
def warm():
    """Import every command module (and what it imports at run time) once, so that a case
    measures its own time and memory, not the first import of torch."""
    for module, _ in COMMANDS.values():
        importlib.import_module(module)
    for name in ("torch", "mujoco", "rerun", "matplotlib.pyplot", "hopper_sim.navigation.runner"):
        importlib.import_module(name)


def _materialise(case: Case, folder: Path) -> None:
    for name, content in case.files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if content is FOLDER:
            path.mkdir()
            continue
        data = content() if callable(content) else content
        path.write_bytes(data.encode() if isinstance(data, str) else data)


def _in_process(case: Case, monkeypatch, capsys) -> tuple[int, str, str, float, int]:
    if case.stdin is not None:
        stream = io.TextIOWrapper(io.BytesIO(case.stdin), encoding="utf-8")
        monkeypatch.setattr(sys, "stdin", stream)
    capsys.readouterr()
    timer = threading.Timer(TIME_LIMIT_S * 2, lambda: os.kill(os.getpid(), 2))  # a hang: SIGINT
    tracemalloc.start()
    t0 = time.perf_counter()
    timer.start()
    try:
        code = main(list(case.argv))
    except SystemExit as exc:  # argparse
        code = exc.code if isinstance(exc.code, int) else 1
    finally:
        timer.cancel()
        seconds = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    captured = capsys.readouterr()
    return code, captured.out, captured.err, seconds, peak


def _subprocess(case: Case, folder: Path) -> tuple[int, str, str, float, int]:
    """Run the case as ``python -m hopnav``; its peak resident memory from ``wait4``."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "hopnav", *case.argv],
        cwd=folder,
        env={**os.environ, "PYTHONPATH": path},
        stdin=subprocess.PIPE if case.stdin is not None else subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    chunks: dict[str, bytes] = {}

    def drain(name: str, stream) -> None:
        chunks[name] = stream.read()

    readers = [
        threading.Thread(target=drain, args=(n, s))
        for n, s in (("out", proc.stdout), ("err", proc.stderr))
    ]
    for r in readers:
        r.start()
    if case.stdin is not None:
        proc.stdin.write(case.stdin)
        proc.stdin.close()
    killer = threading.Timer(TIME_LIMIT_S, proc.kill)
    killer.start()
    try:
        _, status, usage = os.wait4(proc.pid, 0)
    finally:
        killer.cancel()
    proc.returncode = os.waitstatus_to_exitcode(status)
    for r in readers:
        r.join()
    seconds = time.perf_counter() - t0
    out, err = (chunks[k].decode(errors="replace") for k in ("out", "err"))
    return proc.returncode, out, err, seconds, usage.ru_maxrss * 1024


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_hostile_input_fails_cleanly(case, warm, tmp_path, monkeypatch, capsys):
    folder = tmp_path / "case"
    folder.mkdir()
    _materialise(case, folder)
    monkeypatch.chdir(folder)
    before = files_under(folder)
    if case.process:
        code, out, err, seconds, peak = _subprocess(case, folder)
    else:
        code, out, err, seconds, peak = _in_process(case, monkeypatch, capsys)
    lines = [x for x in err.replace("\r", "\n").splitlines() if x.strip()]
    assert code in (1, 2), (code, out[-500:], err[-500:])
    assert "Traceback" not in err and "Traceback" not in out, err[-2000:]
    assert len(lines) == 1, lines[-5:]
    assert "HOPNAV_DEBUG" not in lines[0], lines[0]  # an unexpected exception, not a clean error
    for needle in case.says:
        assert needle in lines[0], (needle, lines[0])
    assert seconds < TIME_LIMIT_S, seconds
    assert peak < MEMORY_LIMIT, peak
    assert files_under(folder) == before, sorted(set(files_under(folder)) - set(before))
