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
    top,
    other,
    stale,
    top_rows,
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
    evaluation. Returns ``(max decrease, violations, moved, evaluations)``, ``moved`` the
    number of states whose value fell by more than ``mark_above``, ``evaluations`` the rows
    evaluated (lazy).

    Top rows (``top`` non-empty; lazy only): ``top[k]`` is the layout row of the highest
    cached value of the ``k``-th state when the copy was made, ``other[k]`` the highest
    cached value of its other rows then, and ``top_rows = (ptr, remaining, succ, lower,
    gap, crit)`` a contiguous copy of those rows
    (:func:`planner.imdp.kernels.rows.gather_rows`; its ``crit`` is written here from
    ``crit``). A state not flagged in ``stale`` evaluates its top row from the copy, where
    the rows lie in pass order (in the layout they lie scattered, which makes them slow
    to read). Where that value exceeds ``other[k]`` it is the state's maximum: cached
    values only fall, so ``other[k]`` still bounds every other row. Otherwise the state is
    flagged stale and evaluated as without the copy. The value is
    :func:`threshold_value`'s on the same entries in the same order, so the pass gives the
    values it gives without the copy.
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
    use_top = lazy and top.size > 0
    t_ptr, t_rem, t_succ, t_lower, t_gap, t_crit = top_rows
    evaluations = 0
    for k in range(states.size):
        s = states[k]
        if track:
            if not due[s]:
                continue
            due[s] = False
        lo = state_rows[k]
        hi = state_rows[k + 1]
        best = -np.inf if maximize else np.inf
        done = False
        if use_top and not stale[k]:
            r = top[k]
            t_crit[k] = t_ptr[k] + crit[r] - row_ptr[r]
            q = threshold_value(k, t_ptr, t_rem, t_succ, t_lower, t_gap, u, sign, t_crit)
            evaluations += 1
            if q > other[k]:  # never for nan: that row is sorted below
                cache[r] = q
                best = q
                done = True
            else:
                stale[k] = True
        if lazy and not done:
            fresh[: hi - lo] = False
            while True:
                first = lo
                for r in range(lo + 1, hi):
                    # ties go to a fresh row: the maximum is then known
                    if cache[r] > cache[first] or (
                        cache[r] == cache[first] and fresh[r - lo] and not fresh[first - lo]
                    ):
                        first = r
                if fresh[first - lo]:
                    best = cache[first]
                    break
                q = threshold_value(first, row_ptr, remaining, succ, lower, gap, u, sign, crit)
                if q != q:
                    q = sorted_value(
                        first, row_ptr, remaining, succ, lower, gap, u, sign, crit, idx, keys
                    )
                cache[first] = q
                fresh[first - lo] = True
                evaluations += 1
        elif not lazy:
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
    return decrease, violations, moved, evaluations


@numba.njit(cache=True, nogil=True)
def top_of_cache(state_rows, cache):
    """Per state of a layout (rows ``state_rows[k]:state_rows[k + 1]``): the row of its
    highest cached value (the first of equal ones) and the highest value of its other rows
    (``-inf`` for a state with one row)."""
    n = state_rows.size - 1
    top = np.empty(n, dtype=np.int64)
    other = np.full(n, -np.inf)
    for k in range(n):
        lo, hi = state_rows[k], state_rows[k + 1]
        first = lo
        for r in range(lo + 1, hi):
            if cache[r] > cache[first]:
                first = r
        top[k] = first
        for r in range(lo, hi):
            if r != first and cache[r] > other[k]:
                other[k] = cache[r]
    return top, other
