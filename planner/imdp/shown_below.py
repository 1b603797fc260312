"""A lower bound of a strategy's value shown in exact arithmetic, for chains that stay long.

Strategy evaluation lowers its computed values ``x`` by a bound of their rounding
(:class:`planner.imdp.evaluate.ChainError`) that grows with the expected stay ``w``: about
``w (k + 4) eps`` times the values, since each row's computed distribution may be off by
that much per step. A state that keeps ``1 - 1e-7`` on itself then loses 1e-8 and the
bracket of a slow leak stays open at the default tolerance.

Here the candidate is ``L = x - delta w`` (``w = A^-1 1``, refined) and the claim is
checked, not estimated: every row ``r`` of the strategy ``sigma`` at a state ``s`` of the
chain's live set ``R`` gets a lower bound of the exact ``T_r(L) - L(s)`` in the difference
form of :mod:`planner.imdp.kernels.verify` (the adversary's greedy vertex at ``L``, shown
feasible exactly; a self-loop contributes exactly 0, so a slow leak adds no rounding per
step). If every bound is ``>= 0``, then ``L <= T_sigma(L)`` on ``R``; ``L`` is then a
sub-martingale along every run under ``sigma`` and the adversary (every adversary when it
minimises, the greedy vertex's choice when it maximises) until the run leaves ``R``, which
it does almost surely (every state of ``R`` reaches a target with positive probability
under every adversary, through ``R``); where it leaves to, ``L`` is a target's 1 or a
fixed value at most the true one. So ``L(s) <= V_sigma(s) <= V*(s)`` on ``R``. The
``delta`` starts at four times the check's noise at ``x`` and is raised sixteenfold while
the check fails (the rounding of ``L`` itself matters where neighbouring values differ by
ulps), up to the lowering the rounding bound already gives; nothing is claimed if it never
passes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from planner.imdp import graph
from planner.imdp.kernels.verify import row_deficits
from planner.imdp.model import IMDP

if TYPE_CHECKING:
    from planner.imdp.evaluate import ChainError

_TRIES = 8
"""Candidates ``delta, 16 delta, ..., 16**7 delta`` checked before giving up (the first
from the check's noise at ``x``; the rounding of ``L`` itself may need more where values
differ by ulps)."""

_FLOOR = 1e-300
"""The least ``delta`` (the check's noise may be exactly 0)."""


def shown_below(
    model: IMDP,
    rows: np.ndarray,
    x: np.ndarray,
    err: ChainError,
    adversary_minimizes: bool,
    worst: float = np.inf,
) -> np.ndarray | None:
    """``(n_states,)`` values ``L`` with ``L <= V_sigma`` shown (see the module docstring)
    on the live states of the chain, ``x`` elsewhere (where ``x`` holds the fixed values
    and 0), or ``None`` when the check did not pass.

    Args:
        model: the interval MDP.
        rows: the strategy's row of each state of the chain (one per state, sorted).
        x: the chain's computed values (``(n_states,)``).
        err: the chain's :class:`ChainError` (its live states, factorisation and rows).
        adversary_minimizes: the adversary's side.
        worst: the largest lowering not worth trying (the rounding bound's, which the
            caller has already).
    """
    w = err.expected_stay()
    if w is None:
        return None
    live = err.states
    row_of = np.full(model.n_states, -1, dtype=np.int64)
    row_of[model.row_state[rows]] = rows
    if not adversary_minimizes:
        # a cooperating adversary's chain may reach the targets only by its own choices:
        # claim only where every adversary gives a chance of them
        mask = np.zeros(model.n_rows, dtype=bool)
        mask[rows] = True
        target = x > 0
        target[model.row_state[rows]] = False
        pos, _ = graph.robust_positive_reach(model, target, rows=mask)
        live = live[pos[live]]
    sel = row_of[live]
    if live.size == 0 or np.any(sel < 0) or not np.all(np.isfinite(w[live])):
        return None
    m = model
    args = (sel, m.row_state, m.row_ptr, m.successor, m.lower, m.upper)
    base = x.copy()
    base[err.states] = 0.0  # a live state outside the claim counts as 0
    base[live] = x[live]
    noise = max(0.0, -float(np.min(row_deficits(*args, base, adversary_minimizes))))
    delta = 4.0 * noise + _FLOOR
    top = float(np.max(w[live]))
    for _ in range(_TRIES):
        if delta * top > worst:
            break  # no better than the rounding bound already in hand
        cand = base.copy()
        cand[live] = np.maximum(np.nextafter(x[live] - delta * w[live], -np.inf), 0.0)
        if np.min(row_deficits(*args, cand, adversary_minimizes)) >= 0.0:
            return cand
        delta *= 16.0
    return None
