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
from scipy.sparse.linalg import splu

from planner.imdp import graph
from planner.imdp.kernels import chain_exit_residual, counting_order
from planner.imdp.kernels.chains import exit_matrix, split_chain
from planner.imdp.kernels.layers import layer_distance
from planner.imdp.model import IMDP
from planner.imdp.ordering import OrderingAdversary
from planner.imdp.shown_below import shown_below

ORDER_SLACK = 1e-13
"""Successor values out of order by at most this much do not re-sort the adversary while
it is improved: the accepted values are within ``ORDER_SLACK`` times the row length of
``V_sigma`` (floating-point noise must not keep the adversary iteration going)."""


DUST = 1e-12
"""Probabilities below this are dropped from a chain before it is solved (the float
leftover of an adversary's distribution)."""


def reaching(adj: sp.csr_matrix, seeds: np.ndarray) -> np.ndarray:
    """States with a path (edges ``adj > 0``) to a seed, seeds included: the breadth-first
    layers of the graph analyses (:func:`planner.imdp.kernels.layers.layer_distance`), each
    state its own row, its edges listed by source (``adj``'s rows) and by target
    (:func:`counting_order`)."""
    adj = sp.csr_matrix(adj)
    n = adj.shape[0]
    edge = adj.data > 0
    src = np.repeat(np.arange(n, dtype=np.int64), np.diff(adj.indptr))[edge]
    order, ptr = counting_order(adj.indices[edge].astype(np.int64), n)
    inc = src[order]  # each state is its own row, so an edge's row and state coincide
    forward = (
        np.arange(n + 1, dtype=np.int64),
        adj.indptr.astype(np.int64),
        adj.indices.astype(np.int64),
        adj.data.astype(np.float64),
    )
    seeds = np.asarray(seeds, dtype=bool)
    dist = layer_distance(seeds, np.ones(n, bool), ptr, inc, inc, np.ones(order.size), *forward)
    return np.isfinite(dist)


_REFINE = 4
"""Rounds of iterative refinement of a chain solve (each a double-double residual and a
solve with the same factorisation)."""

_FLOOR = 1e-28
"""The double-double residual's own rounding, per row (values and probabilities in
``[0, 1]``, rows summing to at most 1)."""


_EPS = 4.0 * np.finfo(float).eps
"""Rounding of the residual itself."""

SHARPEN_ABOVE = 1e-11
"""Where the rounding bound lowers a value by more than this, the sharper bound of
:mod:`planner.imdp.shown_below` (checked in exact arithmetic) is tried as well."""

SOLVE_MARGIN = 1e-3
"""Relative margin on a computed bound ``A^-1 rhs`` (the solve's own rounding)."""


class ChainError:
    """Elementwise rounding bounds of a :func:`chain_reach` solve.

    With ``A = I - P`` on the live states (non-singular, ``A^-1 >= 0``) and the residual
    ``r = b - A x`` of the computed ``x`` (double-double, :func:`chain_exit_residual`), the
    error is ``A^-1 r``, so ``|x* - x| <= A^-1 |r|`` elementwise: small where the chain
    leaves the live states fast *or* the values are small, unlike the norm bound
    ``||A^-1 1|| ||r||`` (``1e8`` steps times ``1e-16`` on a slowly mixing chain).

    The chain's probabilities are themselves rounded (an adversary's distribution is
    computed, not exact): the lower bounds and full gaps it hands out are rounded by at most
    ``eps`` relative, the critical entry (the remaining mass, ``1 - sum(l)`` less a prefix
    sum of gaps) by up to ``k eps`` absolute for ``k`` successors, and any mass the rounding
    adds or loses sits on a successor of value at most the row's largest. Each row's
    expectation is therefore taken to be off by up to ``(k + 4) eps`` times the largest
    value among its successors (:func:`row_rounding`), an error of the right-hand side like
    the residual. Both scale with the values, so states that circulate for long among
    states of tiny value keep a tiny bound.
    """

    def __init__(
        self,
        n_states: int,
        live: np.ndarray,
        states: np.ndarray,
        lu,
        residual: np.ndarray,
        rows: sp.csr_matrix | None = None,
        lost: np.ndarray | None = None,
    ) -> None:
        self._n, self._live, self._states = n_states, live, states
        self._lu, self._residual = lu, residual
        """``|r|`` plus the rounding of the rows, one entry per live state."""
        self._rows, self._lost = rows, lost

    @property
    def states(self) -> np.ndarray:
        """The live states solved for (the chain reaches a target from them)."""
        return self._states

    def expected_stay(self) -> np.ndarray | None:
        """``(n_states,)`` expected steps before the chain leaves its live states, ``w =
        A^-1 1`` (0 elsewhere), refined like the values (double-double residuals);
        ``None`` when nothing was solved."""
        if self._lu is None or self._rows is None or self._lost is None:
            return None
        rows, own, lost = self._rows, self._states, self._lost
        indptr, indices = rows.indptr.astype(np.int64), rows.indices.astype(np.int64)
        w = np.zeros(self._n)
        w[own] = self._lu.solve(np.ones(own.size))
        for _ in range(_REFINE):
            r = chain_exit_residual(indptr, indices, rows.data, w, own, lost)
            w[own] += self._lu.solve(r + 1.0)
        return w

    def bound(self, extra: np.ndarray | None = None) -> np.ndarray:
        """``(n_states,)`` bounds of ``|x* - x|`` (0 off the live states), for the system
        whose right-hand side may also be off by ``extra >= 0`` (one entry per row of the
        solved matrix), with a relative margin for the rounding of this solve itself (its
        forward error is at most about ``cond(A) eps`` relative)."""
        out = np.zeros(self._n)
        if self._lu is None:
            return out
        rhs = self._residual * (1.0 + _EPS)
        if extra is not None:
            rhs = rhs + np.maximum(extra[self._live], 0.0)
        out[self._states] = (1.0 + SOLVE_MARGIN) * np.maximum(self._lu.solve(rhs), 0.0)
        return out


