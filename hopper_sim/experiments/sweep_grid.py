"""The grid of a sweep (the paper's Table I): its cells, its runs with their derived seeds,
and the row each finished run gives.

Seeds: run ``r`` of the cell at position ``k`` (C-major: ``k = i_c * len(epss) + i_eps``) gets
the seed ``SeedSequence(seed).spawn(n_cells * runs)[k * runs + r]`` (its first 32-bit word),
so the table depends only on the grid, ``runs`` and ``seed``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Literal

import numpy as np

from hopper_sim.errors import HopperSimError
from hopper_sim.navigation.events import RunEnd

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


class SweepError(HopperSimError, ValueError):
    """A sweep was set up with bad parameters."""


class SweepBackendError(HopperSimError, RuntimeError):
    """A backend cannot run (unknown name, or its optional package is missing)."""


class SweepRunError(HopperSimError, RuntimeError):
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
