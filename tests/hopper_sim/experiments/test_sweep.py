"""Tests of the sweep machinery with a small deterministic run function.

``fake_run`` stands in for the navigation runner: its result is a known function of the runner
settings (C, eps) and the seed, so aggregation, ordering, seeding, the backends and the files
can be checked exactly. The shipped command uses the real runner.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from hopper_sim.cli import main as hopnav
from hopper_sim.experiments import sweep as sw
from hopper_sim.experiments import sweep_backends
from hopper_sim.experiments import sweep_files as sf
from hopper_sim.experiments.sweep import (
    PAPER_TABLE_I,
    ROW_COLUMNS,
    SweepBackendError,
    SweepError,
    SweepRow,
    SweepRunError,
    SweepSpec,
    mean_ci,
    run_sweep,
    summarize,
)
from hopper_sim.experiments.sweep_files import SweepFileError, read_rows_csv, write_outputs
from hopper_sim.navigation.events import RunEnd
from planner.scenario import load_scenario, resolve_scenario_path

SMALL = SweepSpec(cs=(0.25, 0.75), epss=(0.0025, 0.0075), runs=3, seed=7)


def fake_run(scenario, seed: int, run_index: int) -> RunEnd:
    """Steps fall with eps, reward grows with C, both plus seed-driven noise."""
    r = scenario.runner
    if r.p_rl_ee != r.c or r.seed != seed or r.runs != 1:
        raise AssertionError(f"sweep passed inconsistent runner settings {r} for seed {seed}")
    rng = np.random.default_rng(seed)
    steps = int(100 - 4000 * r.eps + rng.integers(0, 10))
    reward = float(100 * r.c + rng.normal(0.0, 5.0))
    outcome = ("success", "success", "violation", "timeout")[seed % 4]
    switch = None if outcome == "violation" else steps // 2
    end = RunEnd(
        run_index=run_index,
        outcome=outcome,
        steps=steps,
        reward=reward,
        switch_step=switch,
        p_switch=None if switch is None else 0.7,
        backups=seed % 3,
        seconds=0.0,
    )
    if hasattr(end, "reason"):  # RunEnd.reason is newer than this test
        end = dataclasses.replace(end, reason=f"ended, {outcome}")
    return end


def returns_none(scenario, seed: int, run_index: int) -> None:
    return None


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("a")


@pytest.fixture(scope="module")
def serial(scenario):
    return run_sweep(scenario, SMALL, run=fake_run, backend="serial")


# --------------------------------------------------------------------------- grid and seeds


def test_default_spec_is_table_i():
    spec = SweepSpec()
    assert spec.cs == (0.25, 0.5, 0.75)
    assert spec.epss == (0.0025, 0.005, 0.0075)
    assert spec.runs == 10
    assert set(spec.cells) == set(PAPER_TABLE_I)
    assert spec.n_runs == 90


def test_tasks_table_order_and_distinct_seeds():
    tasks = SweepSpec(runs=4, seed=3).tasks()
    assert [t.index for t in tasks] == list(range(36))
    assert [(t.c, t.eps, t.run) for t in tasks] == [
        (c, e, r) for c in (0.25, 0.5, 0.75) for e in (0.0025, 0.005, 0.0075) for r in range(4)
    ]
    assert len({t.seed for t in tasks}) == 36


def test_seeds_depend_only_on_base_seed():
    assert SweepSpec(seed=5).tasks() == SweepSpec(seed=5).tasks()
    assert [t.seed for t in SweepSpec(seed=5).tasks()] != [t.seed for t in SweepSpec().tasks()]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cs": ()}, "cs must hold at least one"),
        ({"cs": (0.5, 0.5)}, "repeated"),
        ({"cs": (1.5,)}, r"cs must lie in \[0, 1\]"),
        ({"epss": (-0.1,)}, "epss must be finite and >= 0"),
        ({"epss": (math.inf,)}, "epss must be finite"),
        ({"runs": 0}, "runs must be a whole number >= 1"),
        ({"seed": -1}, "seed must be a whole number >= 0"),
    ],
)
def test_spec_rejects_bad_input(kwargs, match):
    with pytest.raises(SweepError, match=match):
        SweepSpec(**kwargs)


# --------------------------------------------------------------------------- statistics


@pytest.mark.parametrize("n", [2, 3, 10])
def test_mean_ci_matches_scipy(n):
    y = np.random.default_rng(n).normal(50.0, 8.0, n)
    ci = mean_ci(y)
    low, high = stats.t.interval(0.95, n - 1, loc=y.mean(), scale=stats.sem(y))
    assert ci.mean == pytest.approx(y.mean())
    assert (ci.low, ci.high) == pytest.approx((low, high), rel=1e-12)
    ci90 = mean_ci(y, level=0.9)
    assert (ci90.low, ci90.high) == pytest.approx(
        stats.t.interval(0.9, n - 1, loc=y.mean(), scale=stats.sem(y)), rel=1e-12
    )


def test_mean_ci_small_and_bad_samples():
    one = mean_ci([4.0])
    assert one.mean == 4.0 and math.isnan(one.half_width) and one.n == 1
    empty = mean_ci([])
    assert math.isnan(empty.mean) and empty.n == 0
    with pytest.raises(SweepError, match="finite"):
        mean_ci([1.0, math.nan])
    with pytest.raises(SweepError, match="level"):
        mean_ci([1.0, 2.0], level=1.0)


def test_summaries_match_the_rows(serial):
    assert len(serial.rows) == SMALL.n_runs
    for cell in serial.cells:
        group = [r for r in serial.rows if (r.c, r.eps) == (cell.c, cell.eps)]
        assert len(group) == SMALL.runs == cell.n
        rewards = np.array([r.reward for r in group])
        steps = np.array([r.steps for r in group], dtype=float)
        assert cell.reward.mean == pytest.approx(rewards.mean())
        assert (cell.steps.low, cell.steps.high) == pytest.approx(
            stats.t.interval(0.95, 2, loc=steps.mean(), scale=stats.sem(steps))
        )
        assert cell.successes == sum(r.outcome == "success" for r in group)
        assert sum(cell.outcomes.values()) == cell.n
        assert cell.success_rate == cell.successes / cell.n
        assert cell.paper == PAPER_TABLE_I[(cell.c, cell.eps)]


def test_summarize_without_spec_finds_the_cells(serial):
    cells = summarize(serial.rows)
    assert [(s.c, s.eps) for s in cells] == SMALL.cells
    assert [s.reward.mean for s in cells] == [s.reward.mean for s in serial.cells]


# --------------------------------------------------------------------------- running


def test_rows_follow_the_tasks(serial, scenario):
    tasks = SMALL.tasks()
    for task, row in zip(tasks, serial.rows, strict=True):
        assert (row.c, row.eps, row.p_rl_ee, row.run, row.seed) == (
            task.c,
            task.eps,
            task.c,
            task.run,
            task.seed,
        )
        end = fake_run(
            scenario.with_runner(p_rl_ee=task.c, c=task.c, eps=task.eps, seed=task.seed, runs=1),
            task.seed,
            task.run,
        )
        assert row == SweepRow.from_run_end(task, end)
    assert serial.scenario == "a" and serial.backend == "serial" and serial.workers == 1


def test_same_seed_same_table_other_seed_other_table(serial, scenario):
    again = run_sweep(scenario, SMALL, run=fake_run, backend="serial")
    assert again.rows == serial.rows
    other = run_sweep(scenario, SweepSpec(SMALL.cs, SMALL.epss, SMALL.runs, seed=8), run=fake_run)
    assert other.rows != serial.rows


def test_progress_callback(scenario):
    calls = []
    spec = SweepSpec(cs=(0.5,), epss=(0.005,), runs=3)
    result = run_sweep(scenario, spec, run=fake_run, progress=lambda *a: calls.append(a))
    assert [(d, t) for d, t, _ in calls] == [(1, 3), (2, 3), (3, 3)]
    assert sorted((row for *_, row in calls), key=lambda r: r.run) == list(result.rows)


def test_process_backend_equals_serial(serial, scenario):
    calls = []
    par = run_sweep(
        scenario,
        SMALL,
        run=fake_run,
        backend="process",
        workers=2,
        progress=lambda d, t, row: calls.append(d),
    )
    assert par.rows == serial.rows
    assert par.cells == serial.cells
    assert par.backend == "process" and par.workers == 2
    assert calls == list(range(1, SMALL.n_runs + 1))


def test_process_backend_reraises_a_failing_run(scenario):
    with pytest.raises(
        SweepRunError,
        match=r"run [01] of cell C=0\.5, eps=0\.005 \(seed \d+\): .* must return a RunEnd",
    ):
        run_sweep(
            scenario,
            SweepSpec(cs=(0.5,), epss=(0.005,), runs=2),
            run=returns_none,
            backend="process",
            workers=1,
        )


class _InterruptedAtStart(ProcessPoolExecutor):
    """The process backend's executor, with a Ctrl-C sent to this process as the first run
    is submitted, while the workers start."""

    def submit(self, *args, **kwargs):
        if not getattr(self, "sent", False):
            self.sent = True
            os.kill(os.getpid(), signal.SIGINT)
        return super().submit(*args, **kwargs)


@pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="POSIX signal masks")
def test_process_backend_keeps_a_ctrl_c_that_comes_while_the_workers_start(scenario, monkeypatch):
    """A Ctrl-C while the pool starts is delivered once it has started, not lost. Before the
    fix it was ignored there, and the sweep ran to its end."""
    monkeypatch.setattr(sweep_backends, "ProcessPoolExecutor", _InterruptedAtStart)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            run_sweep(scenario, SMALL, run=fake_run, backend="process", workers=2)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert multiprocessing.active_children() == []  # the workers were ended and joined
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())


def slow_after_the_first(scenario, seed: int, run_index: int) -> RunEnd:
    """:func:`fake_run`, after a minute for every run but the first of its cell."""
    if run_index > 0:
        time.sleep(60.0)
    return fake_run(scenario, seed, run_index)


def test_process_backend_ends_its_workers_when_progress_raises(scenario):
    """A Ctrl-C in ``progress`` (the CLI writes its rows file there) ends the runs in
    progress at once, while the traceback still holds the sweep's frames. Before the fix the
    pool stayed open until the interpreter exited, which then ran every pending run (a
    minute each here; ``hopnav sweep`` printed "interrupted" and went on)."""

    def interrupt(done, total, row):
        raise KeyboardInterrupt

    spec = SweepSpec(cs=(0.5,), epss=(0.005,), runs=3)
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt) as raised:
        run_sweep(
            scenario,
            spec,
            run=slow_after_the_first,
            backend="process",
            workers=2,
            progress=interrupt,
        )
    assert raised.traceback  # the frames are still referenced here
    assert multiprocessing.active_children() == []
    assert time.monotonic() - start < 50.0


@pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="POSIX signal masks")
def test_workers_start_with_ctrl_c_blocked_in_a_fresh_process():
    """Workers spawned while the signals are held inherit SIGINT blocked, also in a process
    whose resource tracker is not running yet. When the first spawn starts the tracker, it
    unblocks SIGINT after its own spawn. The parent's mask is restored after."""
    code = (
        "import multiprocessing, signal\n"
        "from concurrent.futures import ProcessPoolExecutor\n"
        "from hopper_sim.experiments.sweep_backends import _signals_held\n"
        "with _signals_held():\n"
        "    pool = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context('spawn'))\n"
        "    futs = [pool.submit(signal.pthread_sigmask, signal.SIG_BLOCK, set())"
        " for _ in range(2)]\n"
        "masks = [f.result() for f in futs]\n"
        "pool.shutdown()\n"
        "print(all(signal.SIGINT in m for m in masks),"
        " signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, set()))\n"
    )
    root = Path(__file__).resolve().parents[3]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")])),
    }
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["True", "False"]