def chain_lu(
    sub: sp.spmatrix, orderings: ChainOrderings | None = None, exits: np.ndarray | None = None
):
    """Sparse LU of ``A = I - sub`` for a substochastic ``sub`` (rows summing to at most 1)
    whose chain leaves from every state (``A`` non-singular). ``exits``: each row's mass
    leaving its own state, summed from those entries; the diagonal is then ``exits``
    instead of ``1 - sub_ss`` (which keeps nothing of a leak below ``eps``). ``A`` is
    assembled by :func:`planner.imdp.kernels.chains.exit_matrix` (no row of ``sub`` may
    list a column twice).

    ``A`` is then a non-singular M-matrix, weakly diagonally dominant by rows; Gaussian
    elimination keeps both properties in every Schur complement, so its pivots are positive
    and the growth factor is at most 2 without any pivoting. The factorisation therefore
    keeps the diagonal pivots and a symmetric fill-reducing ordering of ``A + A^T``
    (SuperLU's symmetric mode): on the 100 x 100 benchmark grid's chains about half the
    fill of the default column ordering with partial pivoting, and 1.5-2x faster. Any
    symmetric permutation of ``A`` is again such an M-matrix, so an ordering found for
    one chain serves every chain of the same sparsity pattern (``orderings``:
    :class:`ChainOrderings`).
    """
    sub = sp.csr_matrix(sub)
    if exits is None:
        exits = 1.0 - sub.diagonal()
    if orderings is not None:
        return orderings.factor(sub, exits)
    return _symmetric_lu(_exit_matrix(sub, exits), "MMD_AT_PLUS_A")


def _exit_matrix(sub: sp.csr_matrix, exits: np.ndarray, perm: np.ndarray | None = None):
    """``diag(exits) - sub`` off its diagonal, symmetrically permuted by ``perm`` (old index
    of each new one; none by default), in compressed columns."""
    n = sub.shape[0]
    perm = np.arange(n, dtype=np.int64) if perm is None else perm
    ptr, idx, val = exit_matrix(
        sub.indptr.astype(np.int64),
        sub.indices.astype(np.int64),
        sub.data.astype(np.float64),
        np.asarray(exits, dtype=np.float64),
        perm,
    )
    return sp.csc_matrix((val, idx, ptr), shape=(n, n))


def _symmetric_lu(a: sp.csc_matrix, permc_spec: str):
    return splu(a, permc_spec=permc_spec, diag_pivot_thresh=0.0, options={"SymmetricMode": True})


class _PermutedLU:
    """The LU of ``A[p][:, p]``, solving systems of ``A``."""

    def __init__(self, lu, perm: np.ndarray) -> None:
        self._lu, self._perm = lu, perm

    def solve(self, b: np.ndarray) -> np.ndarray:
        x = np.empty_like(b, dtype=np.float64)
        x[self._perm] = self._lu.solve(b[self._perm])
        return x

    @property
    def fill(self) -> int:
        """``nnz(L + U)`` of the factors."""
        return int(self._lu.L.nnz + self._lu.U.nnz)


