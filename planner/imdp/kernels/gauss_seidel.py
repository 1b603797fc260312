"""The Gauss-Seidel sweep of robust value iteration from below, compiled
(:func:`gauss_seidel_sweep`), on the layout of :class:`planner.imdp.kernels.sweeps.ReachSweeper`.

A Gauss-Seidel sweep is sequential by nature: every state's update reads the values that
the states before it in the sweep have just written. Array operations can only do that
layer by layer (Jacobi inside a layer); this kernel does it state by state.
"""

from __future__ import annotations

import numba
import numpy as np

from planner.imdp.kernels.elimination import SKIP_MARGIN, rise_bound
from planner.imdp.kernels.rows import (
    below,
    feasible_bound,
    scratch,
    sort_critical,
    sorted_value,
    threshold_value,
)


@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
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
    maximize,
    adversary_minimizes,
    bound,
    qbase,
    qmax,
    last,
    c_now,
    light,
    light_rows,
    light_off,
    bounded,
) -> float:
    """One Gauss-Seidel sweep of ``V(s) <- max(V(s), opt_a min/max_p sum p V)`` over
    ``states`` in order, in place; returns ``max_s`` of the change.

    ``opt`` is max (``maximize``) or min over the state's rows; the adversary minimises
    (``adversary_minimizes``) or maximises. Each update reads the values written earlier in
    the same sweep. Every row is evaluated and ``best_row[k]`` records the optimal one (the
    light sweeps between full ones, which evaluate only those rows, are
    :func:`light_sweep`). Iterating from below
    (``V_0 <= T(V_0)``) every update is at most the least fixed point, so the values stay a
    sound lower bound; each update is lowered by its rounding bound
    (:func:`planner.imdp.kernels.rows.below`) so that this holds in floating point too.
    Compiled with reassociation allowed (``fastmath={"reassoc"}``, no other fast-math
    assumption: the ``nan`` of a moved critical successor is still tested): the row sums
    then run as parallel partial sums, 25-30 % faster on the 100 x 100 benchmark grid's
    rows of 9-25 entries, and that rounding bound holds for any order of the sums.

    ``bound`` (a maximising strategy; empty: none): per layout row a value
    at least the row's value at every ``V`` swept (the row cache of the passes from above,
    :func:`upper_sweep`, which holds row values at upper bounds). The last best row is
    evaluated first, and a row whose bound is below the best value found so far is skipped:
    it can neither beat nor tie it, so values and best rows are those of the full sweep
    (action elimination).

    ``qbase`` (a maximising strategy; empty: none) does the same without a bound from
    above (:mod:`planner.imdp.kernels.elimination`): per layout row its value when last
    evaluated less ``c_now`` then, where ``c_now`` (kept by :meth:`ReachSweeper.sweep`)
    sums every sweep's residual and every rise of the values between sweeps; a row whose
    ``qbase + rise_bound(c_now) + r`` (``r`` this sweep's residual so far) is below the
    best value found so far is skipped. ``qmax`` (with ``qbase``) holds per state the
    largest ``qbase`` of its rows other than the best: when ``qmax + rise_bound(c_now) +
    r`` is below the best row's value, every other row would be skipped, and none is
    looked at (late in a solve most states; the same values and best rows). ``last``
    (empty: none) receives every value written, for the rise between sweeps.

    ``bounded`` (with ``qbase``, against the minimising adversary; empty: none), a flag
    per layout row: a row whose critical successor moved is not sorted when a feasible
    distribution around its stale threshold (:func:`feasible_bound`, one pass) shows it
    below the best found so far by ``SKIP_MARGIN``; its bound becomes its ``qbase`` and
    the row is flagged, and while flagged the next sweeps try that bound first (one pass)
    and evaluate the row exactly only where it no longer skips it. A skipped row cannot
    beat or tie the best, so values and best rows are those of the sweep without skipping.

    A row whose critical successor moved is sorted for the new one only
    (:func:`sort_critical`, no sorted sum) and evaluated by :func:`threshold_value` there,
    so that every row value comes from the one formula compiled here: a row's value then
    does not depend on whether its stored critical successor still stood or was found
    anew, so sweeps that skip rows (leaving theirs stale) give the values of sweeps that
    do not, to the last bit. Only where that evaluation fails at the edges of rounding
    does :func:`sorted_value` give the sorted sum (it sums in another order, and as a
    function called from several kernels its compiled variant depends on which was called
    first).

    ``light`` (``light_rows`` empty: none): the contiguous copy of one row
    per state that light sweeps read (:func:`planner.imdp.kernels.rows.gather_rows`), its
    slot ``k + light_off`` a copy of the row ``light_rows[k]`` (``-1``: none yet). That row
    is evaluated from the copy and its critical successor copied back: the full layout
    holds a state's rows side by side, so its best rows lie scattered there, and on the
    random 100k-state benchmark model a late full sweep read them at 4.4x the cost of a
    light sweep (12 ms against 2.7 ms, one thread; 4-5 ms from the copy). A state whose
    best row changed copies the new one into its slot while it is in cache, where the
    lengths agree (``light_rows[k]`` then names it), else marks the slot ``-1`` (the
    caller gathers the copy anew): after the sweep the copy holds every state's best row
    with its critical successor, as a fresh gather would, without a pass over the
    scattered rows (on the random model that pass took 5-11 ms on one thread after the
    first two full sweeps).
    """
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = scratch(row_ptr)
    residual = 0.0
    has_bound = bound.size > 0
    has_base = qbase.size > 0
    has_top = has_base and qmax.size > 0
    l_ptr, l_rem, l_succ, l_lower, l_gap, l_crit = light
    prune = maximize and (has_bound or has_base)
    bound_skip = bounded.size > 0 and adversary_minimizes and has_base
    track = last.size > 0
    has_light = light_rows.size > 0
    for k in range(states.size):
        s = states[k]
        lo = state_rows[k]
        hi = state_rows[k + 1]
        best = -np.inf if maximize else np.inf
        arg = lo
        lrow = light_rows[k] if has_light else -1
        lq = 0.0
        j = k + light_off
        if lrow >= 0:
            # the last best row from its contiguous copy (the full layout lies scattered),
            # its critical successor copied back
            lq = threshold_value(j, l_ptr, l_rem, l_succ, l_lower, l_gap, v, sign, l_crit)
            if lq != lq:
                sort_critical(j, l_ptr, l_rem, l_succ, l_gap, v, sign, l_crit, idx, keys)
                lq = threshold_value(j, l_ptr, l_rem, l_succ, l_lower, l_gap, v, sign, l_crit)
                if lq != lq:
                    lq = sorted_value(
                        j, l_ptr, l_rem, l_succ, l_lower, l_gap, v, sign, l_crit, idx, keys
                    )
            crit[lrow] = row_ptr[lrow] + l_crit[j] - l_ptr[j]
        if prune and hi - lo > 1:
            # the last best row first; a row whose bound is below the best so far can
            # neither beat nor tie it
            arg = best_row[k]
            if arg == lrow:
                best = lq
            else:
                best = threshold_value(arg, row_ptr, remaining, succ, lower, gap, v, sign, crit)
                if best != best:
                    sort_critical(arg, row_ptr, remaining, succ, gap, v, sign, crit, idx, keys)
                    best = threshold_value(arg, row_ptr, remaining, succ, lower, gap, v, sign, crit)
                    if best != best:
                        best = sorted_value(
                            arg, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys
                        )
            rise = rise_bound(c_now) + residual
            if has_base:
                qbase[arg] = best - c_now
            # every other row skipped at once: none of their qbase reaches the best
            rows_left = not (has_top and qmax[k] + rise < best)
            for r in range(lo, hi if rows_left else lo):
                if r == arg or (has_bound and bound[r] < best):
                    continue
                if has_base and qbase[r] + rise < best:
                    continue
                # a row skipped by its bound before keeps a stale critical successor:
                # its threshold is not tried, its bound comes first
                if bound_skip and bounded[r]:
                    q = np.nan
                else:
                    q = threshold_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit)
                if q != q:
                    if bound_skip:
                        q = feasible_bound(r, row_ptr, remaining, succ, lower, gap, v, crit)
                        if q + SKIP_MARGIN < best:
                            # a feasible distribution shows it below the best: not sorted
                            bounded[r] = True
                            qbase[r] = q + SKIP_MARGIN - c_now
                            continue
                        bounded[r] = False
                    sort_critical(r, row_ptr, remaining, succ, gap, v, sign, crit, idx, keys)
                    q = threshold_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit)
                    if q != q:
                        q = sorted_value(
                            r, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys
                        )
                if has_base:
                    qbase[r] = q - c_now
                if q > best or (q == best and r < arg):
                    best = q
                    arg = r
            if has_top and rows_left:
                top = -np.inf
                for r in range(lo, hi):
                    if r != arg and qbase[r] > top:
                        top = qbase[r]
                qmax[k] = top
        else:
            for r in range(lo, hi):
                if r == lrow:
                    q = lq
                else:
                    q = threshold_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit)
                    if q != q:
                        sort_critical(r, row_ptr, remaining, succ, gap, v, sign, crit, idx, keys)
                        q = threshold_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit)
                        if q != q:
                            q = sorted_value(
                                r, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys
                            )
                if (q > best) if maximize else (q < best):
                    best = q
                    arg = r
        best_row[k] = arg
        if has_light and arg != lrow:
            # the new best row into the state's slot of the copy, where it has the length
            a = row_ptr[arg]
            la = l_ptr[j]
            if row_ptr[arg + 1] - a == l_ptr[j + 1] - la:
                for e in range(row_ptr[arg + 1] - a):
                    l_succ[la + e] = succ[a + e]
                    l_lower[la + e] = lower[a + e]
                    l_gap[la + e] = gap[a + e]
                l_rem[j] = remaining[arg]
                l_crit[j] = crit[arg] - a + la
                light_rows[k] = arg
            else:
                light_rows[k] = -1
        old = v[s]
        best = below(best, arg, row_ptr)
        if best > old:
            v[s] = best
            if track:
                last[s] = best
            if best - old > residual:
                residual = best - old
    return residual