def test_bad_backend_and_workers(scenario):
    with pytest.raises(SweepBackendError, match="unknown backend 'threads'"):
        run_sweep(scenario, SMALL, run=fake_run, backend="threads")
    with pytest.raises(SweepError, match="workers"):
        run_sweep(scenario, SMALL, run=fake_run, backend="process", workers=0)


def test_ray_missing_gives_a_clear_error(scenario, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # makes `import ray` fail
    with pytest.raises(SweepBackendError, match=r"pip install 'hopnav\[ray\]'"):
        run_sweep(scenario, SMALL, run=fake_run, backend="ray")


@pytest.mark.slow
def test_ray_backend_two_runs_equal_serial(scenario):
    pytest.importorskip("ray")
    spec = SweepSpec(cs=(0.5,), epss=(0.005,), runs=2, seed=11)
    remote = run_sweep(scenario, spec, run=fake_run, backend="ray", workers=1)
    local = run_sweep(scenario, spec, run=fake_run, backend="serial")
    assert remote.rows == local.rows
    assert len(remote.rows) == 2


# --------------------------------------------------------------------------- files


def test_write_outputs_round_trip(serial, tmp_path):
    paths = write_outputs(serial, tmp_path / "out")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(
        [sf.ROWS_FILE, sf.SUMMARY_FILE, sf.MARKDOWN_FILE]
    )
    assert read_rows_csv(paths["rows"]) == list(serial.rows)
    header = paths["rows"].read_text().splitlines()[0]
    assert header == ",".join(ROW_COLUMNS)
    # a violation has no switch: an empty field, read back as None
    assert any(r.switch_step is None for r in read_rows_csv(paths["rows"]))

    summary = list(csv.DictReader(io.StringIO(paths["summary"].read_text())))
    assert [(float(r["c"]), float(r["eps"])) for r in summary] == SMALL.cells
    for rec, cell in zip(summary, serial.cells, strict=True):
        assert float(rec["reward_mean"]) == cell.reward.mean
        assert float(rec["steps_ci_low"]) == cell.steps.low
        assert float(rec["steps_ci_high"]) == cell.steps.high
        assert int(rec["n"]) == SMALL.runs
        assert float(rec["success_rate"]) == cell.success_rate
        assert float(rec["paper_reward"]) == cell.paper[0]


def test_markdown_has_table_i_layout(serial, tmp_path):
    md = write_outputs(serial, tmp_path)["markdown"].read_text()
    lines = md.splitlines()
    header = next(ln for ln in lines if ln.startswith("| P_RL,ee = C"))
    assert header == "| P_RL,ee = C | eps = 0.0025 | eps = 0.0075 |"
    cell = serial.cell(0.75, 0.0075)
    entry = (
        f"{cell.reward.mean:.1f} ± {cell.reward.half_width:.1f} / "
        f"{cell.steps.mean:.1f} ± {cell.steps.half_width:.1f} ({cell.successes}/3)"
    )
    row = next(ln for ln in lines if ln.startswith("| 0.75 |") and "±" in ln)
    assert row.endswith(f"| {entry} |")
    assert "| 0.25 | 61.2/98 | 54.6/65.1 |" in lines
    assert "| 0.75 | 136.4/84.7 | 129.6/85.3 |" in lines


def test_printed_table_shows_measured_and_paper(serial):
    text = sf.format_table(serial)
    assert "[paper 139.75/83]" not in text  # eps = 0.005 is not in SMALL
    assert "[paper 61.2/98]" in text and "[paper 129.6/85.3]" in text
    assert text.split("\n", 1)[1].count("±") == 2 * len(serial.cells)  # below the title


def test_atomic_write_keeps_old_file_on_failure(tmp_path):
    path = tmp_path / "t.csv"
    sf.atomic_write_text(path, "old\n")
    with pytest.raises(TypeError):
        sf.atomic_write_text(path, None)  # type: ignore[arg-type]
    assert path.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]


