"""Action elimination for the sweeps of a maximising strategy, compiled: a bound on a row's
value from its value when last evaluated and how far the values rose since.

The robust expectation ``Q_r(V) = min/max_{p in P_r} sum_j p_j V(s_j)`` is monotone in
``V`` and 1-Lipschitz in the maximum norm (every ``p`` sums to 1), so
``Q_r(V') <= Q_r(V) + max_s (V'(s) - V(s))``. The sweeps keep ``c``, the sum of every
sweep's residual and of every rise of the values between sweeps (:func:`rise_since`), and
per row ``qbase = Q_r(V) - c`` when last evaluated: ``qbase + c`` (now) bounds the row's
value, and a row whose bound is below its state's best value found cannot beat or tie it
(:func:`planner.imdp.kernels.gauss_seidel.gauss_seidel_sweep`, :func:`bounded_row_values`).
"""

from __future__ import annotations

import numba
import numpy as np

from planner.imdp.kernels.rows import feasible_bound, scratch, sorted_value, threshold_value

SKIP_MARGIN = 1e-12
"""Added to the bound of a skipped row: above the rounding of its two evaluations (at
most ``(8k + 16)`` units each, :func:`planner.imdp.kernels.rows.below`, about 2e-14 for
rows of 25 entries), so that skipping never changes a value or a best row."""

C_ROUNDING = 8 * 2.0**-53
"""Times ``c``, added to the bound too: the rounding of ``qbase = q - c`` and of
``qbase + c`` (an ulp of ``c`` each; ``c`` itself never falls below the sum of the rises,
:func:`rose`)."""


@numba.njit(cache=True, nogil=True, inline="always")
def rise_bound(c_now: float) -> float:
    """How far a row's value may have risen since its ``qbase`` was stored, with ``c_now``
    the sum of rises now: ``c_now`` plus ``SKIP_MARGIN`` and ``C_ROUNDING * c_now``
    (``qbase + rise_bound(c_now)`` bounds the row's value)."""
    return c_now + SKIP_MARGIN + C_ROUNDING * c_now


def rose(c: float, rise: float) -> float:
    """``c + rise`` rounded up (one ulp above the float sum): however many rises are added,
    ``c`` stays at least their exact sum."""
    return float(np.nextafter(c + rise, np.inf))


@numba.njit(cache=True, nogil=True)
def bounded_row_values(
    first,
    last,
    out,
    state_rows,
    best_row,
    qbase,
    c_now,
    slack,
    row_ptr,
    remaining,
    succ,
    lower,
    gap,
    crit,
    v,
    adversary_minimizes,
    light,
) -> None:
    """:func:`planner.imdp.kernels.rows.all_row_values` for the rows of the layout states
    ``first:last``, except that a row whose bound from its last value (``qbase + c_now``,
    as in :func:`gauss_seidel_sweep`) is below the value of its state's ``best_row`` by
    more than ``slack`` gets that bound instead: at least its value, and still below the
    best by more than ``slack``; so does, against the minimising adversary, a row whose
    critical successor moved and whose feasible distribution
    (:func:`planner.imdp.kernels.rows.feasible_bound`, plus ``SKIP_MARGIN``) shows it so,
    without sorting it. ``light`` (its rows empty: none): the light sweeps' contiguous copy
    of the best rows, row ``k`` of it a copy of ``best_row[k]``, from which the best rows
    are read (their critical successors copied back), as the full sweeps read them."""
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = scratch(row_ptr)
    rise = rise_bound(c_now)
    l_ptr, l_rem, l_succ, l_lower, l_gap, l_crit = light
    from_light = l_rem.size > 0
    for k in range(first, last):
        arg = best_row[k]
        if from_light:
            best = threshold_value(k, l_ptr, l_rem, l_succ, l_lower, l_gap, v, sign, l_crit)
            if best != best:
                best = sorted_value(
                    k, l_ptr, l_rem, l_succ, l_lower, l_gap, v, sign, l_crit, idx, keys
                )
            crit[arg] = row_ptr[arg] + l_crit[k] - l_ptr[k]
        else:
            best = threshold_value(arg, row_ptr, remaining, succ, lower, gap, v, sign, crit)
            if best != best:
                best = sorted_value(
                    arg, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys
                )
        out[arg] = best
        for r in range(state_rows[k], state_rows[k + 1]):
            if r == arg:
                continue
            q = qbase[r] + rise
            if q < best - slack:
                out[r] = q
                continue
            q = threshold_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit)
            if q != q:
                if adversary_minimizes:
                    b = feasible_bound(r, row_ptr, remaining, succ, lower, gap, v, crit)
                    if b + SKIP_MARGIN < best - slack:
                        out[r] = b + SKIP_MARGIN
                        continue
                q = sorted_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys)
            out[r] = q


@numba.njit(cache=True, nogil=True)
def rise_since(v, last) -> float:
    """``max(0, max_i v[i] - last[i])``, with ``last`` then set to ``v``."""
    rise = 0.0
    for i in range(v.size):
        d = v[i] - last[i]
        if d > rise:
            rise = d
        last[i] = v[i]
    return rise
