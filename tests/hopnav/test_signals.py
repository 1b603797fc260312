"""Interrupted sweeps: ``hopnav sweep --workers 2`` killed (SIGKILL) or interrupted (SIGINT
to its process group, as Ctrl-C does) at 10 random moments. No process of the sweep is left
5 s later, SIGINT ends with one line on stderr and keeps the finished runs, and
``--resume`` completes to the same table as an uninterrupted sweep.

Linux only (the processes of the sweep are found through ``/proc`` by process group).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hopnav.cli import main
from hopper_sim.experiments.sweep_files import MARKDOWN_FILE, ROWS_FILE, read_rows_csv
from tests.hopnav.hostile import scenario

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc"),
]
ROOT = Path(__file__).resolve().parents[2]
GRID = ["--cs", "0.5", "--epss", "0.005,0.0075", "--runs", "3", "--seed", "5"]
#: Attempts killed a moment after one of their runs finished (the others: a moment after
#: their start, while Python, the kernels and the workers start).
AFTER_A_RUN = (1, 4, 7)


def _group(pgid: int) -> list[int]:
    """Live (not zombie) processes of process group ``pgid``."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        if int(fields[2]) == pgid and fields[0] not in ("Z", "X"):
            found.append(int(entry))
    return found


def _wait_gone(pgid: int, seconds: float) -> list[int]:
    deadline = time.monotonic() + seconds
    while (left := _group(pgid)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return left


def _temporaries(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.endswith(".tmp")] if folder.exists() else []


def _kept(folder: Path) -> int:
    """Runs in the sweep's rows file (0 if none)."""
    rows = folder / ROWS_FILE
    return len(read_rows_csv(rows)) if rows.exists() else 0


def _comparable(rows) -> list:
    return [r.__class__(**{**r.__dict__, "seconds": 0.0}) for r in rows]


def _without_commit(markdown: str) -> str:
    """The table without the provenance's commit fields (a commit made while the test runs
    changes them, nothing else)."""
    return re.sub(r"; git_(commit|dirty) `[^`]*`", "", markdown)


def test_sweep_interrupted_at_random_moments_resumes_to_the_same_table(tmp_path, capsys):
    tiny = tmp_path / "tiny.toml"
    tiny.write_text(scenario())
    common = ["sweep", "--scenario", str(tiny), *GRID, "--json"]

    baseline = tmp_path / "baseline"
    assert main([*common, "--backend", "serial", "--out", str(baseline)]) == 0
    capsys.readouterr()

    out = tmp_path / "sweep"
    cmd = [sys.executable, "-m", "hopnav", *common, "--workers", "2", "--out", str(out), "--resume"]
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    env = {**os.environ, "PYTHONPATH": path}
    rng = np.random.default_rng(20260518)
    kinds = [signal.SIGKILL, signal.SIGINT] * 5
    rng.shuffle(kinds)
    history = []
    for k, kind in enumerate(kinds):
        after_a_run = k in AFTER_A_RUN
        delay = rng.uniform(0.0, 2.5) if after_a_run else rng.uniform(0.5, 7.0)
        kept_before = _kept(out)
        proc = subprocess.Popen(
            cmd,
            env=env,
            cwd=tmp_path,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,  # its own process group: the sweep and its workers
        )
        if after_a_run:
            deadline = time.monotonic() + 120
            while _kept(out) == kept_before and proc.poll() is None:
                assert time.monotonic() < deadline, "no run finished in 120 s"
                time.sleep(0.05)
        try:
            proc.wait(timeout=delay)
            finished_first = True
        except subprocess.TimeoutExpired:
            finished_first = False
        if not finished_first:
            if kind == signal.SIGKILL:
                os.kill(proc.pid, signal.SIGKILL)
            else:
                os.killpg(proc.pid, signal.SIGINT)  # as Ctrl-C: the whole group
            signalled = time.monotonic()
        err = proc.communicate(timeout=60)[1]
        where = f"{signal.Signals(kind).name} {'after a run' if after_a_run else 'at'} "
        where += f"+{delay:.2f} s ({_kept(out)} runs kept)"
        history.append(where)
        if finished_first:
            assert proc.returncode == 0, (where, err)
            continue
        if kind == signal.SIGKILL:
            left = _wait_gone(proc.pid, 5.0 - (time.monotonic() - signalled))
            assert left == [], f"{where}: processes left 5 s after SIGKILL: {left}"
        else:
            left = _wait_gone(proc.pid, 5.0)
            assert left == [], f"{where}: processes left after the interrupted sweep: {left}"
            lines = [x for x in err.splitlines() if x.strip()]
            assert "Traceback" not in err, (where, err)
            if proc.returncode != 0:  # it may have finished as the signal came
                assert proc.returncode == 1 and len(lines) == 1, (where, err)
                assert "interrupted" in lines[0], (where, lines)
            assert _temporaries(out) == [], where
        assert _kept(out) >= kept_before, where  # finished runs are never lost
    assert 0 < _kept(out) or any("finished" in h for h in history), history

    done = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert _comparable(read_rows_csv(out / ROWS_FILE)) == _comparable(
        read_rows_csv(baseline / ROWS_FILE)
    )
    assert _without_commit((out / MARKDOWN_FILE).read_text()) == _without_commit(
        (baseline / MARKDOWN_FILE).read_text()
    )
    print("\n".join(history))
    assert _temporaries(out) == []  # those of killed runs were removed


@pytest.mark.parametrize("kind", [signal.SIGTERM, signal.SIGINT])
def test_run_interrupted_mid_run_removes_its_temporary_files(tmp_path, kind):
    """``hopnav run`` stopped by SIGTERM (or SIGINT) while a recording is being written: one
    line, exit code 1, no temporary file or folder left beside the outputs, and the
    recording, when a run had finished, readable with every finished run (100 runs of up
    to 400 hops: the signal comes while one is in progress, however fast a run reaches the
    goal)."""
    tiny = tmp_path / "tiny.toml"
    tiny.write_text(scenario().replace("max_steps = 12", "max_steps = 400"))
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "hopnav",
            "run",
            "--scenario",
            str(tiny),
            "--runs",
            "100",
            "--quiet",
        ],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": path},
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    runs = tmp_path / "runs"
    deadline = time.monotonic() + 120
    while not _temporaries(runs):  # the recording's folder: the run has started
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
        time.sleep(0.05)
    time.sleep(1.0)
    assert proc.poll() is None, "the run ended before the signal"
    os.kill(proc.pid, kind)
    err = proc.communicate(timeout=60)[1]
    lines = [x for x in err.splitlines() if x.strip() and "kernels" not in x]
    assert proc.returncode == 1 and len(lines) == 1 and "interrupted" in lines[0], err
    assert "Traceback" not in err
    assert _temporaries(runs) == [], _temporaries(runs)
    kept = int(lines[0].split("kept the ")[1].split()[0])
    rrd = runs / "tiny.rrd"
    if kept == 0:
        assert not rrd.exists()
    else:  # the recording is readable and holds every finished run
        from hopper_sim.viz.recording import summarize_recording

        ended = [r for r in summarize_recording(rrd)["runs"] if r["outcome"] is not None]
        assert len(ended) == kept, (kept, ended)
