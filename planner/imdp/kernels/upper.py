"""Gauss-Seidel passes from above of robust value iteration, compiled: the pass that
lowers an upper bound and checks it superharmonic (:func:`upper_sweep`), and the flags of
its change tracking. They run on the layout of :class:`planner.imdp.kernels.ReachSweeper`
(:mod:`planner.imdp.kernels.sweeps`)."""

from __future__ import annotations

import numba
import numpy as np

from planner.imdp.kernels.rows import scratch, sorted_value, threshold_value

ROUNDING = 1e-15
"""Slack of :func:`upper_sweep`'s check for floating-point rounding."""


@numba.njit(cache=True, nogil=True, inline="always")
def _flag_predecessors(s, inc_ptr, inc_row, row_state, due):
    for e in range(inc_ptr[s], inc_ptr[s + 1]):
        due[row_state[inc_row[e]]] = True


@numba.njit(cache=True, nogil=True)
def flag_predecessors(changed, inc_ptr, inc_row, row_state, due):
    """Flag the predecessors of the states ``changed`` due (values moved outside the
    passes)."""
    for s in changed:
        _flag_predecessors(s, inc_ptr, inc_row, row_state, due)


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
    due,
    inc_ptr,
    inc_row,
    row_state,
    mark_above,
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

    Change tracking (``due`` non-empty, a flag per model state; not with
    ``raise_violations``, and the violations then certify nothing): only the states
    flagged due are evaluated, which clears their flag, and a state whose value falls by
    more than ``mark_above`` flags its predecessors (the states with a row that has it as
    a successor: ``inc_ptr``/``inc_row`` of the model's reverse index, ``row_state``). A
    skipped update is one left out, which keeps ``U`` an upper bound; with
    ``mark_above = 0`` it is one whose inputs did not change since the state's last
    evaluation. Returns ``(max decrease, violations, moved)``, ``moved`` the number of
    states whose value fell by more than ``mark_above``.
    """
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = scratch(row_ptr)
    decrease = 0.0
    violations = 0
    moved = 0
    lazy = lazy and maximize
    width = 1
    if lazy:
        for k in range(states.size):
            width = max(width, state_rows[k + 1] - state_rows[k])
    fresh = np.zeros(width, dtype=np.bool_)
    track = due.size > 0
    for k in range(states.size):
        s = states[k]
        if track:
            if not due[s]:
                continue
            due[s] = False
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
                q = threshold_value(top, row_ptr, remaining, succ, lower, gap, u, sign, crit)
                if q != q:
                    q = sorted_value(
                        top, row_ptr, remaining, succ, lower, gap, u, sign, crit, idx, keys
                    )
                cache[top] = q
                fresh[top - lo] = True
        else:
            for r in range(lo, hi):
                q = threshold_value(r, row_ptr, remaining, succ, lower, gap, u, sign, crit)
                if q != q:
                    q = sorted_value(
                        r, row_ptr, remaining, succ, lower, gap, u, sign, crit, idx, keys
                    )
                if (q > best) if maximize else (q < best):
                    best = q
        old = u[s]
        if best <= old:
            u[s] = best
            if old - best > decrease:
                decrease = old - best
            if old - best > mark_above:
                moved += 1
                if track:
                    _flag_predecessors(s, inc_ptr, inc_row, row_state, due)
        elif best > old + ROUNDING:
            violations += 1
            if raise_violations:
                u[s] = best
    return decrease, violations, moved
