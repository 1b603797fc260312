"""Per-cell landing-error bounds and transition intervals of the grid abstraction.

Conventions (``docs/design.md``, :class:`planner.imdp.grid.GridWorld`): ``nx`` x ``ny`` cells of
side ``cell`` metres, origin at the lower-left corner; cell ``(i, j)`` covers
``[i*cell, (i+1)*cell) x [j*cell, (j+1)*cell)``, flat index ``i * ny + j``; the absorbing
``out`` state has index ``nx * ny``. Actions, index 0..7: ``N1, N2, E1, E2, S1, S2, W1, W2``
(N = +y, E = +x, one or two cells); an action whose target cell is outside the world is not
enabled and gets no rows.

Landing model: departing from ``x`` in cell ``c`` with action ``a`` (target cell centre
``t``), the robot lands at ``t + e(x) + nu``, ``e`` the unknown mean landing error and ``nu``
independent per-axis truncated-Gaussian noise (:class:`TruncatedGaussianNoise`).

**Error bounds** (:func:`cell_error_bounds`). Each cell is split into ``K x K`` sub-squares
whose centres are the sample points; every point of the cell is within ``h = cell / (2K)`` per
axis of one of them. With the predictor's posterior mean ``mu`` and std ``s`` sampled there and
its variation bounds ``dmu, ds`` (:meth:`~planner.gp.protocol.ErrorPredictor.variation` at
``h``), per axis::

    lower = min_samples mu - dmu - beta * (max_samples s + ds)
    upper = max_samples mu + dmu + beta * (max_samples s + ds)

so ``[mu(x) - beta s(x), mu(x) + beta s(x)]`` is inside ``[lower, upper]`` for every ``x`` in
the cell (the margins are deterministic and sound). The multiplier is
``beta = Phi^-1(1 - delta / (2 N))`` with ``N = 2 * n_cells * K^2`` (axes times sample points):
under the GP model (``e`` drawn from the GP prior, Gaussian observation noise) each
``e_d(x)`` lies outside ``mu_d(x) +- beta s_d(x)`` with probability at most ``delta / N``, so by
the union bound the error lies in its cell's interval at all sample points of all cells, both
axes, simultaneously with probability at least ``1 - delta``; at any single departure point the
miss probability per axis is at most ``delta / N``. (Simultaneity over the continuum of
departure points is not claimed. "The GP model" is the predictor's posterior taken at its
word: for :class:`~planner.gp.LandingErrorGP` the sparse variational posterior, not the exact
GP posterior, and the landing noise ``nu`` is truncated-Gaussian while the GP likelihood is
Gaussian; the empirical audit is what checks the intervals against the real system.)

**Transition bounds** (:func:`transition_intervals`). Per axis, the probability of landing in a
successor's interval ``[lo, hi)`` given ``e`` is ``p(e) = F(hi - t - e) - F(lo - t - e)``,
``F`` the noise CDF. The noise density is symmetric and unimodal, so ``p`` is unimodal in ``e``
with its peak where the window is centred on zero: over ``e in [e_lo, e_hi]`` the minimum is at
an endpoint and the maximum at the clipped centre ``clip((lo + hi)/2 - t, e_lo, e_hi)``. The
2-D bounds are the products of the per-axis bounds (the axes are independent and ``e_x, e_y``
range over a box). ``out``: with ``P_in,d`` the per-axis probability of staying inside
``[0, n_d * cell)``, ``P(out) = 1 - P_in,x P_in,y`` is bounded by
``[1 - max P_in,x max P_in,y, 1 - min P_in,x min P_in,y]`` (exact over the box). For every
``e`` in the box each lower bound is at most the true probability and each upper bound at
least it, and the true probabilities sum to one, so every row satisfies
``sum(lower) <= 1 <= sum(upper)`` (up to floating-point rounding, ~1e-15).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, ndtri

from planner.errors import IntervalError
from planner.gp.protocol import ErrorPredictor
from planner.imdp.grid import GridWorld


@dataclass(frozen=True)
class TruncatedGaussianNoise:
    """Zero-mean Gaussian with std ``sigma`` (metres) truncated to ``[-bound, bound]``."""

    sigma: float = 0.1
    bound: float = 0.2

    def __post_init__(self) -> None:
        for name in ("sigma", "bound"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value <= 0.0:
                raise IntervalError(f"noise {name} must be positive and finite, got {value}")

    def cdf(self, t: np.ndarray) -> np.ndarray:
        """``P(nu <= t)``, elementwise; exactly 0 below ``-bound`` and 1 above ``bound``."""
        b = self.bound / self.sigma
        lo = ndtr(-b)
        z = np.clip(np.asarray(t, dtype=np.float64), -self.bound, self.bound) / self.sigma
        return np.clip((ndtr(z) - lo) / (ndtr(b) - lo), 0.0, 1.0)

    def sample(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> np.ndarray:
        """Draws by inverse CDF from the seeded generator ``rng``."""
        b = self.bound / self.sigma
        lo, hi = ndtr(-b), ndtr(b)
        u = rng.uniform(lo, hi, size=size)
        return np.clip(ndtri(u) * self.sigma, -self.bound, self.bound)


def confidence_beta(delta: float, num_points: int) -> float:
    """``Phi^-1(1 - delta / (2 num_points))``: two-sided Gaussian tails, union over points."""
    if not 0.0 < delta < 1.0:
        raise IntervalError(f"delta must lie in (0, 1), got {delta}")
    if num_points < 1:
        raise IntervalError(f"num_points must be >= 1, got {num_points}")
    return float(ndtri(1.0 - delta / (2.0 * num_points)))


@dataclass(frozen=True)
class CellErrorBounds:
    """Per-cell bounds of the mean landing error, metres, each ``(nx * ny, 2)`` (x, y)."""

    lower: np.ndarray
    upper: np.ndarray
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


def cell_error_bounds(
    predictor: ErrorPredictor,
    grid: GridWorld,
    *,
    samples_per_axis: int = 5,
    delta: float = 0.01,
    beta: float | None = None,
) -> CellErrorBounds:
    """Bounds of the mean landing error over every departure cell (see the module docstring).

    ``beta`` overrides the union-bound multiplier computed from ``delta``.
    """
    pts = cell_sample_points(grid, samples_per_axis)
    n_cells, n_sub = pts.shape[:2]
    if beta is None:
        beta = confidence_beta(delta, 2 * n_cells * n_sub)
    elif not np.isfinite(beta) or beta < 0.0:
        raise IntervalError(f"beta must be finite and >= 0, got {beta}")
    mean, std = predictor.predict(pts.reshape(-1, 2))
    mean = np.asarray(mean, dtype=np.float64).reshape(n_cells, n_sub, 2)
    std = np.asarray(std, dtype=np.float64).reshape(n_cells, n_sub, 2)
    dmean, dstd = predictor.variation(np.full(2, grid.cell / (2 * samples_per_axis)))
    s_max = std.max(axis=1) + np.asarray(dstd)
    lower = mean.min(axis=1) - np.asarray(dmean) - beta * s_max
    upper = mean.max(axis=1) + np.asarray(dmean) + beta * s_max
    return CellErrorBounds(lower, upper, float(beta), float(delta), int(samples_per_axis))


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


def _window_bounds(
    noise: TruncatedGaussianNoise,
    lo: np.ndarray,
    hi: np.ndarray,
    e_lo: np.ndarray,
    e_hi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Min and max over ``e in [e_lo, e_hi]`` of ``P(lo <= e + nu < hi)``, broadcast."""

    def prob(e: np.ndarray) -> np.ndarray:
        return np.clip(noise.cdf(hi - e) - noise.cdf(lo - e), 0.0, 1.0)

    peak = np.clip(0.5 * (lo + hi), e_lo, e_hi)
    return np.minimum(prob(e_lo), prob(e_hi)), prob(peak)


