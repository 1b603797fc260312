"""No writer writes through a link: a symlink planted at the final path or at the temporary
path a writer is about to use is never followed (the file it points to stays as it was),
and the written files' modes follow the user's umask.

Every writer of the project goes through :func:`planner._util.atomic.atomic_write` or, for rerun's
file sink, :func:`planner._util.atomic.new_temporary_folder`; each is exercised here through its
public function. The temporary name is drawn with :func:`secrets.token_hex`; the tests make
the first draw predictable and plant a link there, as an attacker who guessed it would.
"""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

import planner._util.atomic as atomic

VICTIM_TEXT = b"precious: must not change\n"


def _plant(folder: Path, name: str) -> Path:
    """A victim file outside ``folder``'s writer and a symlink ``folder/name`` to it."""
    victim = folder / "victim.txt"
    victim.write_bytes(VICTIM_TEXT)
    link = folder / name
    link.symlink_to(victim)
    return victim


@pytest.fixture
def guessed(monkeypatch):
    """Make the first temporary-name draw ``GUESS`` (later draws random); returns GUESS."""
    guess = "0" * 32
    draws = iter([guess])
    real = secrets.token_hex
    monkeypatch.setattr(atomic.secrets, "token_hex", lambda n=None: next(draws, None) or real(n))
    return guess


def _temp_name(target: Path, guess: str) -> str:
    return f".{target.name}.{os.getpid()}.{guess}.tmp"


def _write_text(path: Path) -> None:
    with atomic.atomic_write(path, "w") as f:
        f.write("new contents\n")


def _sweep_files(path: Path) -> None:
    from hopper_sim.experiments.sweep_files import atomic_write_text

    atomic_write_text(path, "a,b\n1,2\n")


def _figure(path: Path) -> None:
    from hopper_sim.viz.figures import render_run_figure
    from planner.scenario import load_scenario

    render_run_figure(load_scenario("a"), [], path)


def _table_plot(path: Path) -> None:
    from hopper_sim.experiments.sweep import SweepRow, summarize
    from hopper_sim.viz.sweep_plot import write_table_plot

    row = SweepRow(0.5, 0.005, 0.5, 0, 7, "success", 12, 5.0, 3, 0.9, 1, 0.8, "")
    write_table_plot(summarize([row, row]), path)


def _checkpoint(path: Path) -> None:
    from hopper_sim.controller.checkpoint import load_checkpoint, save_checkpoint

    save_checkpoint(load_checkpoint(), path)


def _q_table(path: Path) -> None:
    from planner.qlearning import RobustQLearner

    RobustQLearner(4, 2, 2, state_cell=np.array([0, 1, 0, 1])).save(path)


def _dataset(path: Path) -> None:
    from hopper_sim.controller.dataset import HopDataset, save_dataset

    n = 3
    save_dataset(
        HopDataset(np.zeros((n, 4)), np.zeros((n, 5)), np.ones(n, bool), np.zeros(n, int)), path
    )


def _model(fmt: str) -> Callable[[Path], None]:
    def write(path: Path) -> None:
        from planner.imdp.io import read_bmdp, write_model
        from tests.hopnav.hostile import BMDP

        source = path.parent / "source.bmdp"
        source.write_text(BMDP)
        write_model(read_bmdp(source), path, fmt)
        source.unlink()

    return write


def _recording(path: Path) -> None:
    from hopper_sim.viz.recording import RerunRecorder
    from planner.scenario import load_scenario
    from tests.hopper_sim.synthetic_runs import run_events

    handlers = {"RunStart": "on_run_start", "SynthesisEvent": "on_synthesis"}
    handlers |= {"HopEvent": "on_hop", "RunEnd": "on_run_end"}
    with RerunRecorder(path) as rec:
        for event in run_events(load_scenario("a"), 0, 2):
            getattr(rec, handlers[type(event).__name__])(event)


