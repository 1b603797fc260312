"""One test per user-facing failure: exit code 2 (bad input) or 1 (failed run), one line on
stderr naming what and where, no traceback, nothing half-written on disk.

Unwritable destinations are made with a regular file where a folder should be (this works
for root too, whom permission bits do not stop); the read-only-folder variant runs where the
tests do not run as root.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.hopnav.conftest import assert_one_line_failure, files_under

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def blocked(tmp_path) -> Path:
    """A path whose folder cannot be created: its would-be parent is a regular file."""
    (tmp_path / "blocker").write_text("not a folder\n")
    return tmp_path / "blocker" / "sub"


# --------------------------------------------------------------------------- bad arguments


@pytest.mark.parametrize(
    "args, needle",
    [
        (["run", "--seed", "-3"], "--seed: must be a whole number >= 0, got -3"),
        (["run", "--max-steps", "0"], "--max-steps: must be a whole number >= 1"),
        (["run", "--runs", "0"], "--runs: must be a whole number >= 1"),
        (["train-controller", "--seed", "-1"], "--seed: must be a whole number >= 0, got -1"),
        (["train-controller", "--samples", "0"], "--samples: must be at least 100"),
        (["train-controller", "--samples", "10"], "--samples: must be at least 100"),
        (["train-controller", "--epochs", "0"], "--epochs: must be a whole number >= 1"),
        (["train-controller", "--hidden", "8,x"], "--hidden: expected comma-separated"),
        (["sweep", "--workers", "0"], "--workers: must be a whole number >= 1"),
        (["hop", "--perturb", "-2", "--json"], "--perturb: must be a whole number >= 0"),
        (["imdp", "solve", "m.drn", "--tolerance", "-1"], "--tolerance: must be a finite"),
    ],
)
def test_bad_arguments(hopnav, tmp_path, monkeypatch, args, needle):
    monkeypatch.chdir(tmp_path)
    assert_one_line_failure(hopnav(*args), 2, needle)
    assert files_under(tmp_path) == []


def test_train_controller_help_names_the_default_destination(hopnav):
    result = hopnav("train-controller", "--help")
    assert result.code == 0
    assert "runs/controller.pt" in result.out and "hopper_sim/data/controller.pt" in result.out


# --------------------------------------------------------------------------- destinations


@pytest.mark.parametrize(
    "make_args, what",
    [
        (lambda d: ["run", "--rrd", d / "x.rrd", "--no-png"], "--rrd"),
        (lambda d: ["run", "--png", d / "x.png", "--no-rrd"], "--png"),
        (
            lambda d: ["run", "--scenario", "c", "--q-table", d / "q.npz", "--no-rrd", "--no-png"],
            "--q-table",
        ),
        (lambda d: ["scenario", "a", "--png", d / "world.png"], "--png"),
        (lambda d: ["sweep", "--runs", "1", "--out", d], "--out"),
        (lambda d: ["imdp", "export", "--scenario", "a", "--out", d / "p.drn"], "--out"),
        (lambda d: ["train-controller", "--samples", "100", "--out", d / "c.pt"], "--out"),
        (
            lambda d: ["train-controller", "--samples", "100", "--save-data", d / "d.npz"],
            "--save-data",
        ),
    ],
)
def test_unwritable_destination_fails_before_any_work(
    hopnav, tmp_path, blocked, monkeypatch, make_args, what
):
    import hopper_sim.cli.imdp
    import hopper_sim.controller.dataset
    import hopper_sim.experiments.sweep
    import hopper_sim.navigation.runner
    import planner.warmup

    def work(*args, **kwargs):
        raise AssertionError("the work started before the destination was checked")

    for module, name in [
        (planner.warmup, "compile_kernels"),
        (hopper_sim.navigation.runner.NavigationRunner, "run"),
        (hopper_sim.experiments.sweep, "run_sweep"),
        (hopper_sim.controller.dataset, "generate_dataset"),
        (hopper_sim.cli.imdp, "scenario_product_model"),
    ]:
        monkeypatch.setattr(module, name, work)
    monkeypatch.chdir(tmp_path)
    before = files_under(tmp_path)
    result = hopnav(*make_args(blocked))
    assert_one_line_failure(result, 2, what, "blocker", "is a file, not a folder")
    assert files_under(tmp_path) == before


@pytest.mark.skipif(
    hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes in read-only folders"
)
def test_read_only_folder(hopnav, tmp_path, monkeypatch):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert_one_line_failure(hopnav("run", "--rrd", ro / "x.rrd"), 2, "--rrd", "cannot write")
        assert_one_line_failure(hopnav("sweep", "--out", ro), 2, "--out", "cannot write")
    finally:
        ro.chmod(0o755)
    assert files_under(ro) == []


@pytest.mark.parametrize(
    "args, what, suffix",
    [
        (["run", "--png", "x.gif", "--no-rrd"], "--png", ".png"),
        (["run", "--rrd", "x.txt", "--no-png"], "--rrd", ".rrd"),
        (["scenario", "a", "--png", "x.gif"], "--png", ".png"),
        (["train-controller", "--out", "c.pth"], "--out", ".pt"),
    ],
)
def test_wrong_suffix_is_refused(hopnav, tmp_path, monkeypatch, args, what, suffix):
    monkeypatch.chdir(tmp_path)
    assert_one_line_failure(hopnav(*args), 2, what, f"must end in {suffix}")
    assert files_under(tmp_path) == []


def test_a_folder_as_output_file(hopnav, tmp_path):
    (tmp_path / "x.png").mkdir()
    assert_one_line_failure(
        hopnav("scenario", "a", "--png", tmp_path / "x.png"), 2, "is a folder, not a file"
    )


def test_a_missing_output_folder_is_created(hopnav, tmp_path):
    out = tmp_path / "new" / "deeper" / "world.png"
    assert hopnav("scenario", "a", "--png", out).code == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --------------------------------------------------------------------------- imdp files


def test_imdp_export_refuses_an_unknown_suffix(hopnav, tmp_path):
    out = tmp_path / "a.prism"
    line = assert_one_line_failure(
        hopnav("imdp", "export", "--scenario", "a", "--out", out), 2, "a.prism", "--to"
    )
    assert "cannot tell the model format" in line
    assert not out.exists()


def test_imdp_export_with_explicit_format_writes_it(hopnav, tmp_path):
    out = tmp_path / "a.prism"
    assert hopnav("imdp", "export", "--scenario", "a", "--out", out, "--to", "prism").code == 0
    head = out.read_text().splitlines()[0].split()
    assert len(head) == 3  # PRISM's .tra header: states, choices, transitions
    assert (tmp_path / "a.lab").is_file()


def test_imdp_bad_input_is_exit_code_2(hopnav, tmp_path):
    bad = tmp_path / "m.drn"
    bad.write_text("@type: mdp\nnot a model\n")
    assert_one_line_failure(hopnav("imdp", "solve", bad, "--target", "goal"), 2, "m.drn")
    assert_one_line_failure(hopnav("imdp", "solve", tmp_path / "no.drn", "--target", "g"), 2)
    assert_one_line_failure(
        hopnav("imdp", "export", tmp_path / "no.drn", "--out", tmp_path / "o.drn"),
        2,
        "no such file",
    )


def test_imdp_formats_match_the_library():
    from hopper_sim.cli import imdp as command
    from planner.imdp import io

    assert command.FORMATS == io.FORMATS
    for suffix, fmt in command.SUFFIXES.items():
        assert io.guess_format(f"m{suffix}") == fmt


# --------------------------------------------------------------------------- scenarios


@pytest.mark.parametrize(
    "key, wrong, right", [("hazard", "Hazrd", "Haz"), ("goal", "Gaol", "Goal")]
)
def test_misspelt_hazard_or_goal_label(hopnav, tmp_path, key, wrong, right):
    from planner.scenario import resolve_scenario_path

    text = resolve_scenario_path("a").read_text()
    assert f'{key} = "{right}"' in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(f'{key} = "{right}"', f'{key} = "{wrong}"'))
    for command in (["scenario", bad], ["run", "--scenario", bad, "--no-rrd", "--no-png"]):
        line = assert_one_line_failure(hopnav(*command), 2, "bad.toml", f"key '{key}'")
        assert f"did you mean '{right}'" in line and "line " in line


def test_hazard_label_without_region_but_in_the_formula_is_allowed():
    import dataclasses

    from planner.scenario import load_scenario

    sc = load_scenario("a")
    regions = {k: v for k, v in sc.regions.items() if k != sc.hazard}
    kept = dataclasses.replace(sc, regions=regions)  # the out state still carries "Haz"
    assert kept.hazard == "Haz" and "Haz" in kept.labels


# --------------------------------------------------------------------------- q-tables


def _q_table_of(scenario_name: str, path: Path, provenance_record: dict | None) -> Path:
    import numpy as np

    from planner.imdp.grid import ACTIONS
    from planner.ltl.translate import translate
    from planner.qlearning import RobustQLearner
    from planner.scenario import load_scenario

    sc = load_scenario(scenario_name)
    nq = translate(sc.formula).n_states
    n = (sc.world.nx * sc.world.ny + 1) * nq
    learner = RobustQLearner(n, len(ACTIONS), n // nq, state_cell=np.arange(n) // nq)
    learner.save(path, metadata=None if provenance_record is None else provenance_record)
    return path


def test_q_table_of_another_scenario_is_refused(hopnav, tmp_path):
    from hopper_sim.experiments.provenance import provenance
    from planner.scenario import load_scenario

    q = _q_table_of("c", tmp_path / "q.npz", {"provenance": provenance(load_scenario("c"))})
    before = q.read_bytes()
    args = ["run", "--scenario", "d", "--q-table", q, "--no-rrd", "--no-png", "--max-steps", "3"]
    line = assert_one_line_failure(hopnav(*args), 2, "--q-table", "q.npz")
    assert "belongs to scenario 'c'" in line and "'d'" in line
    assert q.read_bytes() == before


def test_q_table_without_provenance_is_refused(hopnav, tmp_path):
    q = _q_table_of("c", tmp_path / "q.npz", None)
    args = ["run", "--scenario", "c", "--q-table", q, "--no-rrd", "--no-png", "--max-steps", "3"]
    assert_one_line_failure(hopnav(*args), 2, "--q-table", "carries no scenario digest")


def test_corrupt_q_table_is_refused(hopnav, tmp_path):
    q = tmp_path / "q.npz"
    q.write_bytes(b"not a zip")
    args = ["run", "--scenario", "c", "--q-table", q, "--no-rrd", "--no-png"]
    assert_one_line_failure(hopnav(*args), 2, "q.npz", "not a readable Q-table")


# --------------------------------------------------------------------------- train-controller


@pytest.mark.slow
def test_model_worse_than_chance_writes_no_checkpoint(hopnav, tmp_path, monkeypatch):
    """As with `--samples 10` before the minimum: a feasibility head right on 0 % of the
    held-out hops (here the real training, its held-out accuracy then set to 0)."""
    import hopper_sim.controller.training as training

    real = training.train_hop_model

    def worse_than_chance(*args, **kwargs):
        result = real(*args, **kwargs)
        result.metrics["feasibility"]["accuracy"] = 0.0
        return result

    monkeypatch.setattr(training, "train_hop_model", worse_than_chance)
    out = tmp_path / "c.pt"
    args = ["train-controller", "--samples", "100", "--epochs", "1", "--hidden", "4"]
    args += ["--seed", "0", "--nthread", "1", "--out", out]
    result = hopnav(*args)
    line = assert_one_line_failure(
        result, 1, "held-out hops", "no checkpoint written", after_work=True
    )
    assert "--allow-weak" in line
    assert not out.exists() and files_under(tmp_path) == []
    result = hopnav(*args, "--allow-weak")
    assert result.code == 0 and out.is_file()
    assert any("warning" in x for x in result.err_lines)


# --------------------------------------------------------------------------- Ctrl-C


def _interrupt_after(args: list[str], marker: bytes, cwd: Path) -> tuple[int, str, str]:
    """Run hopnav, send SIGINT once ``marker`` appeared on its stderr."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "hopnav", *args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    chunks: list[bytes] = []

    def read() -> None:
        while block := proc.stderr.read1(4096):
            chunks.append(block)

    reader = threading.Thread(target=read)
    reader.start()
    deadline = time.monotonic() + 240
    while marker not in b"".join(chunks) and proc.poll() is None:
        assert time.monotonic() < deadline, b"".join(chunks)[-2000:]
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    out = proc.stdout.read()
    proc.wait(timeout=120)
    reader.join()
    return proc.returncode, out.decode(), b"".join(chunks).decode()