def axis_bin_bounds(
    noise: TruncatedGaussianNoise,
    n: int,
    cell: float,
    target: np.ndarray,
    e_lo: np.ndarray,
    e_hi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis landing bounds for the decoupled abstraction
    (:mod:`planner.imdp.decoupled`): for rows aiming at ``target`` (shape ``(rows,)``,
    metres) with the mean error in ``[e_lo, e_hi]``, the min and max over that interval of
    the probability of landing in each of the ``n + 2`` bins *below* ``0``, the ``n``
    columns ``[k cell, (k + 1) cell)``, and *above* ``n cell``. Shapes ``(rows, n + 2)``."""
    t = np.asarray(target, dtype=np.float64)[:, None]
    edges = np.concatenate(([-np.inf], np.arange(n + 1, dtype=np.float64) * cell, [np.inf]))
    return _window_bounds(
        noise,
        edges[None, :-1] - t,
        edges[None, 1:] - t,
        np.asarray(e_lo, dtype=np.float64)[:, None],
        np.asarray(e_hi, dtype=np.float64)[:, None],
    )


def transition_intervals(
    bounds: CellErrorBounds,
    grid: GridWorld,
    noise: TruncatedGaussianNoise | None = None,
) -> TransitionIntervals:
    """Transition intervals for every enabled (cell, action) and every reachable successor.

    Successors with upper bound exactly 0 (unreachable given the bounded noise) are left out;
    ``out`` (index ``nx * ny``) appears wherever leaving the world is possible.
    """
    noise = noise or TruncatedGaussianNoise()
    nx, ny, cell, n_cells = grid.nx, grid.ny, grid.cell, grid.n_cells
    e_lo = np.asarray(bounds.lower, dtype=np.float64)
    e_hi = np.asarray(bounds.upper, dtype=np.float64)
    if e_lo.shape != (n_cells, 2) or e_hi.shape != (n_cells, 2):
        raise IntervalError(
            f"error bounds must have shape ({n_cells}, 2), got {e_lo.shape} and {e_hi.shape}"
        )
    bad = np.flatnonzero(~(np.isfinite(e_lo) & np.isfinite(e_hi) & (e_lo <= e_hi)).all(axis=1))
    if bad.size:
        raise IntervalError(f"error bounds of cell {int(bad[0])} are not a finite interval")
    state, action = np.nonzero(grid.enabled[:n_cells])
    centre = grid.target_centres[state, action]
    per_axis = []
    for d, n in ((0, nx), (1, ny)):
        lo_e = e_lo[state, d][:, None]
        hi_e = e_hi[state, d][:, None]
        t = centre[:, d][:, None]
        edges = np.arange(n + 1, dtype=np.float64) * cell
        p_lo, p_hi = _window_bounds(noise, edges[None, :-1] - t, edges[None, 1:] - t, lo_e, hi_e)
        in_lo, in_hi = _window_bounds(noise, -t, n * cell - t, lo_e, hi_e)
        per_axis.append((p_lo, p_hi, in_lo[:, 0], in_hi[:, 0]))
    (xl, xh, inxl, inxh), (yl, yh, inyl, inyh) = per_axis
    lower = (xl[:, :, None] * yl[:, None, :]).reshape(len(state), n_cells)
    upper = (xh[:, :, None] * yh[:, None, :]).reshape(len(state), n_cells)
    out_lo = np.clip(1.0 - inxh * inyh, 0.0, 1.0)
    out_hi = np.clip(1.0 - inxl * inyl, 0.0, 1.0)
    lower = np.concatenate([lower, out_lo[:, None]], axis=1)
    upper = np.concatenate([upper, out_hi[:, None]], axis=1)
    row, succ = np.nonzero(upper > 0.0)
    return TransitionIntervals(
        state=state[row].astype(np.int64),
        action=action[row].astype(np.int64),
        successor=succ.astype(np.int64),
        lower=lower[row, succ],
        upper=upper[row, succ],
        num_states=n_cells + 1,
    )
