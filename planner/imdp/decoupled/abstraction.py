"""The decoupled abstraction of a grid world from per-row landing-error bounds."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from planner.errors import ModelError
from planner.imdp.decoupled.model import DecoupledIMDP
from planner.imdp.grid import ACTIONS, OUT_ACTION, GridWorld
from planner.imdp.model import BOUND_TOLERANCE
from planner.intervals import TruncatedGaussianNoise, axis_bin_bounds


def grid_decoupled_model(
    grid: GridWorld,
    state: np.ndarray,
    action: np.ndarray,
    error_lower: np.ndarray,
    error_upper: np.ndarray,
    noise: TruncatedGaussianNoise | None = None,
    initial: Iterable[int] = (0,),
    tolerance: float = BOUND_TOLERANCE,
) -> DecoupledIMDP:
    """The decoupled abstraction of ``grid`` from per-row error bounds.

    Args:
        grid: the world.
        state, action: the rows: every enabled (cell, action) pair exactly once.
        error_lower, error_upper: ``(rows, 2)`` bounds of the mean landing error of each
            row, per axis (x, y), metres: the row departs from its cell with that action.
            (Per-cell bounds: index them by ``state``.)
        noise: the per-axis landing noise (default :class:`TruncatedGaussianNoise`).
        initial: initial states.

    Each axis has the bins *below*, the ``n`` columns (rows) and *above*
    (:func:`planner.intervals.axis_bin_bounds`); a pair with a bin outside maps to ``out``,
    which keeps its self-loop. Bins with upper bound 0 are left out.

    Raises:
        ModelError: rows that are not exactly the enabled (cell, action) pairs, or bounds
            of the wrong shape.
    """
    noise = noise or TruncatedGaussianNoise()
    s = np.asarray(state, dtype=np.int64)
    a = np.asarray(action, dtype=np.int64)
    e_lo = np.asarray(error_lower, dtype=np.float64)
    e_hi = np.asarray(error_upper, dtype=np.float64)
    if e_lo.shape != (s.size, 2) or e_hi.shape != (s.size, 2):
        raise ModelError(f"error bounds must have shape ({s.size}, 2)")
    order = np.lexsort((a, s))
    s, a, e_lo, e_hi = s[order], a[order], e_lo[order], e_hi[order]
    want_s, want_a = np.nonzero(grid.enabled[: grid.n_cells])
    if s.size != want_s.size or np.any(s != want_s) or np.any(a != want_a):
        raise ModelError("rows must be every enabled (cell, action) pair exactly once")
    centre = grid.target_centres[s, a]
    axes = []
    for d, n in ((0, grid.nx), (1, grid.ny)):
        lo, hi = axis_bin_bounds(noise, n, grid.cell, centre[:, d], e_lo[:, d], e_hi[:, d])
        lo = np.vstack([lo, np.eye(1, n + 2)])  # out: the "below" bin for sure
        hi = np.vstack([hi, np.eye(1, n + 2)])
        r, b = np.nonzero(hi > 0.0)
        ptr = np.concatenate(([0], np.cumsum(np.bincount(r, minlength=lo.shape[0]))))
        axes += [ptr, b, lo[r, b], hi[r, b]]
    nx, ny = grid.nx, grid.ny
    maps = np.full((1, nx + 2, ny + 2), grid.out, dtype=np.int64)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    maps[0, 1 : nx + 1, 1 : ny + 1] = i * ny + j
    return DecoupledIMDP(
        grid.n_states,
        np.append(s, grid.out),
        np.append(a, OUT_ACTION),
        *axes,
        maps,
        np.zeros(s.size + 1, dtype=np.int64),
        n_actions=len(ACTIONS),
        labels=grid.labels,
        propositions=grid.propositions,
        initial=initial,
        action_names=ACTIONS,
        tolerance=tolerance,
    )
