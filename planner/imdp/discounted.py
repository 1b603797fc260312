"""Robust discounted-reward value iteration: ``V(s) = opt_a min/max_p sum_{s'} p(s') (W(s') +
gamma V(s'))``, the reward ``W`` collected on *landing* in a state (docs/design.md).

Jacobi sweeps that tolerate successors out of order by less than ``tolerance / 100``, then
exact sweeps until the residual is small; the bracket is the contraction bound
``||V* - v|| <= gamma / (1 - gamma) * residual`` of an exact sweep (certified: the sweeps
go on until that bound is below ``tolerance / 2``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.errors import SpecificationError
from planner.imdp.model import IMDP
from planner.imdp.ordering import OrderingAdversary
from planner.imdp.problem import ValueIteration


@dataclass
class DiscountedResult:
    """Values ``v``, the bracket ``lower``/``upper``, the last exact sweep's ``residual``,
    the sweeps, the robust value ``q`` of every free row and whether it converged."""

    values: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    residual: float
    iterations: int
    q: np.ndarray
    converged: bool


def discounted_values(
    m: IMDP,
    free_rows: np.ndarray,
    fixed: np.ndarray,
    reward: np.ndarray,
    discount: float,
    adversary_minimizes: bool,
    maximize: bool,
    alg: ValueIteration,
) -> DiscountedResult:
    """Discounted reward of the free states (the ``fixed`` ones hold 0)."""
    rs = m.row_state[free_rows]
    seg = np.flatnonzero(np.concatenate(([True], rs[1:] != rs[:-1]))) if rs.size else rs
    seg_states = rs[seg]
    op = np.maximum if maximize else np.minimum
    full = OrderingAdversary(
        m, adversary_minimizes, rows=free_rows, resort_tolerance=alg.tolerance * 1e-2
    )
    v, residual, it = _start(m, fixed, alg.initial), 0.0, 0
    factor = discount / (1.0 - discount)
    goal = alg.tolerance / (2.0 * factor) if alg.certified and factor > 0 else alg.tolerance
    while free_rows.size and it < alg.max_iterations:
        it += 1
        q_free = full.expectation(reward + discount * v)
        v_new = v.copy()
        v_new[seg_states] = op.reduceat(q_free, seg)
        residual = float(np.max(np.abs(v_new - v)))
        v = v_new
        if alg.callback is not None:
            alg.callback(it, residual)
        if residual < goal:
            if full.resort_tolerance == 0.0:
                break
            full.resort_tolerance = 0.0
    q_free = full.expectation(reward + discount * v) if free_rows.size else np.zeros(0)
    err = np.where(fixed, 0.0, factor * residual)
    converged = bool(residual < goal) and full.resort_tolerance == 0.0
    return DiscountedResult(v, v - err, v + err, residual, it, q_free, converged)


def _start(m: IMDP, fixed: np.ndarray, initial: np.ndarray | None) -> np.ndarray:
    """The first iterate of the sweeps: ``initial`` off the fixed states (which hold 0)."""
    if initial is None:
        return np.zeros(m.n_states)
    start = np.asarray(initial, dtype=np.float64)
    if start.shape != (m.n_states,) or not np.all(np.isfinite(start)):
        raise SpecificationError(
            f"initial values must be a finite array of shape ({m.n_states},), got {start.shape}"
        )
    return np.where(fixed, 0.0, start)
