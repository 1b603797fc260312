"""Gauss-Seidel sweeps of robust value iteration, compiled, and the sweep-ordered layout
they run on (:class:`ReachSweeper`).

A Gauss-Seidel sweep is sequential by nature: every state's update reads the values that
the states before it in the sweep have just written. Array operations can only do that
layer by layer (Jacobi inside a layer); these kernels do it state by state.

Layout (built by :class:`ReachSweeper`): the free states in sweep order, their rows
(``state_rows[k]:state_rows[k + 1]`` are the rows of the ``k``-th state) and, per row, its
entries (:mod:`planner.imdp.kernels.rows`).
"""

from __future__ import annotations

import numba
import numpy as np

from planner.imdp.kernels.rows import all_row_values, gather_rows, row_value, scratch
from planner.imdp.model import IMDP, first_of_runs, row_entries


@numba.njit(cache=True, nogil=True)
def gauss_seidel_sweep(
    states,
    state_rows,
    row_ptr,
    remaining,
    succ,
    lower,
    gap,
    crit,
    v,
    best_row,
    full,
    maximize,
    adversary_minimizes,
) -> float:
    """One Gauss-Seidel sweep of ``V(s) <- max(V(s), opt_a min/max_p sum p V)`` over
    ``states`` in order, in place; returns ``max_s`` of the change.

    ``opt`` is max (``maximize``) or min over the state's rows; the adversary minimises
    (``adversary_minimizes``) or maximises. Each update reads the values written earlier in
    the same sweep. ``full``: every row is evaluated and ``best_row[k]`` records the optimal
    one; otherwise only the row ``best_row[k]`` is (a modified-policy-iteration sweep: for
    a maximising strategy its update is at most the full one). Iterating from below
    (``V_0 <= T(V_0)``) every update is at most the least fixed point, so the values stay a
    sound lower bound.
    """
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = scratch(row_ptr)
    residual = 0.0
    for k in range(states.size):
        s = states[k]
        if full:
            lo = state_rows[k]
            hi = state_rows[k + 1]
        else:
            lo = best_row[k]
            hi = lo + 1
        best = -np.inf if maximize else np.inf
        arg = lo
        for r in range(lo, hi):
            q = row_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys)
            if (q > best) if maximize else (q < best):
                best = q
                arg = r
        if full:
            best_row[k] = arg
        old = v[s]
        if best > old:
            v[s] = best
            if best - old > residual:
                residual = best - old
    return residual


ROUNDING = 1e-15
"""Slack of :func:`upper_sweep`'s check for floating-point rounding."""


@numba.njit(cache=True, nogil=True)
def upper_sweep(
    states,
    state_rows,
    row_ptr,
    remaining,
    succ,
    lower,
    gap,
    crit,
    u,
    maximize,
    adversary_minimizes,
    raise_violations,
    cache,
    lazy,
):
    """One Gauss-Seidel pass of ``U(s) <- T(U)(s)`` from above, in place, that only ever
    lowers ``U``: a state whose Bellman value exceeds ``U(s)`` keeps ``U(s)`` and counts as
    a violation (``raise_violations``: it takes the Bellman value, still counting as a
    violation; the pass is then a candidate's repair, not a bound). Returns
    ``(max decrease, violations)``.

    A value above ``U(s)`` by at most ``ROUNDING`` (1e-15, floating-point noise of the
    row sums) keeps ``U(s)`` without counting.
    A pass with no violation certifies the final ``U`` as superharmonic, ``T(U) <= U``:
    each state's value was computed from values at least the final ones (they only
    decrease) and ``T`` is monotone. For reachability every superharmonic ``U`` (with the
    targets at 1) is at least the least fixed point, i.e. an upper bound of the values.

    ``lazy`` (maximising strategy only): ``cache[r]`` holds, per layout row, a value the
    row had at an earlier ``U`` (``inf`` before its first evaluation). Between passes
    ``U`` must only decrease; the row values, monotone in ``U``, then only decrease too, so
    a cached value bounds the row's current one from above, and a state's rows are
    evaluated highest cache first until a freshly evaluated value is at least every
    cached one left: the same maximum as evaluating every row (up to the row rounding
    the checks already allow), mostly at the cost of one row.
    """
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = scratch(row_ptr)
    decrease = 0.0
    violations = 0
    lazy = lazy and maximize
    width = 1
    if lazy:
        for k in range(states.size):
            width = max(width, state_rows[k + 1] - state_rows[k])
    fresh = np.zeros(width, dtype=np.bool_)
    for k in range(states.size):
        s = states[k]
        lo = state_rows[k]
        hi = state_rows[k + 1]
        best = -np.inf if maximize else np.inf
        if lazy:
            fresh[: hi - lo] = False
            while True:
                top = lo
                for r in range(lo + 1, hi):
                    # ties go to a fresh row: the maximum is then known
                    if cache[r] > cache[top] or (
                        cache[r] == cache[top] and fresh[r - lo] and not fresh[top - lo]
                    ):
                        top = r
                if fresh[top - lo]:
                    best = cache[top]
                    break
                cache[top] = row_value(
                    top, row_ptr, remaining, succ, lower, gap, u, sign, crit, idx, keys
                )
                fresh[top - lo] = True
        else:
            for r in range(lo, hi):
                q = row_value(r, row_ptr, remaining, succ, lower, gap, u, sign, crit, idx, keys)
                if (q > best) if maximize else (q < best):
                    best = q
        old = u[s]
        if best <= old:
            u[s] = best
            if old - best > decrease:
                decrease = old - best
        elif best > old + ROUNDING:
            violations += 1
            if raise_violations:
                u[s] = best
    return decrease, violations