def test_read_rows_csv_names_the_problem(serial, tmp_path):
    good = sf.rows_csv(serial.rows).splitlines()
    bad = tmp_path / "bad.csv"
    fields = good[2].split(",")
    fields[ROW_COLUMNS.index("steps")] = "many"
    bad.write_text("\n".join([good[0], good[1], ",".join(fields)]) + "\n")
    with pytest.raises(SweepFileError, match=r"bad\.csv:3: column 'steps'"):
        read_rows_csv(bad)
    fields = good[1].split(",")
    fields[ROW_COLUMNS.index("outcome")] = "won"
    bad.write_text("\n".join([good[0], ",".join(fields)]) + "\n")
    with pytest.raises(SweepFileError, match=r"bad\.csv:2: column 'outcome': must be one of"):
        read_rows_csv(bad)
    cut = tmp_path / "cut.csv"
    cut.write_text(good[0].replace(",reward", "") + "\n")
    with pytest.raises(SweepFileError, match=r"cut\.csv:1: missing column\(s\) \['reward'\]"):
        read_rows_csv(cut)
    with pytest.raises(SweepFileError, match="cannot read"):
        read_rows_csv(tmp_path / "absent.csv")


def test_json_has_no_nan(scenario):
    one = run_sweep(scenario, SweepSpec(cs=(0.5,), epss=(0.005,), runs=1), run=fake_run)
    text = json.dumps(one.to_json(), allow_nan=False)
    record = json.loads(text)
    assert record["cells"][0]["reward_ci_low"] is None  # one run: no interval
    assert record["cells"][0]["paper_reward"] == 88.9


