"""Statistics of a sweep: per-cell means with Student-t intervals, the success rate, the
paper's values beside them, and the finished sweep as a record.

    mean = (1/n) sum_i y_i,    s^2 = (1/(n-1)) sum_i (y_i - mean)^2,
    CI = mean +- t_{(1+level)/2, n-1} * s / sqrt(n).

Means are over all runs of a cell, whatever their outcome (a timeout counts with its capped
step number, a violation with the hops it made), as the paper averages over complete runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from hopper_sim.experiments.sweep_grid import PAPER_TABLE_I, SweepError, SweepRow, SweepSpec
from hopper_sim.navigation.events import OUTCOMES
from planner.modes import Outcome


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
                successes=counts[Outcome.SUCCESS],
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
