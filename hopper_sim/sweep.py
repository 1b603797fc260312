"""Parameter sweeps over the switching parameters (the paper's Table I).

A sweep runs ``runs`` complete navigation runs for every cell of the grid
``P_RL,ee = C in cs`` x ``eps in epss`` on one scenario and summarises each cell by the mean
reward and the mean number of hops (steps), each with a two-sided Student-t confidence
interval, and by the success rate:

    mean = (1/n) sum_i y_i,    s^2 = (1/(n-1)) sum_i (y_i - mean)^2,
    CI = mean +- t_{(1+level)/2, n-1} * s / sqrt(n).

Means are over all runs of a cell, whatever their outcome (a timeout counts with its capped
step number, a violation with the hops it made), as the paper averages over complete runs;
the success rate says how many of them reached the goal.

Seeds: run ``r`` of the cell at position ``k`` (C-major: ``k = i_c * len(epss) + i_eps``) gets
the seed ``SeedSequence(seed).spawn(n_cells * runs)[k * runs + r]`` (its first 32-bit word),
so the table depends only on the grid, ``runs`` and ``seed``: not on the backend or the
number of workers, nor on the order in which runs finish.

Backends: ``serial`` (in this process), ``process`` (a pool of worker processes started with
``spawn``, one thread each) and ``ray`` (the optional extra ``ray``; a local instance is
started when no address is given). The run function is a parameter (picklable, module level,
``run(scenario, seed, run_index) -> RunEnd``); by default
:func:`hopper_sim.runner.run_single`, imported when the sweep starts.

This module neither prints nor writes files; :mod:`hopper_sim.sweep_files` writes the CSV and
Markdown outputs.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from hopper_sim.events import OUTCOMES, RunEnd

if TYPE_CHECKING:
    from planner.scenario import Scenario

Backend = Literal["serial", "process", "ray"]
BACKENDS: tuple[str, ...] = ("serial", "process", "ray")

RunFunction = Callable[["Scenario", int, int], RunEnd]
"""``run(scenario, seed, run_index) -> RunEnd``: one complete navigation run."""

ProgressCallback = Callable[[int, int, "SweepRow"], None]
"""``progress(done, total, row)``: called once per finished run, in completion order."""

PAPER_CS: tuple[float, ...] = (0.25, 0.50, 0.75)
"""The paper's values of ``P_RL,ee = C`` (rows of Table I)."""

PAPER_EPSS: tuple[float, ...] = (0.0025, 0.0050, 0.0075)
"""The paper's values of ``eps`` (columns of Table I)."""

PAPER_TABLE_I: dict[tuple[float, float], tuple[float, float]] = {
    (0.25, 0.0025): (61.2, 98.0),
    (0.25, 0.0050): (64.4, 80.6),
    (0.25, 0.0075): (54.6, 65.1),
    (0.50, 0.0025): (112.9, 87.2),
    (0.50, 0.0050): (88.9, 72.8),
    (0.50, 0.0075): (84.7, 71.2),
    (0.75, 0.0025): (136.4, 84.7),
    (0.75, 0.0050): (139.75, 83.0),
    (0.75, 0.0075): (129.6, 85.3),
}
"""The paper's Table I: ``(C, eps) -> (mean reward, mean steps)`` over ten runs of case (a)."""


#: Most runs of one sweep (the seeds of all of them are drawn up front).
MAX_RUNS = 100_000


class SweepError(ValueError):
    """A sweep was set up with bad parameters."""


class SweepBackendError(RuntimeError):
    """A backend cannot run (unknown name, or its optional package is missing)."""


class SweepRunError(RuntimeError):
    """One run of the sweep failed; the message names its cell, run number and seed."""


# --------------------------------------------------------------------------- the grid


def _as_levels(name: str, values: Iterable[float]) -> tuple[float, ...]:
    levels = tuple(float(v) for v in values)
    if not levels:
        raise SweepError(f"{name} must hold at least one value")
    if len(set(levels)) != len(levels):
        raise SweepError(f"{name} has repeated values: {levels}")
    return levels


