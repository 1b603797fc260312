"""Exact reachability values of a fixed strategy (policy evaluation by sparse solves).

For a memoryless strategy ``sigma`` (one row per state) and a fixed adversary (one
distribution ``P`` per row) the probability ``x`` of reaching the states of positive
fixed value ``c`` (targets: ``c = 1``) is the *least* solution of ``x = P x + P c``: zero
on the states that cannot reach them in the graph of ``P > 0``, and on the rest the unique
solution of the non-singular system ``(I - P_SS) x_S = (P c)_S``.

:func:`strategy_reach_value` computes ``V_sigma``, the value of ``sigma`` against the
optimal adversary:

* an adversary that *maximises* cooperates with the strategy, so the chain of
  ``sigma`` and any one adversary is a lower bound of the (maximal) value;
* an adversary that *minimises*: first the states where it can force probability 0
  (graph analysis: outside the robust attractor of the targets under ``sigma``) get 0;
  on the rest the minimising Bellman operator of ``sigma`` has a unique fixed point, which
  adversary-side policy iteration reaches: evaluate the chain of the current adversary,
  re-sort the ordering adversary for those values, repeat until the order stands.

Both give values ``x`` with ``x <= T(x)`` and ``x`` at most the least fixed point of
maximal reachability, so value iteration may continue from ``max(v, x)``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order
from scipy.sparse.linalg import splu

from planner.imdp import graph
from planner.imdp.model import IMDP
from planner.imdp.ordering import OrderingAdversary

ORDER_SLACK = 1e-13
"""Successor values out of order by at most this much do not re-sort the adversary while
it is improved: the accepted values are within ``ORDER_SLACK`` times the row length of
``V_sigma`` (floating-point noise must not keep the adversary iteration going)."""


_DUST = 1e-12


def reaching(adj: sp.csr_matrix, seeds: np.ndarray) -> np.ndarray:
    """States with a path (edges ``adj > 0``) to a seed, seeds included."""
    k = adj.shape[0]
    rev = (adj > 0).T.tocsr().astype(np.int8)
    src = np.flatnonzero(seeds)
    ext = sp.bmat(
        [
            [rev, sp.csr_matrix((k, 1), dtype=np.int8)],
            [sp.csr_matrix((np.ones(src.size, np.int8), (np.zeros_like(src), src)), (1, k)), None],
        ],
        format="csr",
    )
    out = np.zeros(k + 1, dtype=bool)
    out[breadth_first_order(ext, k, directed=True, return_predecessors=False)] = True
    return out[:k]


def chain_reach(
    matrix: sp.csr_matrix, states: np.ndarray, fixed_val: np.ndarray, error: bool = False
) -> np.ndarray | tuple[np.ndarray, float, float]:
    """Least solution of ``x_s = sum_j matrix[i, j] x_j`` for ``s = states[i]``.

    Args:
        matrix: ``(len(states), n_states)`` distributions, one row per state of ``states``.
        states: the states being solved for (sorted, distinct).
        fixed_val: ``(n_states,)`` values of all other states (read only there).
        error: also return the rounding bound: with ``A = I - P`` on the live states
            (non-singular, ``A^-1 >= 0``) and the residual ``r = A x - b`` of the computed
            ``x``, the error ``A^-1 r`` is at most ``||A^-1 1||_inf ||r||_inf``; the second
            solve (``A^-1 1``: expected steps before the chain leaves the live states)
            reuses the factorisation.

    Returns:
        ``(n_states,)``: ``fixed_val`` outside ``states``, the reachability values on them;
        with ``error``, ``(values, steps, residual)``.
    """
    # float dust of the adversary's leftover mass (1e-16) can link a closed class to the
    # target: the class counts as live and ``I - sub`` is singular. Dropping mass below
    # _DUST only lowers the least solution, so the value stays a lower bound.
    matrix = sp.csr_matrix(matrix, copy=True)
    matrix.data[matrix.data < _DUST] = 0.0
    matrix.eliminate_zeros()
    base = np.asarray(fixed_val, dtype=np.float64).copy()
    base[states] = 0.0
    b = matrix @ base
    inner = matrix[:, states].tocsr()
    inner.eliminate_zeros()
    live = np.flatnonzero(reaching(inner, b > 0))
    out = base
    steps = resid = 0.0
    if live.size:
        sub = inner[live][:, live]
        a = (sp.identity(live.size, format="csc") - sub).tocsc()
        lu = splu(a)
        x = lu.solve(b[live])
        if error:
            steps = float(np.max(np.abs(lu.solve(np.ones(live.size)))))
            resid = float(np.max(np.abs(a @ x - b[live])))
        out[states[live]] = np.clip(x, 0.0, 1.0)
    return (out, steps, resid) if error else out


def strategy_reach_value(
    model: IMDP,
    rows: np.ndarray,
    fixed_val: np.ndarray,
    adversary_minimizes: bool,
    start: np.ndarray,
    max_rounds: int = 50,
    sound: bool = True,
) -> np.ndarray | None:
    """``V_sigma`` of the strategy that plays ``rows`` (one row per free state, sorted),
    lowered by the error bound of its computation (the solve's residual and the order
    slack, each times the expected steps; see :func:`chain_reach`) so that it is a lower
    bound despite rounding.

    Args:
        model: the interval MDP.
        rows: the strategy's row of every free state, in increasing order.
        fixed_val: ``(n_states,)`` values of the states without a row in ``rows``
            (``> 0`` marks the targets).
        adversary_minimizes: the adversary's side (see the module docstring).
        start: values that seed the adversary's order.
        max_rounds: adversary improvement rounds before giving up.
        sound: lower the values by the error bound (default). ``False``: the computed
            values as they are, a *candidate* only (e.g. for an upper bound that is then
            checked), not a bound.

    Returns:
        ``(n_states,)`` values, or ``None`` when the adversary did not settle within
        ``max_rounds`` (no bound is then claimed).
    """
    rows = np.asarray(rows, dtype=np.int64)
    states = model.row_state[rows]
    fixed_val = np.asarray(fixed_val, dtype=np.float64)
    if not adversary_minimizes:
        adv = OrderingAdversary(model, False, rows=rows)
        x, steps, resid = chain_reach(adv.matrix(start), states, fixed_val, error=True)
        return _lowered(x, states, steps * (resid + _EPS) if sound else 0.0)
    row_mask = np.zeros(model.n_rows, dtype=bool)
    row_mask[rows] = True
    target = fixed_val > 0
    target[states] = False
    pos, _ = graph.robust_positive_reach(model, target, rows=row_mask)
    keep = pos[states]
    base = fixed_val.copy()
    base[states] = 0.0
    if not keep.any():
        return base
    rows, states = rows[keep], states[keep]
    adv = OrderingAdversary(model, True, rows=rows, resort_tolerance=ORDER_SLACK)
    x = np.where(pos, start, base)
    for _ in range(max_rounds):
        matrix = adv.matrix(x)
        sorts = adv.n_sorts
        x, steps, resid = chain_reach(matrix, states, base, error=True)
        adv.update(x)
        if adv.n_sorts == sorts:
            # the accepted order may miss the exact minimiser by the slack: its defect at
            # x, like the solve's residual, costs at most ``steps`` times itself
            exact = OrderingAdversary(model, True, rows=rows).expectation(x)
            defect = float(np.max(matrix @ x - exact, initial=0.0))
            margin = steps * (resid + max(defect, 0.0) + _EPS)
            return _lowered(x, states, margin if sound else 0.0)
    return None


_EPS = 4.0 * np.finfo(float).eps
"""Rounding of the residual itself."""


def _lowered(x: np.ndarray, states: np.ndarray, margin: float) -> np.ndarray:
    out = x.copy()
    out[states] = np.maximum(x[states] - margin, 0.0)
    return out
