"""The decoupled abstraction of a grid world from the landing-error bounds of the runner.

Both abstractions of the grid are built from the same per-axis intervals,
:func:`planner.intervals.axis_intervals` (the known noise nu plus the predictor's per-action
residual, exactly as the product-interval IMDP of
:func:`planner.intervals.transition_intervals`): per row ``(cell, action)`` and axis, the
bounds ``[l_b, u_b]`` of the probability of landing in each column (row) ``b`` and of
leaving the world along that axis (:meth:`planner.intervals.AxisIntervals.bins`). The
product-interval IMDP bounds a successor cell ``(i, j)`` by ``[l^x_i l^y_j, u^x_i u^y_j]``
and lets its adversary pick any joint distribution inside; here the adversary picks one
distribution per axis inside its intervals and the transition is their product. Every
such product lies inside the product-interval bounds (``p^x_i p^y_j`` between the products
of the bounds; ``P(out) = 1 - p^x_in p^y_in`` with ``p^x_in = 1 - p^x_outside`` in
``[min P_in,x, max P_in,x]``), so the decoupled adversary's choices are a subset of the
product-interval adversary's and the decoupled worst-case value is never below the
product-interval one; both are sound for the same model (module docstring of
:mod:`planner.intervals`) because the true per-axis distributions lie in these intervals.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from planner.errors import ModelError
from planner.imdp.decoupled.model import DecoupledIMDP
from planner.imdp.grid import ACTIONS, OUT_ACTION, GridWorld
from planner.imdp.model import BOUND_TOLERANCE
from planner.intervals import AxisIntervals, CellErrorBounds, TruncatedGaussianNoise, axis_intervals


def grid_decoupled_model(
    grid: GridWorld,
    bounds: CellErrorBounds,
    noise: TruncatedGaussianNoise | None = None,
    initial: Iterable[int] = (0,),
    tolerance: float = BOUND_TOLERANCE,
) -> DecoupledIMDP:
    """The decoupled abstraction of ``grid`` for the mean-error bounds ``bounds`` (their
    residual std included) and the known noise ``noise`` (default
    :class:`~planner.intervals.TruncatedGaussianNoise`): the per-axis intervals of
    :func:`planner.intervals.axis_intervals`, made a model by :func:`decoupled_from_axes`.

    Raises:
        IntervalError: bounds of the wrong shape, a negative or non-finite residual std, or
            an enabled pair whose bounds are not a finite interval.
    """
    return decoupled_from_axes(grid, axis_intervals(bounds, grid, noise), initial, tolerance)


def decoupled_from_axes(
    grid: GridWorld,
    axes: AxisIntervals,
    initial: Iterable[int] = (0,),
    tolerance: float = BOUND_TOLERANCE,
) -> DecoupledIMDP:
    """The decoupled model of per-axis intervals (rows in ``np.nonzero(grid.enabled)``
    order, as :func:`planner.intervals.axis_intervals` gives them).

    Each axis has the bins ``0 .. n - 1`` (columns or rows) and ``n`` (outside,
    :meth:`~planner.intervals.AxisIntervals.bins`); a pair with a bin outside maps to
    ``out``, whose row lands outside for sure (its self-loop). Bins with upper bound 0 are
    left out.

    Raises:
        ModelError: rows that are not exactly the enabled (cell, action) pairs, or per-axis
            bounds that do not bracket one.
    """
    s, a = np.asarray(axes.state, np.int64), np.asarray(axes.action, np.int64)
    want_s, want_a = np.nonzero(grid.enabled[: grid.n_cells])
    if s.size != want_s.size or np.any(s != want_s) or np.any(a != want_a):
        raise ModelError("rows must be every enabled (cell, action) pair exactly once")
    csr = []
    for d, n in ((0, grid.nx), (1, grid.ny)):
        lo, hi = axes.bins(d)
        sure_out = np.eye(1, n + 1, n)  # the row of ``out``: outside for sure
        lo, hi = np.vstack([lo, sure_out]), np.vstack([hi, sure_out])
        r, b = np.nonzero(hi > 0.0)
        ptr = np.concatenate(([0], np.cumsum(np.bincount(r, minlength=lo.shape[0]))))
        csr += [ptr, b, lo[r, b], hi[r, b]]
    nx, ny = grid.nx, grid.ny
    maps = np.full((1, nx + 1, ny + 1), grid.out, dtype=np.int64)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    maps[0, :nx, :ny] = i * ny + j
    return DecoupledIMDP(
        grid.n_states,
        np.append(s, grid.out),
        np.append(a, OUT_ACTION),
        *csr,
        maps,
        np.zeros(s.size + 1, dtype=np.int64),
        n_actions=len(ACTIONS),
        labels=grid.labels,
        propositions=grid.propositions,
        initial=initial,
        action_names=ACTIONS,
        tolerance=tolerance,
    )