@dataclass(frozen=True)
class SweepSpec:
    """The grid of a sweep and how many runs each cell gets.

    Attributes:
        cs: values of ``P_RL,ee = C`` (probabilities in [0, 1]).
        epss: values of the decay rate ``eps`` (>= 0, per goal-reaching step).
        runs: runs per cell (>= 1; confidence intervals need >= 2).
        seed: base seed (>= 0) from which every run's seed is derived.

    Raises:
        SweepError: empty or repeated levels, a level out of range, ``runs < 1``, ``seed < 0``.
    """

    cs: tuple[float, ...] = PAPER_CS
    epss: tuple[float, ...] = PAPER_EPSS
    runs: int = 10
    seed: int = 0

    def __post_init__(self) -> None:
        cs = _as_levels("cs", self.cs)
        epss = _as_levels("epss", self.epss)
        bad_c = [c for c in cs if not 0.0 <= c <= 1.0]
        if bad_c:
            raise SweepError(f"cs must lie in [0, 1], got {bad_c}")
        bad_eps = [e for e in epss if not (math.isfinite(e) and e >= 0.0)]
        if bad_eps:
            raise SweepError(f"epss must be finite and >= 0, got {bad_eps}")
        if int(self.runs) != self.runs or self.runs < 1:
            raise SweepError(f"runs must be a whole number >= 1, got {self.runs}")
        if int(self.seed) != self.seed or self.seed < 0:
            raise SweepError(f"seed must be a whole number >= 0, got {self.seed}")
        n_runs = len(cs) * len(epss) * int(self.runs)
        if n_runs > MAX_RUNS:
            raise SweepError(
                f"{len(cs)} x {len(epss)} cells x {int(self.runs)} runs = {n_runs} runs, more "
                f"than the limit of {MAX_RUNS}"
            )
        object.__setattr__(self, "cs", cs)
        object.__setattr__(self, "epss", epss)
        object.__setattr__(self, "runs", int(self.runs))
        object.__setattr__(self, "seed", int(self.seed))

    @property
    def cells(self) -> list[tuple[float, float]]:
        """The ``(C, eps)`` cells, C-major."""
        return [(c, e) for c in self.cs for e in self.epss]

    @property
    def n_runs(self) -> int:
        """Total number of runs."""
        return len(self.cs) * len(self.epss) * self.runs

    def tasks(self) -> list[SweepTask]:
        """Every run of the sweep with its derived seed, in table order (C, eps, run)."""
        children = np.random.SeedSequence(self.seed).spawn(self.n_runs)
        seeds = [int(ch.generate_state(1, dtype=np.uint32)[0]) for ch in children]
        return [
            SweepTask(index=k * self.runs + r, c=c, eps=e, run=r, seed=seeds[k * self.runs + r])
            for k, (c, e) in enumerate(self.cells)
            for r in range(self.runs)
        ]


@dataclass(frozen=True)
class SweepTask:
    """One run of a sweep: its position, its cell ``(C, eps)``, its run number and seed."""

    index: int
    c: float
    eps: float
    run: int
    seed: int


@dataclass(frozen=True)
class SweepRow:
    """The result of one run (one line of the raw CSV).

    ``p_rl_ee`` equals ``c`` in a Table I sweep; ``switch_step`` and ``p_switch`` are ``None``
    when goal reaching never began; ``seconds`` is the run's wall-clock time; ``reason`` says
    in words what ended the run (the runner's ``RunEnd.reason``, empty if it gives none);
    ``p_trace`` the worst-case satisfaction probability at the run's current state after each
    synthesis, ``step:P`` pairs separated by spaces (empty if the run function gives none).
    """

    c: float
    eps: float
    p_rl_ee: float
    run: int
    seed: int
    outcome: str
    steps: int
    reward: float
    switch_step: int | None
    p_switch: float | None
    backups: int
    seconds: float
    p_trace: str = ""
    reason: str = ""

    @classmethod
    def from_run_end(cls, task: SweepTask, end: RunEnd) -> SweepRow:
        """The row of ``task`` given the run's end event."""
        return cls(
            c=task.c,
            eps=task.eps,
            p_rl_ee=task.c,
            run=task.run,
            seed=task.seed,
            outcome=end.outcome,
            steps=int(end.steps),
            reward=float(end.reward),
            switch_step=None if end.switch_step is None else int(end.switch_step),
            p_switch=None if end.p_switch is None else float(end.p_switch),
            backups=int(end.backups),
            seconds=float(end.seconds),
            p_trace=" ".join(
                f"{r.step}:{r.p_worst_current:.4f}" for r in getattr(end, "resyntheses", ())
            ),
            reason=str(getattr(end, "reason", "")),  # RunEnd.reason: what ended the run
        )


