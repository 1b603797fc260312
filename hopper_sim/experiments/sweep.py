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
:func:`hopper_sim.navigation.runner.run_single`, imported when the sweep starts.

The grid, its seeds and rows are in :mod:`hopper_sim.experiments.sweep_grid`, the statistics in
:mod:`hopper_sim.experiments.sweep_stats`, the backends in
:mod:`hopper_sim.experiments.sweep_backends`; their public
names are importable from here. This module neither prints nor writes files;
:mod:`hopper_sim.experiments.sweep_files` writes the CSV and Markdown outputs.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING

from hopper_sim.experiments.sweep_backends import (
    _import_ray,
    _iter_process,
    _iter_ray,
    _iter_serial,
    available_cores,
    default_run_function,
)
from hopper_sim.experiments.sweep_grid import (
    BACKENDS,
    MAX_RUNS,
    PAPER_CS,
    PAPER_EPSS,
    PAPER_TABLE_I,
    ROW_COLUMNS,
    Backend,
    ProgressCallback,
    RunFunction,
    SweepBackendError,
    SweepError,
    SweepRow,
    SweepRunError,
    SweepSpec,
    SweepTask,
)
from hopper_sim.experiments.sweep_stats import (
    CellSummary,
    MeanCI,
    SweepResult,
    mean_ci,
    paper_value,
    summarize,
    summary_record,
)

if TYPE_CHECKING:
    from planner.scenario import Scenario

__all__ = [
    "BACKENDS",
    "MAX_RUNS",
    "PAPER_CS",
    "PAPER_EPSS",
    "PAPER_TABLE_I",
    "ROW_COLUMNS",
    "Backend",
    "CellSummary",
    "MeanCI",
    "ProgressCallback",
    "RunFunction",
    "SweepBackendError",
    "SweepError",
    "SweepResult",
    "SweepRow",
    "SweepRunError",
    "SweepSpec",
    "SweepTask",
    "available_cores",
    "default_run_function",
    "mean_ci",
    "paper_value",
    "run_sweep",
    "summarize",
    "summary_record",
]


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
    results, todo = _reuse(spec.tasks(), previous)
    if run is None and todo:
        run = default_run_function()
    stream = _stream(backend, run, scenario, todo, workers, ray_address)
    t0 = time.perf_counter()
    try:
        for done, (task, row) in enumerate(stream, start=1):
            results[task.index] = row
            if progress is not None:
                progress(done, len(todo), row)
    finally:
        # A Ctrl-C or error in ``progress`` leaves the backend suspended at its ``yield``,
        # its workers running; closing it ends them now. Left to the garbage collector, a
        # process pool would instead run every pending task at interpreter exit.
        close = getattr(stream, "close", None)
        if close is not None:
            close()
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


def _reuse(
    tasks: list[SweepTask], previous: Iterable[SweepRow]
) -> tuple[list[SweepRow | None], list[SweepTask]]:
    """``(rows by task index, None where still to run; the tasks still to run)``: a task
    whose cell, run number and seed match a row of ``previous`` reuses that row."""
    results: list[SweepRow | None] = [None] * len(tasks)
    known = {(r.c, r.eps, r.run, r.seed): r for r in previous}
    for t in tasks:
        results[t.index] = known.get((t.c, t.eps, t.run, t.seed))
    return results, [t for t in tasks if results[t.index] is None]


def _stream(
    backend: Backend,
    run: RunFunction | None,
    scenario: Scenario,
    todo: list[SweepTask],
    workers: int,
    ray_address: str | None,
) -> Iterator[tuple[SweepTask, SweepRow]]:
    """The ``(task, row)`` pairs of ``todo`` in completion order, from ``backend``."""
    if backend == "serial":
        return _iter_serial(run, scenario, todo)
    if not todo:
        return iter(())
    if backend == "process":
        return _iter_process(run, scenario, todo, min(workers, len(todo)))
    return _iter_ray(run, scenario, todo, workers, ray_address)
