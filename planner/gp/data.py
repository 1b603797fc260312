"""Checks of the data of the landing-error model (:mod:`planner.gp.landing`): training
hops and query points, in metres; each failure a :class:`~planner.errors.GPDataError` that
names the array and the first bad row."""

from __future__ import annotations

import numpy as np

from planner.errors import GPDataError


def check_hops(
    positions: np.ndarray, errors: np.ndarray, actions: np.ndarray, n_actions: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``positions`` (N, 2) and ``errors`` (N, 2) as finite float64 arrays, ``actions`` (N,)
    as int64 indices in ``[0, n_actions)``."""
    pos = np.asarray(positions, dtype=np.float64)
    err = np.asarray(errors, dtype=np.float64)
    act = np.asarray(actions)
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise GPDataError(f"positions must have shape (N, 2), got {pos.shape}")
    if err.shape != pos.shape:
        raise GPDataError(f"errors must have shape {pos.shape} like positions, got {err.shape}")
    if act.shape != (pos.shape[0],):
        raise GPDataError(f"actions must have shape ({pos.shape[0]},), got {act.shape}")
    if act.size and (act.dtype.kind not in "iu" or act.min() < 0 or act.max() >= n_actions):
        bad = np.flatnonzero((act < 0) | (act >= n_actions) | (act != np.round(act)))
        row = int(bad[0]) if bad.size else 0
        raise GPDataError(
            f"actions must be integers in [0, {n_actions}), got {act[row]!r} in row {row}"
        )
    for name, arr in (("positions", pos), ("errors", err)):
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        if bad.size:
            raise GPDataError(f"{name} has non-finite values in row {int(bad[0])}")
    return pos, err, act.astype(np.int64)


def check_points(points: np.ndarray) -> np.ndarray:
    """Query ``points`` (M, 2) as a finite float64 array."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise GPDataError(f"points must have shape (M, 2), got {pts.shape}")
    if not np.isfinite(pts).all():
        raise GPDataError("points has non-finite values")
    return pts