ROW_COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(SweepRow))
"""Columns of the raw-rows CSV (``reason`` and ``p_trace`` may be absent from files of older
versions)."""


# --------------------------------------------------------------------------- statistics


@dataclass(frozen=True)
class MeanCI:
    """A sample mean with a two-sided Student-t confidence interval.

    Attributes:
        mean: the sample mean (nan for an empty sample).
        half_width: ``t_{(1+level)/2, n-1} * s / sqrt(n)`` (nan when ``n < 2``).
        n: sample size.
        level: confidence level, e.g. 0.95.
    """

    mean: float
    half_width: float
    n: int
    level: float = 0.95

    @property
    def low(self) -> float:
        """Lower end of the interval."""
        return self.mean - self.half_width

    @property
    def high(self) -> float:
        """Upper end of the interval."""
        return self.mean + self.half_width


def mean_ci(values: Sequence[float] | np.ndarray, level: float = 0.95) -> MeanCI:
    """Mean of ``values`` and the Student-t confidence interval at ``level``.

    A sample of one has an undefined interval (``half_width`` nan); an empty sample has a nan
    mean as well.

    Raises:
        SweepError: ``level`` outside (0, 1) or a non-finite value.
    """
    from scipy import stats

    if not 0.0 < level < 1.0:
        raise SweepError(f"confidence level must be in (0, 1), got {level}")
    y = np.asarray(values, dtype=float).ravel()
    if not np.isfinite(y).all():
        raise SweepError(f"values must be finite, got {y[~np.isfinite(y)][:3].tolist()}")
    n = y.size
    if n == 0:
        return MeanCI(math.nan, math.nan, 0, level)
    mean = float(y.mean())
    if n < 2:
        return MeanCI(mean, math.nan, 1, level)
    sem = float(y.std(ddof=1)) / math.sqrt(n)
    return MeanCI(mean, float(stats.t.ppf(0.5 + level / 2.0, n - 1)) * sem, n, level)


@dataclass(frozen=True)
class CellSummary:
    """Summary of one ``(C, eps)`` cell.

    Attributes:
        c, eps: the cell.
        reward: mean total reward with its confidence interval.
        steps: mean number of hops with its confidence interval.
        successes: runs that reached the goal.
        outcomes: number of runs per outcome (``success``, ``violation``, ``timeout``).
        paper: the paper's ``(reward, steps)`` for this cell, or ``None`` if it has none.
    """

    c: float
    eps: float
    reward: MeanCI
    steps: MeanCI
    successes: int
    outcomes: dict[str, int]
    paper: tuple[float, float] | None

    @property
    def n(self) -> int:
        """Runs in this cell."""
        return self.reward.n

    @property
    def success_rate(self) -> float:
        """Fraction of runs that reached the goal (nan for an empty cell)."""
        return self.successes / self.n if self.n else math.nan


def paper_value(c: float, eps: float) -> tuple[float, float] | None:
    """The paper's Table I ``(reward, steps)`` at ``(c, eps)``, or ``None`` off its grid."""
    for (pc, pe), value in PAPER_TABLE_I.items():
        if math.isclose(pc, c, abs_tol=1e-12) and math.isclose(pe, eps, abs_tol=1e-12):
            return value
    return None