@pytest.mark.slow
def test_ctrl_c_keeps_the_finished_runs(tmp_path):
    from hopper_sim.viz.recording import summarize_recording

    args = ["run", "--scenario", "c", "--runs", "50", "--max-steps", "5", "--seed", "2"]
    code, out, err = _interrupt_after(args, b"run 3/50", tmp_path)
    assert code == 1
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    last = [x for x in err.replace("\r", "\n").splitlines() if x.strip()][-1]
    assert last.startswith("hopnav run: run ") and "interrupted" in last
    assert sum("interrupted" in x for x in err.replace("\r", "\n").splitlines()) == 1
    assert "kept the " in last and "runs/c.rrd" in last
    kept = int(last.split("kept the ")[1].split()[0])
    assert kept >= 2
    # the recording holds every finished run, complete; no temporary file is left
    assert sorted(os.listdir(tmp_path / "runs")) == ["c.png", "c.rrd"]
    summary = summarize_recording(tmp_path / "runs" / "c.rrd")
    ended = [r for r in summary["runs"] if r["outcome"] is not None]
    assert len(ended) == kept and all(r["hops"] == r["steps"] for r in ended)
    assert summary["provenance"]["scenario"] == "c"
    # and the summary table of the finished runs went to stdout
    assert out.count("timeout") + out.count("success") + out.count("violation") >= kept


@pytest.mark.slow
def test_ctrl_c_before_any_run_finished_leaves_nothing(tmp_path):
    args = ["run", "--scenario", "a", "--max-steps", "400"]
    code, out, err = _interrupt_after(args, b"run 1/1", tmp_path)
    assert code == 1 and "Traceback" not in err
    last = [x for x in err.replace("\r", "\n").splitlines() if x.strip()][-1]
    assert "interrupted" in last and "kept the 0 finished run(s)" in last
    assert not (tmp_path / "runs").exists() or os.listdir(tmp_path / "runs") == []
    assert json.dumps(out)  # whatever it printed is text