# --------------------------------------------------------------------------- command


def test_command_writes_table_and_json(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sw, "default_run_function", lambda: fake_run)
    out = tmp_path / "sweep"
    args = ["sweep", "--runs", "2", "--seed", "4", "--backend", "serial", "--out", str(out)]
    assert hopnav([*args, "--cs", "0.25,0.5", "--epss", "0.005", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["scenario"] == "a" and record["runs"] == 2 and record["seed"] == 4
    assert [(c["c"], c["eps"]) for c in record["cells"]] == [(0.25, 0.005), (0.5, 0.005)]
    assert len(record["rows"]) == 4
    assert record["files"]["rows"] == str(out / sf.ROWS_FILE)
    assert len(read_rows_csv(out / sf.ROWS_FILE)) == 4

    # another sweep into the folder of this one is refused (nothing touched) unless --force
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert hopnav(args) == 2
    err = capsys.readouterr().err
    assert "holds the results of a sweep" in err and len(err.strip().splitlines()) == 1
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert hopnav([*args, "--force"]) == 0
    text = capsys.readouterr().out
    assert "P_RL,ee = C" in text and "[paper 139.75/83]" in text
    assert len(read_rows_csv(out / sf.ROWS_FILE)) == 18


def test_command_errors(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sw, "default_run_function", lambda: fake_run)
    assert hopnav(["sweep", "--scenario", str(tmp_path / "none.toml")]) == 2
    assert "no scenario" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:  # argparse rejects it, one line
        hopnav(["sweep", "--runs", "0", "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    assert "--runs: must be a whole number >= 1" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "ray", None)
    assert hopnav(["sweep", "--backend", "ray", "--out", str(tmp_path)]) == 2
    assert "hopnav[ray]" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


# --------------------------------------------------------------------------- resume


def counting(calls: list, fail_at: int | None = None):
    """A serial-only run function that records its calls and fails at call ``fail_at``."""

    def run(scenario, seed, run_index):
        if fail_at is not None and len(calls) + 1 == fail_at:
            raise RuntimeError("interrupted")
        calls.append(seed)
        return fake_run(scenario, seed, run_index)

    return run


def test_previous_rows_are_reused(serial, scenario):
    calls: list = []
    done: list = []
    half = serial.rows[::2]
    result = run_sweep(
        scenario,
        SMALL,
        run=counting(calls),
        previous=half,
        progress=lambda d, t, row: done.append((d, t)),
    )
    assert result.rows == serial.rows
    assert sorted(calls) == sorted(r.seed for r in serial.rows[1::2])
    assert done[-1] == (len(serial.rows) - len(half),) * 2
    stale = [SweepRow(**{**r.__dict__, "seed": r.seed + 1}) for r in serial.rows]
    calls.clear()
    assert run_sweep(scenario, SMALL, run=counting(calls), previous=stale).rows == serial.rows
    assert len(calls) == SMALL.n_runs  # other seeds: nothing reused


def test_command_resumes_an_interrupted_sweep(tmp_path, monkeypatch, capsys):
    out = tmp_path / "sweep"
    args = ["sweep", "--runs", "2", "--cs", "0.25,0.75", "--epss", "0.005", "--json"]
    args += ["--backend", "serial", "--out", str(out)]
    calls: list = []
    monkeypatch.setattr(sw, "default_run_function", lambda: counting(calls, fail_at=3))
    assert hopnav(args) == 1
    err = capsys.readouterr().err
    assert "RuntimeError: interrupted" in err and "the 2 finished runs are in" in err
    assert len(read_rows_csv(out / sf.ROWS_FILE)) == 2  # the finished runs were kept
    assert not (out / sf.SUMMARY_FILE).exists()

    calls.clear()
    monkeypatch.setattr(sw, "default_run_function", lambda: counting(calls))
    assert hopnav([*args, "--resume"]) == 0
    resumed = json.loads(capsys.readouterr().out)
    assert len(calls) == 2
    assert hopnav([*args, "--force"]) == 0  # from scratch
    fresh = json.loads(capsys.readouterr().out)
    assert resumed["rows"] == fresh["rows"] and resumed["cells"] == fresh["cells"]

    # the digest is of the scenario, not of its file's bytes: a comment changes nothing ...
    same = tmp_path / "same.toml"
    same.write_text(resolve_scenario_path("a").read_text() + "\n# edited\n")
    calls.clear()
    assert hopnav([*args, "--resume", "--scenario", str(same)]) == 0
    assert calls == [] and json.loads(capsys.readouterr().out)["rows"] == fresh["rows"]
    # ... a changed value refuses the resume, naming both scenarios
    other = tmp_path / "other.toml"
    text = resolve_scenario_path("a").read_text()
    assert "p_sat = 0.65" in text
    other.write_text(text.replace("p_sat = 0.65", "p_sat = 0.7"))
    assert hopnav([*args, "--resume", "--scenario", str(other)]) == 2
    err = capsys.readouterr().err
    assert "cannot resume" in err and "belongs to scenario 'a'" in err
    assert len(err.strip().splitlines()) == 1


def test_resume_refuses_another_grid_seed_runs_or_scenario(tmp_path, monkeypatch, capsys):
    """A resume that would rewrite the rows of another sweep is refused with one line and
    touches nothing; the same sweep resumes (nothing to run)."""
    monkeypatch.setattr(sw, "default_run_function", lambda: fake_run)
    out = tmp_path / "sweep"
    base = ["sweep", "--backend", "serial", "--out", str(out), "--json"]
    grid = ["--cs", "0.25,0.75", "--epss", "0.005", "--runs", "2", "--seed", "3"]
    assert hopnav([*base, *grid]) == 0
    capsys.readouterr()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    other = resolve_scenario_path("b")
    for change in (
        ["--cs", "0.25", "--epss", "0.005", "--runs", "2", "--seed", "3"],  # grid
        ["--cs", "0.25,0.75", "--epss", "0.005,0.0075", "--runs", "2", "--seed", "3"],
        ["--cs", "0.25,0.75", "--epss", "0.005", "--runs", "2", "--seed", "4"],  # seed
        ["--cs", "0.25,0.75", "--epss", "0.005", "--runs", "3", "--seed", "3"],  # runs
        [*grid, "--scenario", str(other)],  # scenario
    ):
        assert hopnav([*base, *change, "--resume"]) == 2, change
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "cannot resume" in err, err
        assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert hopnav([*base, *grid, "--resume"]) == 0
    assert len(json.loads(capsys.readouterr().out)["rows"]) == 4


def test_default_run_function_needs_the_runner(monkeypatch):
    monkeypatch.setitem(sys.modules, "hopper_sim.navigation.runner", None)  # as if not installed
    with pytest.raises(SweepBackendError, match=r"hopper_sim\.navigation\.runner is not available"):
        sw.default_run_function()


def test_reason_is_kept_and_optional_in_files(serial, tmp_path):
    from types import SimpleNamespace

    task = SMALL.tasks()[0]
    end = SimpleNamespace(
        **fake_run(
            load_scenario("a").with_runner(p_rl_ee=task.c, c=task.c, eps=task.eps, seed=task.seed),
            task.seed,
            0,
        ).__dict__
    )
    end.reason = "hop failed: no_touchdown, at x = 3"
    row = SweepRow.from_run_end(task, end)
    assert row.reason == "hop failed: no_touchdown, at x = 3"
    rows = [row, *serial.rows[1:]]
    path = sf.atomic_write_text(tmp_path / "r.csv", sf.rows_csv(rows))
    assert read_rows_csv(path) == rows  # a comma inside the reason survives
    # a file without the reason column (older version) reads with empty reasons
    records = list(csv.reader(io.StringIO(sf.rows_csv(serial.rows))))
    assert records[0][-1] == "reason"
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rec[:-1] for rec in records)
    old = sf.atomic_write_text(tmp_path / "old.csv", buf.getvalue())
    expected = [dataclasses.replace(r, reason="") for r in serial.rows]
    assert read_rows_csv(old) == expected

    result = dataclasses.replace(serial, rows=tuple(rows))
    ended = sf.format_table(result).splitlines()[-1]
    assert ended.startswith("runs ended by: ") and "1 x hop failed: no_touchdown, at x = 3" in ended


# --------------------------------------------------------------------------- ray's API, faked


class FakeRef:
    def __init__(self, value):
        self.value = value


class FakeRay:
    """The part of Ray's API the ray backend calls (init, put, remote, wait, get, shutdown);
    tasks run eagerly and ``wait`` hands them back newest first, to mimic completion out of
    submission order. It checks the backend's control flow, not Ray itself (see the test
    above, which runs on a real local instance when ray is installed)."""

    def __init__(self, initialized: bool = False):
        self.initialized = initialized
        self.init_kwargs = None
        self.shutdowns = 0
        self.remote_options = None

    def is_initialized(self):
        return self.initialized

    def init(self, **kwargs):
        self.initialized, self.init_kwargs = True, kwargs

    def shutdown(self):
        self.initialized = False
        self.shutdowns += 1

    def put(self, value):
        return FakeRef(value)

    def remote(self, **options):
        self.remote_options = options

        def decorate(fn):
            def call(*args):
                return FakeRef(fn(*(a.value if isinstance(a, FakeRef) else a for a in args)))

            return type("Remote", (), {"remote": staticmethod(call)})

        return decorate

    def wait(self, refs, num_returns=1):
        return refs[-num_returns:], refs[:-num_returns]

    def get(self, ref):
        return ref.value


def test_ray_backend_control_flow(serial, scenario, monkeypatch):
    fake = FakeRay()
    monkeypatch.setitem(sys.modules, "ray", fake)
    done = []
    result = run_sweep(
        scenario, SMALL, run=fake_run, backend="ray", workers=3, progress=lambda *a: done.append(a)
    )
    assert result.rows == serial.rows and result.backend == "ray"
    assert [d for d, _, _ in done] == list(range(1, SMALL.n_runs + 1))
    assert [row.run for *_, row in done][:2] == [2, 1]  # finished out of order, table in order
    assert fake.init_kwargs["num_cpus"] == 3 and fake.remote_options == {"num_cpus": 1}
    root = str(Path(sw.__file__).resolve().parents[2])
    assert fake.init_kwargs["runtime_env"]["env_vars"]["PYTHONPATH"].split(os.pathsep)[0] == root
    assert fake.shutdowns == 1 and not fake.initialized

    cluster = FakeRay()
    monkeypatch.setitem(sys.modules, "ray", cluster)
    run_sweep(scenario, SMALL, run=fake_run, backend="ray", ray_address="ray://head:10001")
    assert cluster.init_kwargs["address"] == "ray://head:10001" and cluster.shutdowns == 1

    running = FakeRay(initialized=True)  # the caller's instance: used, left running
    monkeypatch.setitem(sys.modules, "ray", running)
    assert run_sweep(scenario, SMALL, run=fake_run, backend="ray").rows == serial.rows
    assert running.init_kwargs is None and running.shutdowns == 0


def torch_threads_run(scenario, seed: int, run_index: int) -> RunEnd:
    """Reports, as its step count, how many threads torch had during the run."""
    import torch

    return RunEnd(run_index, "success", torch.get_num_threads(), 0.0, None, None, 0, 0.0)


def test_runs_use_one_torch_thread_on_every_backend(scenario):
    import torch

    spec = SweepSpec(cs=(0.5,), epss=(0.005,), runs=1)
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        serial_rows = run_sweep(scenario, spec, run=torch_threads_run).rows
        assert torch.get_num_threads() == 2  # restored
        process_rows = run_sweep(
            scenario, spec, run=torch_threads_run, backend="process", workers=1
        ).rows
    finally:
        torch.set_num_threads(before)
    assert [r.steps for r in serial_rows] == [r.steps for r in process_rows] == [1]