def summarize(
    rows: Sequence[SweepRow], spec: SweepSpec | None = None, level: float = 0.95
) -> list[CellSummary]:
    """Per-cell summaries of ``rows``, C-major.

    With ``spec`` the cells are those of its grid (an empty cell gets nan means); without it,
    the cells present in ``rows``, sorted.
    """
    if spec is not None:
        cells = spec.cells
    else:
        cells = sorted({(r.c, r.eps) for r in rows})
    by_cell: dict[tuple[float, float], list[SweepRow]] = {cell: [] for cell in cells}
    for r in rows:
        by_cell.setdefault((r.c, r.eps), []).append(r)
    out = []
    for c, e in cells:
        group = by_cell[(c, e)]
        counts = {o: sum(r.outcome == o for r in group) for o in OUTCOMES}
        out.append(
            CellSummary(
                c=c,
                eps=e,
                reward=mean_ci([r.reward for r in group], level),
                steps=mean_ci([r.steps for r in group], level),
                successes=counts["success"],
                outcomes=counts,
                paper=paper_value(c, e),
            )
        )
    return out


@dataclass(frozen=True)
class SweepResult:
    """A finished sweep: the scenario's name, the grid, the raw rows and the summaries.

    ``rows`` are in table order (C, eps, run), whatever order the runs finished in.
    """

    scenario: str
    spec: SweepSpec
    rows: tuple[SweepRow, ...]
    cells: tuple[CellSummary, ...]
    backend: str
    workers: int
    seconds: float

    def cell(self, c: float, eps: float) -> CellSummary:
        """The summary of cell ``(c, eps)``.

        Raises:
            KeyError: no such cell.
        """
        for s in self.cells:
            if math.isclose(s.c, c) and math.isclose(s.eps, eps):
                return s
        raise KeyError(f"no cell C={c}, eps={eps} in this sweep")

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict: settings, per-cell summaries (with the paper's values), rows."""
        return _json_safe(
            {
                "scenario": self.scenario,
                "cs": list(self.spec.cs),
                "epss": list(self.spec.epss),
                "runs": self.spec.runs,
                "seed": self.spec.seed,
                "backend": self.backend,
                "workers": self.workers,
                "seconds": self.seconds,
                "cells": [summary_record(s) for s in self.cells],
                "rows": [asdict(r) for r in self.rows],
            }
        )


def _json_safe(value: Any) -> Any:
    """``value`` with every nan float replaced by ``None`` (JSON has no nan)."""
    if isinstance(value, float) and math.isnan(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    return value


def summary_record(s: CellSummary) -> dict[str, Any]:
    """One cell as a flat dict (the columns of the summary CSV; nan where undefined)."""
    paper = s.paper or (None, None)
    return {
        "c": s.c,
        "eps": s.eps,
        "n": s.n,
        "reward_mean": s.reward.mean,
        "reward_ci_low": s.reward.low,
        "reward_ci_high": s.reward.high,
        "steps_mean": s.steps.mean,
        "steps_ci_low": s.steps.low,
        "steps_ci_high": s.steps.high,
        "success_rate": s.success_rate,
        **{f"n_{o}": s.outcomes[o] for o in OUTCOMES},
        "paper_reward": paper[0],
        "paper_steps": paper[1],
    }


# --------------------------------------------------------------------------- running


def available_cores() -> int:
    """CPU cores this process may use (its affinity set where the OS reports one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def default_run_function() -> RunFunction:
    """The real navigation run, :func:`hopper_sim.runner.run_single` (imported now).

    Raises:
        SweepBackendError: this installation has no :mod:`hopper_sim.runner`.
    """
    try:
        from hopper_sim.runner import run_single
    except ModuleNotFoundError as err:
        if err.name != "hopper_sim.runner":
            raise
        raise SweepBackendError(
            "the navigation runner hopper_sim.runner is not available in this installation"
        ) from err

    return run_single


def _run_task(run: RunFunction, scenario: Scenario, task: SweepTask) -> SweepRow:
    where = f"run {task.run} of cell C={task.c:g}, eps={task.eps:g} (seed {task.seed})"
    sc = scenario.with_runner(p_rl_ee=task.c, c=task.c, eps=task.eps, seed=task.seed, runs=1)
    try:
        end = run(sc, task.seed, task.run)
    except Exception as err:
        raise SweepRunError(f"{where} failed: {type(err).__name__}: {err}") from err
    if not isinstance(end, RunEnd):
        raise SweepRunError(
            f"{where}: the run function must return a RunEnd, got {type(end).__name__}"
        )
    return SweepRow.from_run_end(task, end)


_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def die_with_parent(parent: int) -> None:
    """Make this process end when its parent (pid ``parent``) ends, also by SIGKILL: the
    kernel sends it SIGKILL then (Linux ``PR_SET_PDEATHSIG``; elsewhere a no-op). Exits at
    once if the parent has already gone."""
    import sys

    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig, sigkill = 1, 9
        libc.prctl(pr_set_pdeathsig, sigkill, 0, 0, 0)
    if os.getppid() != parent:  # the parent died before the line above took effect
        os._exit(1)


def _init_worker(parent: int | None = None) -> None:
    # Workers share the cores: one compute thread each (torch reads these when imported).
    for var in _THREAD_VARS:
        os.environ[var] = "1"
    import signal
    import sys

    if parent is not None:
        die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    signal.signal(signal.SIGTERM, signal.SIG_DFL)

    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


def _iter_serial(
    run: RunFunction, scenario: Scenario, tasks: Sequence[SweepTask]
) -> Iterator[tuple[SweepTask, SweepRow]]:
    import sys

    for task in tasks:
        # One torch thread during each run, as in the workers, so that float reductions and
        # hence the runs do not depend on the backend; the caller's setting is restored.
        torch = sys.modules.get("torch")
        before = torch.get_num_threads() if torch is not None else None
        if torch is not None:
            torch.set_num_threads(1)
        try:
            row = _run_task(run, scenario, task)
        finally:
            if torch is not None:
                torch.set_num_threads(before)
        yield task, row


def _iter_process(
    run: RunFunction, scenario: Scenario, tasks: Sequence[SweepTask], workers: int
) -> Iterator[tuple[SweepTask, SweepRow]]:
    import multiprocessing
    import signal
    import threading

    ctx = multiprocessing.get_context("spawn")
    pool: ProcessPoolExecutor | None = None
    pending: dict = {}
    # The workers (and multiprocessing's resource tracker) are started with SIGINT ignored,
    # which they keep from their first instruction: a Ctrl-C reaches the whole process
    # group, and is the parent's alone to handle (no worker prints a traceback).
    main = threading.current_thread() is threading.main_thread()
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
        try:
            pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=ctx,
                initializer=_init_worker,
                initargs=(os.getpid(),),
            )
            pending = {pool.submit(_run_task, run, scenario, t): t for t in tasks}
        finally:
            if main:
                signal.signal(signal.SIGINT, previous)
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                task = pending.pop(fut)
                yield task, fut.result()
    except BaseException:
        # interrupted (Ctrl-C, SIGTERM), a run failed or the consumer stopped: end the runs
        # in progress now instead of waiting for them (a SIGKILL of this process ends the
        # workers through die_with_parent)
        for fut in pending:
            fut.cancel()
        for proc in list((getattr(pool, "_processes", None) or {}).values()):
            proc.terminate()
        raise
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)


def _import_ray() -> Any:
    try:
        import ray
    except ImportError as err:
        raise SweepBackendError(
            "the 'ray' backend needs the optional extra: pip install 'hopnav[ray]' "
            "(or use --backend process)"
        ) from err
    return ray


def _iter_ray(
    run: RunFunction,
    scenario: Scenario,
    tasks: Sequence[SweepTask],
    workers: int,
    address: str | None,
) -> Iterator[tuple[SweepTask, SweepRow]]:
    ray = _import_ray()
    started = False
    if not ray.is_initialized():
        if address is None:
            # Local workers import this project from its source tree even when it is not
            # installed; remote clusters need it installed (pip install 'hopnav[ray]').
            root = str(Path(__file__).resolve().parents[1])
            path = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)
            ray.init(
                num_cpus=workers,
                include_dashboard=False,
                log_to_driver=False,
                runtime_env={"env_vars": {"PYTHONPATH": path, **dict.fromkeys(_THREAD_VARS, "1")}},
            )
        else:
            ray.init(address=address, log_to_driver=False)
        started = True
    try:
        remote = ray.remote(num_cpus=1)(_run_task)
        run_ref = ray.put(run)
        scenario_ref = ray.put(scenario)
        pending = {remote.remote(run_ref, scenario_ref, t): t for t in tasks}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                task = pending.pop(ref)
                yield task, ray.get(ref)
    finally:
        if started:
            ray.shutdown()


def run_sweep(
    scenario: Scenario,
    spec: SweepSpec | None = None,
    *,
    run: RunFunction | None = None,
    backend: Backend = "serial",
    workers: int | None = None,
    ray_address: str | None = None,
    progress: ProgressCallback | None = None,
    previous: Iterable[SweepRow] = (),
    level: float = 0.95,
) -> SweepResult:
    """Run every ``(C, eps, run)`` of ``spec`` on ``scenario`` and summarise the results.

    Each run uses ``scenario`` with ``p_rl_ee = c = C``, ``eps`` and its derived seed set in
    the runner settings, and calls ``run(scenario, seed, run_index)`` with ``run_index`` its
    number within the cell.

    Args:
        scenario: the scenario (its other runner settings are kept).
        spec: the grid, runs per cell and base seed (default: the paper's Table I, 10 runs).
        run: the run function (default :func:`default_run_function`); for the ``process``
            and ``ray`` backends it must be picklable (a module-level function).
        backend: ``"serial"``, ``"process"`` or ``"ray"``.
        workers: parallel workers for ``process``/``ray`` (default: the machine's cores).
        ray_address: address of a running Ray cluster; ``None`` starts a local instance.
        progress: called as ``progress(done, total, row)`` after each run finished in this
            call (``total``: the runs this call makes, reused ones not counted).
        previous: rows of an earlier, interrupted sweep: a task whose cell, run number and
            seed match one of them is not run again and its row is reused (resume).
        level: confidence level of the intervals.

    Raises:
        SweepBackendError: unknown backend, or ``ray`` requested but not installed.
        SweepError: ``workers < 1``.
        SweepRunError: a run raised or returned something else than a ``RunEnd`` (the
            runs finished before it were passed to ``progress``).
    """
    import time

    spec = SweepSpec() if spec is None else spec
    if backend not in BACKENDS:
        raise SweepBackendError(f"unknown backend {backend!r}; choose one of {BACKENDS}")
    if backend == "ray":
        _import_ray()  # fail before any work when ray is missing
    if workers is None:
        workers = available_cores()
    if int(workers) != workers or workers < 1:
        raise SweepError(f"workers must be a whole number >= 1, got {workers}")
    workers = 1 if backend == "serial" else int(workers)
    tasks = spec.tasks()
    results: list[SweepRow | None] = [None] * len(tasks)
    known = {(r.c, r.eps, r.run, r.seed): r for r in previous}
    for t in tasks:
        results[t.index] = known.get((t.c, t.eps, t.run, t.seed))
    todo = [t for t in tasks if results[t.index] is None]
    if run is None and todo:
        run = default_run_function()
    if backend == "serial":
        stream = _iter_serial(run, scenario, todo)
    elif not todo:
        stream = iter(())
    elif backend == "process":
        stream = _iter_process(run, scenario, todo, min(workers, len(todo)))
    else:
        stream = _iter_ray(run, scenario, todo, workers, ray_address)
    t0 = time.perf_counter()
    for done, (task, row) in enumerate(stream, start=1):
        results[task.index] = row
        if progress is not None:
            progress(done, len(todo), row)
    rows = tuple(r for r in results if r is not None)
    return SweepResult(
        scenario=scenario.name,
        spec=spec,
        rows=rows,
        cells=tuple(summarize(rows, spec, level)),
        backend=backend,
        workers=workers,
        seconds=time.perf_counter() - t0,
    )
