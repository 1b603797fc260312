"""Per-(cell, action) landing-error bounds and transition intervals of the grid abstraction.

Conventions (``docs/design.md``, :class:`planner.imdp.grid.GridWorld`): ``nx`` x ``ny`` cells of
side ``cell`` metres, origin at the lower-left corner; cell ``(i, j)`` covers
``[i*cell, (i+1)*cell) x [j*cell, (j+1)*cell)``, flat index ``i * ny + j``; the absorbing
``out`` state has index ``nx * ny``. Actions, index 0..7: ``N1, N2, E1, E2, S1, S2, W1, W2``
(N = +y, E = +x, one or two cells); an action whose target cell is outside the world is not
enabled and gets no rows.

Landing model: departing from ``x`` in cell ``c`` with executed action ``a`` (target cell
centre ``t``), the robot lands at ``t + e(x, a) + w`` per axis, ``e`` the unknown mean landing
error and ``w = nu + r`` the hop-to-hop part: the known noise ``nu``
(:class:`TruncatedGaussianNoise`) plus the predictor's residual ``r`` (Gaussian with the
predictor's ``residual_std`` for ``(a, axis)``, truncated at three stds;
:class:`~planner.gp.noise.ResidualNoise`), independent per hop and axis.

**Error bounds** (:func:`cell_error_bounds`), per (cell, action, axis), as
``(n_cells, n_actions, 2)`` arrays. Each cell is split into ``K x K`` sub-squares whose
centres are the sample points; every point of the cell is within ``h = cell / (2K)`` per axis
of one of them. With the predictor's posterior mean ``mu`` and std ``s`` sampled there and its
variation bounds at ``h`` (``dmu`` per sample point, ``ds`` per action and axis)::

    lower = min_samples (mu - dmu) - beta * (max_samples s + ds)
    upper = max_samples (mu + dmu) + beta * (max_samples s + ds)

so ``[mu(x) - beta s(x), mu(x) + beta s(x)]`` lies inside ``[lower, upper]`` for every ``x``
in the cell (deterministic margins). ``beta = Phi^-1(1 - delta / (4 H))``: ``H`` the horizon
(hops) and ``delta`` the miss probability the confidence is stated for (below).

**Transition bounds** (:func:`axis_intervals`, :func:`transition_intervals`). Per axis, the
probability of landing in a successor's interval ``[lo, hi)`` given ``e`` is
``p(e) = F(hi - t - e) - F(lo - t - e)``, ``F`` the CDF of ``w``. The density of ``w`` is
symmetric and unimodal, so ``p`` is unimodal in ``e`` with its peak where the window is
centred on zero: over ``e in [e_lo, e_hi]`` the minimum is at an endpoint and the maximum at
the clipped centre ``clip((lo + hi)/2 - t, e_lo, e_hi)``. The 2-D bounds are the products of
the per-axis bounds (the axes are independent and ``e_x, e_y`` range over a box). ``out``:
with ``P_in,d`` the per-axis probability of staying inside ``[0, n_d * cell)``,
``P(out) = 1 - P_in,x P_in,y`` is bounded by
``[1 - max P_in,x max P_in,y, 1 - min P_in,x min P_in,y]`` (exact over the box). For every
``e`` in the box each lower bound is at most the true probability and each upper bound at
least it, and the true probabilities sum to one, so every row satisfies
``sum(lower) <= 1 <= sum(upper)`` (up to floating-point rounding, ~1e-15). A successor's upper
bound is exactly 0 when no ``e`` in the box and no ``w`` in its support can reach it.

**What the bounds guarantee, and what they do not.**

*Model assumption (M):* for every action ``a`` and axis ``d``, the mean error ``e_d(., a)`` is
a draw from the predictor's prior, the predictor's posterior is the exact posterior given the
data (true of :class:`~planner.gp.LandingErrorGP`: exact GP regression with fixed
hyperparameters), and each hop's error is ``e_d(x, a) + nu_d + r_d`` with ``nu`` and ``r`` as
above, independent of everything else.

1. *Confidence, per hop.* Under (M), for any departure point ``x`` and action ``a`` fixed in
   advance, the posterior probability that ``e(x, a)`` lies outside its (cell, action) box on
   either axis is at most ``2 * 2 (1 - Phi(beta)) = delta / H``.
2. *Per trajectory.* A run that makes at most ``H`` hops on an abstraction (the goal-reaching
   phase after the switch: the plan of the switch is kept) has all its hops' errors inside
   their boxes except with probability at most ``delta``, by the union bound over its hops,
   **provided** the departures are not selected by the errors themselves (the run's
   departure points depend on earlier landings, hence on ``e``; the per-hop bound is stated
   for points fixed in advance, and this step treats them so). The defaults ``delta = 0.01``,
   ``H = 100`` give ``beta = 4.06``.
3. *Transitions.* Wherever a departure's error lies in its box, the one-hop successor
   probabilities lie in the pair's intervals (exactly, by the min/max argument above). So,
   when 2 holds, the worst-case satisfaction probability of the IMDP bounds from below the
   probability that the plan satisfies the task, and a run that follows the goal plan of a
   switch with worst-case probability ``p_switch`` satisfies the task with probability at
   least ``(1 - delta) p_switch >= p_switch - delta`` (over the draw of ``e`` and the noise)
   if it does so within ``H`` hops.

These are statements about the posterior, recomputed at every re-synthesis from its data;
being posterior statements they also hold at a data-dependent time such as the switch. A
confidence simultaneous over all (cell, action) pairs of the world (a union bound over pairs
and sample points, ``N = 2 * 1620 * K^2`` for 15 x 15) would need ``beta = 5.1`` (``K = 3``)
instead of 4.06, a quarter more ``beta s`` on every box, although a run uses only the pairs
it visits.

*Not covered:* (i) the model being wrong: the mean error not being a draw of that prior (a
terrain-to-error map that is not linear in the stance force, sensitivities or amplitudes
other than the prior's, a controller bias that varies with position), the residual not being
Gaussian (measured on MuJoCo hops: skewed towards undershooting, tails beyond three stds in
about 0.1 % of hops) or depending on an incoming velocity whose distribution at a cell differs
from that of the data, or the residual variances being misestimated (they are plug-in
estimates, not integrated over); (ii) the selection caveat of 2; (iii) simultaneity over the
continuum of a cell: the margins put the posterior band ``mu(x) +- beta s(x)`` of every point
of a cell inside the bounds, and 1 holds at every point, but no statement about the supremum
of the sample path over a cell is made; (iv) runs longer than ``H`` hops after the switch
(the miss bound grows with the hops, and the worst-case satisfaction probability is an
unbounded-horizon one: a value of 1 reached through small lower bounds of progress may need
many hops); (v) failed hops (the hopper falls), which the abstraction does not model. The
empirical checks against MuJoCo are ``benchmarks/audit_intervals.py`` (per pair successor
frequencies) and ``benchmarks/guarantee.py`` (the end-to-end rate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri

from planner.errors import IntervalError
from planner.gp.noise import ResidualNoise, TruncatedGaussianNoise
from planner.gp.protocol import ErrorPredictor
from planner.imdp.grid import GridWorld

__all__ = [
    "AxisIntervals",
    "CellErrorBounds",
    "ResidualNoise",
    "TransitionIntervals",
    "TruncatedGaussianNoise",
    "axis_intervals",
    "cell_error_bounds",
    "cell_sample_points",
    "confidence_beta",
    "transition_intervals",
]


def confidence_beta(delta: float, num_points: int) -> float:
    """``Phi^-1(1 - delta / (2 num_points))``: two-sided Gaussian tails, union over points."""
    if not 0.0 < delta < 1.0:
        raise IntervalError(f"delta must lie in (0, 1), got {delta}")
    if num_points < 1:
        raise IntervalError(f"num_points must be >= 1, got {num_points}")
    return float(ndtri(1.0 - delta / (2.0 * num_points)))


@dataclass(frozen=True)
class CellErrorBounds:
    """Bounds of the mean landing error per (cell, action, axis), metres: ``lower``,
    ``upper`` ``(n_cells, n_actions, 2)``; ``residual_std`` ``(n_actions, 2)`` the residual
    of the hop-to-hop error beyond the noise nu (metres); ``beta`` the multiplier used."""

    lower: np.ndarray
    upper: np.ndarray
    residual_std: np.ndarray
    beta: float
    delta: float
    samples_per_axis: int


def cell_sample_points(grid: GridWorld, samples_per_axis: int) -> np.ndarray:
    """Sub-square centres of every cell, ``(n_cells, K * K, 2)`` metres, flat cell order."""
    nx, ny, cell = grid.nx, grid.ny, grid.cell
    k = int(samples_per_axis)
    if k < 1:
        raise IntervalError(f"samples_per_axis must be >= 1, got {samples_per_axis}")
    offs = (np.arange(k) + 0.5) * (cell / k)
    sub = np.stack(np.meshgrid(offs, offs, indexing="ij"), axis=-1).reshape(-1, 2)
    corner = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij"), axis=-1)
    corner = corner.reshape(-1, 1, 2) * cell
    return corner + sub[None, :, :]


def _checked(name: str, value: object, shape: tuple[int, ...], *, nonneg: bool) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != shape:
        raise IntervalError(f"the predictor's {name} has shape {arr.shape}, expected {shape}")
    bad = ~np.isfinite(arr) | ((arr < 0.0) if nonneg else False)
    if bad.any():
        idx = tuple(int(v) for v in np.argwhere(bad)[0])
        what = "finite and >= 0" if nonneg else "finite"
        raise IntervalError(f"the predictor's {name} must be {what}: {float(arr[idx])} at {idx}")
    return arr


def cell_error_bounds(
    predictor: ErrorPredictor,
    grid: GridWorld,
    *,
    samples_per_axis: int,
    delta: float,
    horizon: int,
    beta: float | None = None,
) -> CellErrorBounds:
    """Bounds of the mean landing error of every (cell, action) (see the module docstring).

    The settings' defaults are those of :class:`planner.config.PlannerConfig`
    (``cell_error_bounds(gp, grid, **PlannerConfig().interval_options())``). ``beta``
    overrides the union-bound multiplier computed from ``delta``. Raises
    :class:`~planner.errors.IntervalError` if the predictor returns arrays of the wrong shape,
    non-finite values or a negative std, variation or residual.
    """
    pts = cell_sample_points(grid, samples_per_axis)
    n_cells, n_sub = pts.shape[:2]
    na = int(grid.enabled.shape[1])
    if int(getattr(predictor, "n_actions", na)) != na:
        raise IntervalError(
            f"the predictor models {predictor.n_actions} actions, the grid has {na}"
        )
    if int(horizon) < 1:
        raise IntervalError(f"horizon must be >= 1 hop, got {horizon}")
    if beta is None:
        beta = confidence_beta(delta, 2 * int(horizon))
    elif not np.isfinite(beta) or beta < 0.0:
        raise IntervalError(f"beta must be finite and >= 0, got {beta}")
    mean, std = predictor.predict(pts.reshape(-1, 2))
    shape = (n_cells * n_sub, na, 2)
    mean = _checked("mean", mean, shape, nonneg=False).reshape(n_cells, n_sub, na, 2)
    std = _checked("std", std, shape, nonneg=True).reshape(n_cells, n_sub, na, 2)
    dmean, dstd = predictor.variation(
        pts.reshape(-1, 2), np.full(2, grid.cell / (2 * samples_per_axis))
    )
    dmean = _checked("mean variation", dmean, shape, nonneg=True).reshape(mean.shape)
    dstd = _checked("std variation", dstd, (na, 2), nonneg=True)
    resid = _checked("residual std", predictor.residual_std(), (na, 2), nonneg=True)
    s_max = std.max(axis=1) + dstd
    lower = (mean - dmean).min(axis=1) - beta * s_max
    upper = (mean + dmean).max(axis=1) + beta * s_max
    return CellErrorBounds(
        lower, upper, resid.copy(), float(beta), float(delta), int(samples_per_axis)
    )


@dataclass(frozen=True)
class TransitionIntervals:
    """COO transition intervals: row ``k`` bounds ``P(successor[k] | state[k], action[k])``.

    Feed them to :meth:`planner.imdp.grid.GridWorld.imdp_from_intervals` (which adds the
    self-loop of ``out``) with :meth:`coo`.
    """

    state: np.ndarray
    action: np.ndarray
    successor: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    num_states: int

    def coo(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(state, action, successor, lower, upper)``."""
        return self.state, self.action, self.successor, self.lower, self.upper