class ChainOrderings:
    """The fill-reducing ordering of the last chain factorised, reused for the next chain
    with the same sparsity pattern: the adversary-improvement rounds of one strategy's
    evaluation (:func:`strategy_reach_value`) change the chain's probabilities, not its
    pattern, when every lower bound is positive. The minimum-degree ordering depends on
    the pattern alone, so the factors are those of :func:`chain_lu`, computed without a
    third of its work (the ordering; see ``benchmarks/bench_certified_parts.py``)."""

    def __init__(self) -> None:
        self._pattern: tuple[np.ndarray, np.ndarray] | None = None
        self._perm = np.zeros(0, dtype=np.int64)
        self.reused = 0
        """Factorisations that reused an ordering."""

    def factor(self, sub: sp.csr_matrix, exits: np.ndarray):
        """The LU of :func:`chain_lu` for ``sub`` and ``exits``."""
        a = _exit_matrix(sub, exits)
        pattern = self._pattern
        if (
            pattern is not None
            and np.array_equal(pattern[0], a.indptr)
            and np.array_equal(pattern[1], a.indices)
        ):
            self.reused += 1
            perm = self._perm
            return _PermutedLU(_symmetric_lu(_exit_matrix(sub, exits, perm), "NATURAL"), perm)
        lu = _symmetric_lu(a, "MMD_AT_PLUS_A")
        self._pattern = (a.indptr.copy(), a.indices.copy())
        self._perm = np.empty(a.shape[0], dtype=np.int64)
        self._perm[lu.perm_c] = np.arange(a.shape[0])
        return lu


def chain_reach(
    matrix: sp.csr_matrix,
    states: np.ndarray,
    fixed_val: np.ndarray,
    error: bool = False,
    orderings: ChainOrderings | None = None,
) -> np.ndarray | tuple[np.ndarray, ChainError]:
    """Least solution of ``x_s = sum_j matrix[i, j] x_j`` for ``s = states[i]``.

    The solve is iteratively refined with residuals in double-double arithmetic
    (:mod:`planner.imdp.kernels.exact`): slowly mixing chains are ill-conditioned
    (condition ~ the expected stay), and a plain LU solution can be off by far more than
    its double-precision residual shows.

    Args:
        matrix: ``(len(states), n_states)`` distributions, one row per state of ``states``.
        states: the states being solved for (sorted, distinct).
        fixed_val: ``(n_states,)`` values of all other states (read only there).
        error: also return the elementwise rounding bounds (:class:`ChainError`).
        orderings: reuse the ordering of an earlier chain of the same pattern
            (:class:`ChainOrderings`).

    Returns:
        ``(n_states,)``: ``fixed_val`` outside ``states``, the reachability values on them;
        with ``error``, ``(values, ChainError)``.
    """
    # float dust of the adversary's leftover mass (1e-16) can link a closed class to the
    # target: the class counts as live and ``I - sub`` is singular. Dropping mass below
    # DUST only lowers the least solution, so the value stays a lower bound. Each state's
    # stay on itself is implied by what leaves it (slow leaks keep their relative
    # precision in the matrix and in the residuals); the dust that leaves goes to value 0,
    # not back to the state.
    matrix = sp.csr_matrix(matrix)
    states = np.asarray(states, dtype=np.int64)
    n_states = matrix.shape[1]
    pos = np.full(n_states, -1, dtype=np.int64)
    pos[states] = np.arange(states.size)
    base = np.asarray(fixed_val, dtype=np.float64).copy()
    base[states] = 0.0
    k_ptr, k_idx, k_val, i_ptr, i_idx, i_val, lost, kept, b = split_chain(
        matrix.indptr.astype(np.int64),
        matrix.indices.astype(np.int64),
        matrix.data.astype(np.float64),
        states,
        pos,
        base,
        DUST,
    )
    inner = sp.csr_matrix((i_val, i_idx, i_ptr), shape=(states.size, states.size))
    live = np.flatnonzero(reaching(inner, b > 0))
    out = base
    err = ChainError(base.size, live, states[live], None, np.zeros(0))
    if live.size:
        own = states[live]
        rows, sub = sp.csr_matrix((k_val, k_idx, k_ptr), shape=(states.size, n_states)), inner
        if live.size < states.size:
            rows, sub = rows[live], inner[live][:, live]
        indptr = np.asarray(rows.indptr, dtype=np.int64)
        indices = np.asarray(rows.indices, dtype=np.int64)
        data = rows.data
        lost_live = lost[live]
        lu = chain_lu(sub, orderings, kept[live] + lost_live)
        out[own] = lu.solve(b[live])
        r = chain_exit_residual(indptr, indices, data, out, own, lost_live)
        for _ in range(_REFINE):
            if not np.any(r):
                break
            out[own] += lu.solve(r)
            r_new = chain_exit_residual(indptr, indices, data, out, own, lost_live)
            if np.max(np.abs(r_new)) >= np.max(np.abs(r)):
                r = r_new
                break
            r = r_new
        rounding = row_rounding(indptr, indices, out)
        err = ChainError(base.size, live, own, lu, np.abs(r) + rounding, rows, lost_live)
        out[own] = np.clip(out[own], 0.0, 1.0)
    return (out, err) if error else out


