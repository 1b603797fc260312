"""Checks of the paper's trade-off theorem on a sweep's per-run data.

The theorem (and the discussion of Table I) predicts two trends:

* the number of steps to satisfy the LTL task decreases as the decay rate ``eps`` grows
  (checked for ``C = 0.25`` and ``C = 0.5``, where the paper observes it);
* the reward increases with ``P_RL,ee = C`` (checked at each ``eps`` and pooled over all).

Each trend is an ordinary least-squares slope on the per-run data ``(x_i, y_i)``:

    b = S_xy / S_xx,   s^2 = sum_i (y_i - a - b x_i)^2 / (n - 2),   se(b) = s / sqrt(S_xx),
    CI = b +- t_{(1+level)/2, n-2} * se(b),

with ``S_xx = sum (x_i - xbar)^2`` and ``S_xy = sum (x_i - xbar)(y_i - ybar)``. A trend
*holds* when the whole interval lies on the predicted side of zero, *does not hold* when it
lies entirely on the other side, and is *inconclusive* otherwise (zero inside the interval).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from hopper_sim.errors import HopperSimError
from hopper_sim.experiments.sweep import PAPER_TABLE_I

Verdict = Literal["holds", "does not hold", "inconclusive", "insufficient data"]

STEPS_TREND_CS: tuple[float, ...] = (0.25, 0.50)
"""The values of C at which the paper reports fewer steps for larger eps."""


class Point(Protocol):
    """What the trend checks read from a run (a :class:`~hopper_sim.experiments.sweep.SweepRow`) or
    from a
    cell mean (:class:`CellMean`)."""

    @property
    def c(self) -> float: ...
    @property
    def eps(self) -> float: ...
    @property
    def steps(self) -> float: ...
    @property
    def reward(self) -> float: ...


@dataclass(frozen=True)
class CellMean:
    """A cell's mean reward and steps, e.g. one entry of the paper's Table I."""

    c: float
    eps: float
    reward: float
    steps: float


def paper_points() -> list[CellMean]:
    """The paper's Table I as nine points (cell means only: the paper gives no per-run data,
    so slopes fitted on these treat each mean as one observation)."""
    return [CellMean(c, e, r, s) for (c, e), (r, s) in PAPER_TABLE_I.items()]


class TrendDataError(HopperSimError, ValueError):
    """The data cannot give a slope (too few points, a single x value, non-finite values)."""


@dataclass(frozen=True)
class Slope:
    """A least-squares slope with its confidence interval.

    Attributes:
        slope: ``b``, in units of y per unit of x.
        low, high: ends of the ``level`` confidence interval.
        stderr: standard error ``se(b)``.
        n: number of points.
        level: confidence level.
    """

    slope: float
    low: float
    high: float
    stderr: float
    n: int
    level: float = 0.95


def slope_ci(
    x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray, level: float = 0.95
) -> Slope:
    """The OLS slope of ``y`` on ``x`` with its Student-t confidence interval (``n - 2`` dof).

    Raises:
        TrendDataError: fewer than 3 points, all ``x`` equal, mismatched lengths or
            non-finite values.
        ValueError: ``level`` outside (0, 1).
    """
    from scipy import stats

    if not 0.0 < level < 1.0:
        raise ValueError(f"confidence level must be in (0, 1), got {level}")
    xa = np.asarray(x, dtype=float).ravel()
    ya = np.asarray(y, dtype=float).ravel()
    if xa.size != ya.size:
        raise TrendDataError(f"x has {xa.size} values but y has {ya.size}")
    if not (np.isfinite(xa).all() and np.isfinite(ya).all()):
        raise TrendDataError("x and y must be finite")
    n = xa.size
    if n < 3:
        raise TrendDataError(f"a slope with a confidence interval needs >= 3 points, got {n}")
    if np.all(xa == xa[0]):
        raise TrendDataError(f"all x values are equal ({xa[0]:g}): no slope")
    dx = xa - xa.mean()
    sxx = float(dx @ dx)
    b = float(dx @ (ya - ya.mean())) / sxx
    resid = ya - ya.mean() - b * dx
    se = math.sqrt(float(resid @ resid) / (n - 2) / sxx)
    half = float(stats.t.ppf(0.5 + level / 2.0, n - 2)) * se
    return Slope(b, b - half, b + half, se, n, level)


def classify(slope: Slope, predicted_sign: int) -> Verdict:
    """``"holds"`` if the interval lies strictly on the side of ``predicted_sign`` (+1 or -1),
    ``"does not hold"`` if strictly on the other side, ``"inconclusive"`` otherwise.

    Raises:
        ValueError: ``predicted_sign`` not +1 or -1.
    """
    if predicted_sign not in (1, -1):
        raise ValueError(f"predicted_sign must be +1 or -1, got {predicted_sign}")
    low, high = slope.low * predicted_sign, slope.high * predicted_sign
    low, high = min(low, high), max(low, high)
    if low > 0.0:
        return "holds"
    if high < 0.0:
        return "does not hold"
    return "inconclusive"


@dataclass(frozen=True)
class Trend:
    """One predicted trend and what the data say about it.

    Attributes:
        name: what is checked, e.g. ``"steps vs eps at C = 0.25"``.
        x, y: the variables (``"eps"``/``"c"``, ``"steps"``/``"reward"``).
        predicted_sign: -1 (decreasing) or +1 (increasing).
        slope: the fitted slope, or ``None`` when the data were insufficient.
        verdict: see :func:`classify`; ``"insufficient data"`` when no slope could be fitted.
        reason: why the data were insufficient (empty otherwise).
    """

    name: str
    x: str
    y: str
    predicted_sign: int
    slope: Slope | None
    verdict: Verdict
    reason: str = ""


def _trend(name: str, x: str, y: str, sign: int, rows: Sequence[Point], level: float) -> Trend:
    xs = [float(getattr(r, x)) for r in rows]
    ys = [float(getattr(r, y)) for r in rows]
    try:
        s = slope_ci(xs, ys, level)
    except TrendDataError as err:
        return Trend(name, x, y, sign, None, "insufficient data", str(err))
    return Trend(name, x, y, sign, s, classify(s, sign))


def _same(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)


def check_tradeoff(
    rows: Sequence[Point],
    steps_cs: Sequence[float] = STEPS_TREND_CS,
    level: float = 0.95,
) -> list[Trend]:
    """The trade-off trends on per-run sweep rows.

    Returns, in order: ``steps`` vs ``eps`` (predicted decreasing) for each C in
    ``steps_cs``; ``reward`` vs ``C`` (predicted increasing) at each ``eps`` present in the
    rows, sorted; and ``reward`` vs ``C`` pooled over all rows.
    """
    trends = []
    for c in steps_cs:
        sub = [r for r in rows if _same(r.c, c)]
        trends.append(_trend(f"steps vs eps at C = {c:g}", "eps", "steps", -1, sub, level))
    for e in sorted({r.eps for r in rows}):
        sub = [r for r in rows if _same(r.eps, e)]
        trends.append(_trend(f"reward vs C at eps = {e:g}", "c", "reward", +1, sub, level))
    trends.append(_trend("reward vs C, all eps pooled", "c", "reward", +1, rows, level))
    return trends


def format_trends(trends: Sequence[Trend]) -> str:
    """A plain-text table of the trends: slope, its CI, the prediction and the verdict."""
    head = ["trend", "predicted", "slope (y per unit x)", "CI", "n", "verdict"]
    body = []
    for t in trends:
        pred = "decreasing" if t.predicted_sign < 0 else "increasing"
        if t.slope is None:
            body.append([t.name, pred, "-", "-", "-", f"{t.verdict} ({t.reason})"])
            continue
        s = t.slope
        ci = f"[{s.low:.4g}, {s.high:.4g}] ({round(100 * s.level)} %)"
        body.append([t.name, pred, f"{s.slope:.4g}", ci, str(s.n), t.verdict])
    grid = [head, *body]
    widths = [max(len(r[k]) for r in grid) for k in range(len(head))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in grid]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)