@dataclass(frozen=True)
class AxisIntervals:
    """Per-axis interval distributions of every enabled (cell, action) (``R`` rows, in
    ``np.nonzero(grid.enabled[:n_cells])`` order): ``x_lower``, ``x_upper`` ``(R, nx)``
    bound the probability of landing in column ``i`` (x in ``[i*cell, (i+1)*cell)``),
    ``y_lower``, ``y_upper`` ``(R, ny)`` in row ``j``; ``inside_x``, ``inside_y`` ``(R, 2)``
    bound (lower, upper) the probability of staying inside the world along that axis. The
    axes are independent, so a 2-D distribution is the product of one distribution per axis
    (the orthogonally decoupled abstraction, :mod:`planner.imdp.decoupled`, whose bins are
    :meth:`bins`); :func:`transition_intervals` multiplies the same bounds."""

    state: np.ndarray
    action: np.ndarray
    x_lower: np.ndarray
    x_upper: np.ndarray
    y_lower: np.ndarray
    y_upper: np.ndarray
    inside_x: np.ndarray
    inside_y: np.ndarray

    def bins(self, axis: int) -> tuple[np.ndarray, np.ndarray]:
        """Per-axis bin bounds ``(lower, upper)``, ``(R, n + 1)``: the ``n`` columns (axis 0)
        or rows (axis 1), then *outside* (below ``0`` or above ``n cell``), whose probability
        ``1 - P_in`` is bounded by ``[1 - max P_in, 1 - min P_in]`` (exact over the box,
        as the out bounds of :func:`transition_intervals`). Each row brackets one:
        ``sum_b min_e P_b(e) <= min_e sum_b P_b(e) = 1`` and likewise for the maxima."""
        if axis not in (0, 1):
            raise IntervalError(f"axis must be 0 (x) or 1 (y), got {axis}")
        lo, up, inside = (
            (self.x_lower, self.x_upper, self.inside_x)
            if axis == 0
            else (self.y_lower, self.y_upper, self.inside_y)
        )
        out_lo = np.clip(1.0 - inside[:, 1], 0.0, 1.0)[:, None]
        out_hi = np.clip(1.0 - inside[:, 0], 0.0, 1.0)[:, None]
        return np.hstack([lo, out_lo]), np.hstack([up, out_hi])