def row_rounding(
    indptr: np.ndarray, indices: np.ndarray, values: np.ndarray, per_entry: float = 1.0
) -> np.ndarray:
    """Per CSR row of distributions: ``(per_entry k + 4) eps`` times the largest
    ``|values|`` of its ``k`` entries, plus the double-double floor. ``per_entry = 1``:
    the rounding of an adversary's computed distribution (:class:`ChainError`); ``3``: of
    a compiled row evaluation as well (its sums of ``k`` products)."""
    lens = np.diff(indptr)
    top = np.zeros(lens.size)
    full = lens > 0
    if indices.size:
        top[full] = np.maximum.reduceat(np.abs(values[indices]), indptr[:-1][full])
    return (per_entry * lens + 4.0) * np.finfo(float).eps * top + _FLOOR


def _settled_chain(
    model: IMDP,
    rows: np.ndarray,
    fixed_val: np.ndarray,
    adversary_minimizes: bool,
    start: np.ndarray,
    max_rounds: int,
) -> tuple[np.ndarray, ChainError | None, np.ndarray] | None:
    """The chain of ``rows`` and the adversary's best response, solved: ``(x, error,
    defect, used)`` (``defect`` the order slack's error of each strategy row that keeps a
    chance of the targets, ``used`` those rows), or ``None`` when the adversary did not
    settle."""
    rows = np.asarray(rows, dtype=np.int64)
    states = model.row_state[rows]
    fixed_val = np.asarray(fixed_val, dtype=np.float64)
    if not adversary_minimizes:
        adv = OrderingAdversary(model, False, rows=rows)
        x, err = chain_reach(adv.matrix(start), states, fixed_val, error=True)
        return x, err, np.zeros(rows.size), rows
    row_mask = np.zeros(model.n_rows, dtype=bool)
    row_mask[rows] = True
    target = fixed_val > 0
    target[states] = False
    pos, _ = graph.robust_positive_reach(model, target, rows=row_mask)
    keep = pos[states]
    base = fixed_val.copy()
    base[states] = 0.0
    if not keep.any():
        return base, None, np.zeros(0), rows[:0]
    rows, states = rows[keep], states[keep]
    adv = OrderingAdversary(model, True, rows=rows, resort_tolerance=ORDER_SLACK)
    x = np.where(pos, start, base)
    orderings = ChainOrderings()
    for _ in range(max_rounds):
        matrix = adv.matrix(x)
        sorts = adv.n_sorts
        x, err = chain_reach(matrix, states, base, error=True, orderings=orderings)
        adv.update(x)
        if adv.n_sorts == sorts:
            # the accepted order may miss the exact minimiser by the slack: its defect at
            # x is an error of the right-hand side, like the solve's residual (the exact
            # order: the accepted one, re-sorted where any successors are out of order)
            accepted = matrix @ x
            adv.resort_tolerance = 0.0
            return x, err, np.maximum(accepted - adv.expectation(x), 0.0), rows
    return None


def strategy_reach_value(
    model: IMDP,
    rows: np.ndarray,
    fixed_val: np.ndarray,
    adversary_minimizes: bool,
    start: np.ndarray,
    max_rounds: int = 50,
    sound: bool = True,
) -> tuple[np.ndarray, np.ndarray] | None:
    """``V_sigma`` of the strategy that plays ``rows`` (one row per free state, sorted),
    lowered state by state by the error bound of its computation (``A^-1`` applied to the
    solve's residual plus the order slack's defect; see :class:`ChainError`) so that it
    is a lower bound despite rounding.

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
        ``(values, computed)``: the ``(n_states,)`` values and the computed values they
        lowered (equal without ``sound``; strategy iteration decides by the computed
        ones), or ``None`` when the adversary did not settle within
        ``max_rounds`` (no bound is then claimed).
    """
    out = _settled_chain(model, rows, fixed_val, adversary_minimizes, start, max_rounds)
    if out is None:
        return None
    x, err, defect, used = out
    if err is None or not sound:
        return x.copy(), x
    # rounded down: the subtraction itself must not round above the bound
    low = np.maximum(np.nextafter(x - err.bound(defect), -np.inf), 0.0)
    worst = float(np.max(x - low))
    if worst > SHARPEN_ABOVE:
        shown = shown_below(model, used, x, err, adversary_minimizes, worst)
        if shown is not None:
            low = np.maximum(low, shown)
    return low, x