WRITERS = {
    "atomic_write": (_write_text, "out.txt"),
    "sweep_files": (_sweep_files, "sweep_runs.csv"),
    "figure": (_figure, "world.png"),
    "table_plot": (_table_plot, "table_i.png"),
    "checkpoint": (_checkpoint, "c.pt"),
    "q_table": (_q_table, "q.npz"),
    "dataset": (_dataset, "d.npz"),
    "prism": (_model("prism"), "m.tra"),
    "drn": (_model("drn"), "m.drn"),
    "bmdp": (_model("bmdp"), "m.bmdp"),
    "recording": (_recording, "r.rrd"),
}


@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_a_link_at_the_final_path_is_replaced_not_followed(tmp_path, writer):
    write, name = WRITERS[writer]
    victim = _plant(tmp_path, name)
    if writer == "prism":
        lab_victim = tmp_path / "lab-victim.txt"
        lab_victim.write_bytes(VICTIM_TEXT)
        (tmp_path / "m.lab").symlink_to(lab_victim)
    write(tmp_path / name)
    assert victim.read_bytes() == VICTIM_TEXT
    assert not (tmp_path / name).is_symlink() and (tmp_path / name).stat().st_size > 0
    if writer == "prism":
        assert lab_victim.read_bytes() == VICTIM_TEXT and not (tmp_path / "m.lab").is_symlink()
    assert not [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_a_link_at_the_temporary_path_is_not_followed(tmp_path, writer, guessed):
    write, name = WRITERS[writer]
    link_name = _temp_name(tmp_path / name, guessed)
    victim = _plant(tmp_path, link_name)
    if writer == "prism":  # the .tra is written first and draws the guess
        pass
    write(tmp_path / name)
    assert victim.read_bytes() == VICTIM_TEXT  # the planted link was not written through
    assert (tmp_path / link_name).is_symlink()  # nor removed: it is not the writer's
    assert (tmp_path / name).is_file() and not (tmp_path / name).is_symlink()
    others = [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert others == [link_name]


def test_the_old_predictable_temporary_name_is_harmless(tmp_path):
    """The recording's temporary file used to be ``.NAME.PID.tmp``, a link planted there made
    ``hopnav run`` overwrite any file."""
    target = tmp_path / "r.rrd"
    victim = _plant(tmp_path, f".r.rrd.{os.getpid()}.tmp")
    _recording(target)
    assert victim.read_bytes() == VICTIM_TEXT and target.is_file()


@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
@pytest.mark.parametrize("writer", ["atomic_write", "recording", "checkpoint", "sweep_files"])
def test_modes_follow_the_umask(tmp_path, writer, mask):
    write, name = WRITERS[writer]
    previous = os.umask(mask)  # the test sets it; the library never does
    try:
        write(tmp_path / name)
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o666 & ~mask


def test_the_library_never_changes_the_umask(tmp_path, monkeypatch):
    def forbidden(mask):
        raise AssertionError("os.umask called")

    monkeypatch.setattr(os, "umask", forbidden)
    for writer in ("atomic_write", "recording", "q_table"):
        write, name = WRITERS[writer]
        write(tmp_path / name)


@pytest.mark.parametrize("writer", ["atomic_write", "recording"])
def test_stale_temporaries_of_dead_writers_are_removed(tmp_path, writer):
    """A writer killed by SIGKILL leaves its temporary file (or the recording's folder); the
    next write of the same path removes those of processes that no longer run (and leaves a
    live writer's alone)."""
    import subprocess
    import sys

    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    pid = int(dead.stdout)
    write, name = WRITERS[writer]
    target = tmp_path / name
    stale_file = tmp_path / f".{name}.{pid}.{'a' * 32}.tmp"
    stale_file.write_text("half")
    stale_folder = tmp_path / f".{name}.{pid}.{'b' * 32}.tmp"
    stale_folder.mkdir()
    (stale_folder / name).write_text("half")
    live = tmp_path / f".{name}.{os.getppid()}.{'c' * 32}.tmp"
    live.write_text("a writer that still runs")
    unrelated = tmp_path / f".{name}.notes.tmp"
    unrelated.write_text("not ours")
    write(target)
    assert not stale_file.exists() and not stale_folder.exists()
    assert live.exists() and unrelated.exists()
    assert target.is_file() and target.stat().st_size > 0