def _window_bounds(
    noise: TruncatedGaussianNoise | ResidualNoise,
    lo: np.ndarray,
    hi: np.ndarray,
    e_lo: np.ndarray,
    e_hi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Min and max over ``e in [e_lo, e_hi]`` of ``P(lo <= e + w < hi)``, broadcast."""

    def prob(e: np.ndarray) -> np.ndarray:
        return np.clip(noise.cdf(hi - e) - noise.cdf(lo - e), 0.0, 1.0)

    peak = np.clip(0.5 * (lo + hi), e_lo, e_hi)
    return np.minimum(prob(e_lo), prob(e_hi)), prob(peak)


def _validated_bounds(bounds: CellErrorBounds, grid: GridWorld) -> tuple[np.ndarray, ...]:
    n_cells, na = grid.n_cells, int(grid.enabled.shape[1])
    e_lo = np.asarray(bounds.lower, dtype=np.float64)
    e_hi = np.asarray(bounds.upper, dtype=np.float64)
    resid = np.asarray(bounds.residual_std, dtype=np.float64)
    want = (n_cells, na, 2)
    if e_lo.shape != want or e_hi.shape != want:
        raise IntervalError(
            f"error bounds must have shape {want}, got {e_lo.shape} and {e_hi.shape}"
        )
    if resid.shape != (na, 2) or not (np.isfinite(resid) & (resid >= 0)).all():
        raise IntervalError(
            f"residual_std must be finite, >= 0 and of shape ({na}, 2), got {resid.shape}"
        )
    state, action = np.nonzero(grid.enabled[:n_cells])
    lo, hi = e_lo[state, action], e_hi[state, action]
    bad = np.flatnonzero(~(np.isfinite(lo) & np.isfinite(hi) & (lo <= hi)).all(axis=1))
    if bad.size:
        c, a = int(state[bad[0]]), int(action[bad[0]])
        raise IntervalError(f"error bounds of cell {c}, action {a} are not a finite interval")
    return state, action, lo, hi, resid


def axis_intervals(
    bounds: CellErrorBounds,
    grid: GridWorld,
    noise: TruncatedGaussianNoise | None = None,
) -> AxisIntervals:
    """Per-axis successor intervals of every enabled (cell, action) (module docstring)."""
    noise = noise or TruncatedGaussianNoise()
    state, action, lo, hi, resid = _validated_bounds(bounds, grid)
    centre = grid.target_centres[state, action]
    out: list[np.ndarray] = []
    for d, n in ((0, grid.nx), (1, grid.ny)):
        edges = np.arange(n + 1, dtype=np.float64) * grid.cell
        p_lo, p_hi = np.zeros((len(state), n)), np.zeros((len(state), n))
        inside = np.zeros((len(state), 2))
        for a in np.unique(action):
            rows = np.flatnonzero(action == a)
            w = ResidualNoise(noise, float(resid[a, d]))
            t = centre[rows, d][:, None]
            e_lo, e_hi = lo[rows, d][:, None], hi[rows, d][:, None]
            p_lo[rows], p_hi[rows] = _window_bounds(w, edges[:-1] - t, edges[1:] - t, e_lo, e_hi)
            i_lo, i_hi = _window_bounds(w, -t, n * grid.cell - t, e_lo, e_hi)
            inside[rows, 0], inside[rows, 1] = i_lo[:, 0], i_hi[:, 0]
        out += [p_lo, p_hi, inside]
    x_lo, x_hi, in_x, y_lo, y_hi, in_y = out
    return AxisIntervals(
        state.astype(np.int64), action.astype(np.int64), x_lo, x_hi, y_lo, y_hi, in_x, in_y
    )


def transition_intervals(
    bounds: CellErrorBounds,
    grid: GridWorld,
    noise: TruncatedGaussianNoise | None = None,
) -> TransitionIntervals:
    """Transition intervals for every enabled (cell, action) and every reachable successor.

    ``noise`` is the known landing noise nu; the residual of ``bounds`` is added to it.
    Successors with upper bound exactly 0 (unreachable given the bounded noise) are left out;
    ``out`` (index ``nx * ny``) appears wherever leaving the world is possible.
    """
    ax = axis_intervals(bounds, grid, noise)
    n_cells, rows = grid.n_cells, len(ax.state)
    lower = (ax.x_lower[:, :, None] * ax.y_lower[:, None, :]).reshape(rows, n_cells)
    upper = (ax.x_upper[:, :, None] * ax.y_upper[:, None, :]).reshape(rows, n_cells)
    out_lo = np.clip(1.0 - ax.inside_x[:, 1] * ax.inside_y[:, 1], 0.0, 1.0)
    out_hi = np.clip(1.0 - ax.inside_x[:, 0] * ax.inside_y[:, 0], 0.0, 1.0)
    lower = np.concatenate([lower, out_lo[:, None]], axis=1)
    upper = np.concatenate([upper, out_hi[:, None]], axis=1)
    row, succ = np.nonzero(upper > 0.0)
    return TransitionIntervals(
        state=ax.state[row],
        action=ax.action[row],
        successor=succ.astype(np.int64),
        lower=lower[row, succ],
        upper=upper[row, succ],
        num_states=n_cells + 1,
    )