@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
def light_sweep(states, row_ptr, remaining, succ, lower, gap, crit, v, adversary_minimizes, last):
    """A light sweep: the Gauss-Seidel sweep of the contiguous copy of one row per state
    (row ``k`` of the copy belongs to ``states[k]``), in place; returns the largest change.
    A modified-policy-iteration sweep (for a maximising strategy its update is at most the
    full one): :func:`gauss_seidel_sweep` of that copy as a layout of one row per state,
    without that kernel's tests for the strategy's rows and the bounds of a full sweep
    (the light sweeps of the random 100k-state benchmark model are most of its sweeps)."""
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = scratch(row_ptr)
    residual = 0.0
    track = last.size > 0
    for k in range(states.size):
        s = states[k]
        q = threshold_value(k, row_ptr, remaining, succ, lower, gap, v, sign, crit)
        if q != q:
            sort_critical(k, row_ptr, remaining, succ, gap, v, sign, crit, idx, keys)
            q = threshold_value(k, row_ptr, remaining, succ, lower, gap, v, sign, crit)
            if q != q:
                q = sorted_value(k, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys)
        q = below(q, k, row_ptr)
        old = v[s]
        if q > old:
            v[s] = q
            if track:
                last[s] = q
            if q - old > residual:
                residual = q - old
    return residual