class ReachSweeper:
    """The compact, sweep-ordered layout of the free rows of a model, and its sweeps.

    Full sweeps evaluate every row and record each state's best row; light sweeps
    evaluate only those rows, from a contiguous copy made after the last full sweep (the
    best rows lie scattered in the full layout, which makes them slow to read).

    Args:
        model: the interval MDP.
        free_rows: the rows the strategy may use at the free states (sorted).
        sweep_key: ``(n_states,)`` sort key of the states; sweeps visit the free states in
            increasing key (ties by index).
        maximize: the strategy maximises (else minimises) over rows.
        adversary_minimizes: the adversary minimises (else maximises) the expectation.
    """

    def __init__(
        self,
        model: IMDP,
        free_rows: np.ndarray,
        sweep_key: np.ndarray,
        maximize: bool,
        adversary_minimizes: bool,
    ) -> None:
        m = model
        rs = m.row_state[free_rows]
        order = np.lexsort((free_rows, sweep_key[rs]))
        self._position = order
        rows = free_rows[order]
        self.rows = rows
        """The model row of every row of the layout."""
        rs = rs[order]
        first = first_of_runs(rs)
        self.states = rs[first].astype(np.int64)
        """The free states in sweep order."""
        self.state_rows = np.append(first, rows.size).astype(np.int64)
        ent = row_entries(m, rows)
        lens = m.row_ptr[rows + 1] - m.row_ptr[rows]
        self.row_ptr = np.concatenate(([0], np.cumsum(lens))).astype(np.int64)
        self.remaining = 1.0 - m.row_lower_sum[rows]
        self.succ = m.successor[ent].astype(np.int64)
        self.lower = m.lower[ent].astype(np.float64)
        self.gap = m.upper[ent] - self.lower
        self.crit = self.row_ptr[:-1].copy()
        self.crit_up = self.crit.copy()
        self.best_row = self.state_rows[:-1].copy()
        self.maximize = bool(maximize)
        self.adversary_minimizes = bool(adversary_minimizes)
        self._one_row = np.arange(self.states.size + 1, dtype=np.int64)
        self._light: tuple[np.ndarray, ...] | None = None
        self._light_rows = self.best_row
        self._no_cache = np.empty(0)

    def sweep(self, v: np.ndarray, full: bool = True) -> float:
        """One Gauss-Seidel sweep on ``v`` in place (see :func:`gauss_seidel_sweep`): all
        rows (``full``) or the best rows of the last full sweep."""
        if full or self._light is None:
            residual = gauss_seidel_sweep(
                self.states,
                self.state_rows,
                self.row_ptr,
                self.remaining,
                self.succ,
                self.lower,
                self.gap,
                self.crit,
                v,
                self.best_row,
                True,
                self.maximize,
                self.adversary_minimizes,
            )
            if self._light is None or not np.array_equal(self.best_row, self._light_rows):
                self._light_rows = self.best_row.copy()
                self._light = gather_rows(
                    self.best_row,
                    self.row_ptr,
                    self.remaining,
                    self.succ,
                    self.lower,
                    self.gap,
                    self.crit,
                )
            return float(residual)
        row_ptr, remaining, succ, lower, gap, crit = self._light
        return float(
            gauss_seidel_sweep(
                self.states,
                self._one_row,
                row_ptr,
                remaining,
                succ,
                lower,
                gap,
                crit,
                v,
                self._one_row,
                False,
                self.maximize,
                self.adversary_minimizes,
            )
        )

    def upper_cache(self) -> np.ndarray:
        """A fresh row cache for lazy passes of :meth:`upper_pass` (every row unknown)."""
        return np.full(self.rows.size, np.inf)

    def upper_pass(
        self, u: np.ndarray, raise_violations: bool = False, cache: np.ndarray | None = None
    ) -> tuple[float, int]:
        """One pass of :func:`upper_sweep` on ``u`` in place: ``(max decrease,
        violations)``. With a ``cache`` (:meth:`upper_cache`; maximising strategies) the
        pass is lazy: ``u`` must not have increased anywhere since the last pass with that
        cache."""
        lazy = cache is not None
        dec, bad = upper_sweep(
            self.states,
            self.state_rows,
            self.row_ptr,
            self.remaining,
            self.succ,
            self.lower,
            self.gap,
            self.crit_up,
            u,
            self.maximize,
            self.adversary_minimizes,
            raise_violations,
            cache if lazy else self._no_cache,
            lazy,
        )
        return float(dec), int(bad)

    def row_values(self, v: np.ndarray) -> np.ndarray:
        """The robust expectation of ``v`` for every free row, in the order of the
        ``free_rows`` given to the constructor."""
        q = all_row_values(
            self.row_ptr,
            self.remaining,
            self.succ,
            self.lower,
            self.gap,
            self.crit,
            v,
            self.adversary_minimizes,
        )
        out = np.empty_like(q)
        out[self._position] = q
        return out
