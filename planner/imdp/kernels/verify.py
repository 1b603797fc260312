"""A superharmonicity check whose rounding cannot hide a violation.

For a reachability upper bound ``U`` and a row ``r`` of state ``s`` the kernels bound the
*exact* excess ``T_r(U) - U(s)`` from above, ``T_r(U)`` the adversary's expectation of
``U`` over the row's interval polytope ``{p : l <= p <= u, sum p = 1}``, computed in the
form whose rounding scales with the value *differences* (not with the values, as a plain
``sum p U`` does):

* minimising adversary: the greedy vertex (successors by ascending ``U``: upper bounds
  before the critical successor ``k``, lower bounds after, ``p_k = 1 - sum_{j != k} p_j``
  exactly) has expectation ``U_k + sum_{j != k} p_j (U_j - U_k)``, an upper bound of the
  minimum once ``l_k <= p_k <= u_k`` is verified with the rounding of the sum allowed for;
* maximising adversary: for any ``lambda``, ``lambda + sum_{U_j > lambda} u_j (U_j -
  lambda) + sum_{U_j < lambda} l_j (U_j - lambda)`` bounds the maximum from above (weak
  duality), ``lambda`` the critical successor's value (where it is exact).

Each difference is split exactly into its rounded value and its error (TwoSum of
:mod:`planner.imdp.kernels.exact`), and the
sum is taken up by ``(2n + 6)`` units of roundoff of the summed magnitudes, so the result
is at least the exact excess. Where the values of a pocket are equal the excess is exactly
0 and nothing is added: no allowance per step accumulates over long stays.
"""

from __future__ import annotations

import numba
import numpy as np

from planner.imdp.kernels.exact import _at_least, _two_sum, expansion_sum
from planner.imdp.kernels.rows import scratch, sort_entries

_UNIT = 2.0**-53
"""Unit roundoff of double precision."""


@numba.njit(cache=True, nogil=True)
def row_excess(a, b, succ, lower, upper, u, us, minimizes, idx, keys, work, below=False) -> float:
    """An upper bound of the exact ``T_r(U) - U(s)`` for the row with entries ``a:b``
    (``us = U(s)``); ``inf`` where the minimising adversary has no feasible vertex,
    decided in exact arithmetic (never for a row that brackets 1 exactly, as the model's
    constructor makes every row).
    ``below``: a *lower* bound of the exact excess instead, from the adversary's greedy
    vertex shown feasible (the minimum of a minimising adversary, a value a maximising one
    can reach; ``-inf`` where no vertex is shown feasible).
    ``idx``: scratch as long as the row, ``keys`` twice that (:func:`sort_entries`);
    ``work``: scratch of twice the row length plus 8."""
    n = b - a
    sort_entries(a, n, succ, u, 1.0 if minimizes else -1.0, idx, keys)
    # the critical position: the adversary's remaining mass runs out there
    rem = 1.0
    for i in range(n):
        rem -= lower[idx[i]]
    c = n - 1
    for i in range(n):
        e = idx[i]
        g = upper[e] - lower[e]
        if rem <= g:
            c = i
            break
        rem -= g
    if minimizes or below:
        # the vertex must be feasible: p_c = 1 - sum of the others within [l_c, u_c],
        # both sides decided exactly; where rounding put the critical
        # position off, it moves to the exact one (towards lower positions when p_c < l_c,
        # higher when p_c > u_c: it exists for a row that brackets 1)
        terms = work[: n + 3]
        e = work[n + 3 :]
        side = _critical_side(c, n, idx, lower, upper, terms, e)
        if side != 0:
            # the side is +1 left of the exact critical position and -1 right of it:
            # a bisection on the indicated side (a long row with gaps below the rounding
            # of ``rem`` may put the float position far off)
            first, last = (c + 1, n - 1) if side > 0 else (0, c - 1)
            c = -1
            while first <= last:
                mid = (first + last) // 2
                side = _critical_side(mid, n, idx, lower, upper, terms, e)
                if side == 0:
                    c = mid
                    break
                if side > 0:
                    first = mid + 1
                else:
                    last = mid - 1
            if c < 0:
                return -np.inf if below else np.inf
    uc = u[succ[idx[c]]]
    total, tail = _two_sum(uc, -us)
    bound = abs(tail)
    size = abs(total)
    for i in range(n):
        if i == c:
            continue
        e = idx[i]
        # before the critical position: upper bounds (either adversary's greedy order)
        p = upper[e] if i < c else lower[e]
        d, de = _two_sum(u[succ[e]], -uc)
        t = p * d
        total += t
        size += abs(t)
        bound += p * abs(de)
    margin = bound + (2 * n + 6) * _UNIT * (size + bound)
    first = total - margin if below else total + margin
    if (first >= 0.0) if below else (first <= 0.0):
        return first
    # the same pivoted on U(s): a self-loop then adds exactly 0, however much it keeps
    other = _pivot_on_state(c, n, idx, succ, lower, upper, u, us, minimizes or below, work)
    if below:
        return max(first, other[0] - other[1])
    return min(first, other[0] + other[1])


@numba.njit(cache=True, nogil=True)
def _pivot_on_state(c, n, idx, succ, lower, upper, u, us, vertex, work):
    """``(total, margin)`` with ``|T_r(U) - U(s) - total| <= margin`` in the form
    ``sum_j p_j (U_j - U(s))`` (``vertex``: the greedy vertex, shown feasible, its critical
    mass ``p_c = 1 - sum_{j != c} p_j`` taken from an exact expansion), or, for a
    maximising adversary without a shown vertex, the weak-duality bound at ``lambda =
    U(s)``: ``sum_j (u_j if U_j > U(s) else l_j) (U_j - U(s))``, of which only
    ``total + margin`` is meant."""
    total, bound, size = 0.0, 0.0, 0.0
    for i in range(n):
        e = idx[i]
        d, de = _two_sum(u[succ[e]], -us)
        if d == 0.0 and de == 0.0:
            continue
        if not vertex:
            p = upper[e] if d > 0.0 else lower[e]
        elif i != c:
            p = upper[e] if i < c else lower[e]
        else:
            terms = work[: n + 1]
            k = _others_of_vertex(c, n, idx, lower, upper, terms)
            terms[k] = 1.0
            p, m = expansion_sum(terms, k + 1, work[n + 1 :])
            bound += (2 * m + 2) * _UNIT * abs(p) * (abs(d) + abs(de)) + 2.0**-1074
        t = p * d
        total += t
        size += abs(t)
        bound += p * abs(de)
    return total, bound + (2 * n + 6) * _UNIT * (size + bound)


@numba.njit(cache=True, nogil=True)
def row_deficits(rows, row_state, row_ptr, succ, lower, upper, u, minimizes):
    """For each row of ``rows``: a lower bound of the exact ``T_r(U) - U(s)``, ``s`` its
    state (``row_excess`` with ``below``); all of them ``>= 0`` shows ``U <= T_sigma(U)``
    for the strategy that plays ``rows``."""
    idx, keys = scratch(row_ptr)
    work = np.empty(2 * idx.size + 8)
    out = np.empty(rows.size)
    for k in range(rows.size):
        r = rows[k]
        s = row_state[r]
        a, b = row_ptr[r], row_ptr[r + 1]
        out[k] = row_excess(a, b, succ, lower, upper, u, u[s], minimizes, idx, keys, work, True)
    return out


@numba.njit(cache=True, nogil=True)
def _critical_side(c, n, idx, lower, upper, terms, e) -> int:
    """0 where ``p_c = 1 - sum_{i < c} u_i - sum_{i > c} l_i`` (positions in the
    adversary's order ``idx``) lies in ``[l_c, u_c]`` exactly, -1 where it is below, 1
    where above."""
    m = _others_of_vertex(c, n, idx, lower, upper, terms)
    ec = idx[c]
    terms[m] = 1.0
    terms[m + 1] = -lower[ec]
    if not _at_least(terms, m + 2, e):
        return -1
    for i in range(m):
        terms[i] = -terms[i]
    terms[m] = -1.0
    terms[m + 1] = upper[ec]
    if not _at_least(terms, m + 2, e):
        return 1
    return 0


@numba.njit(cache=True, nogil=True, inline="always")
def _others_of_vertex(c, n, idx, lower, upper, terms) -> int:
    """``terms[:n - 1]`` the negated masses of the greedy vertex's entries other than the
    critical position ``c`` (upper bounds before it, lower bounds after, in the order
    ``idx``); returns ``n - 1``."""
    m = 0
    for i in range(n):
        if i != c:
            terms[m] = -(upper[idx[i]] if i < c else lower[idx[i]])
            m += 1
    return m


@numba.njit(cache=True, nogil=True)
def clear_excess(a, b, succ, lower, upper, u, us, minimizes) -> float:
    """A bound of the exact ``T_r(U) - U(s)`` from above, found in one pass without
    sorting, when it shows the row clear (at most 0); ``inf`` where it cannot (then
    :func:`row_excess` decides). With ``d_j = U_j - U(s)`` (its sign exact in floating
    point), ``m = p - l`` the mass above the lower bounds (``sum m = R = 1 - sum l``):

    * minimising adversary: ``m`` may fill the entries with ``d_j < 0`` up to their gaps
      (capacity ``C``) and put the rest on the others, so ``min_p sum p d <= sum l d +
      min(R, C) max_{d_j < 0} d_j + max(R - C, 0) max_{d_j >= 0} d_j``; where ``C > R``
      also ``<= sum l d + sum_{d_j < 0} g_j d_j - (C - R) min_j d_j`` (every gap below
      filled, the excess taken back where it weighs most), the smaller of the two;
    * maximising adversary: ``max_p sum p d <= sum l d + R max_j d_j``.

    The rounding of the sums, of ``R`` and ``C`` and of the differences is allowed for by
    ``(4n + 16)`` units of roundoff of the magnitudes involved (``|d| <= 1``), so a row
    that passes here passes exactly; rows within about ``8 n^2`` units of roundoff of
    their bound are left to the exact check. Most rows of a maximising controller lie far
    below their state's bound: on the benchmark models this skips the sorting and the
    exact sums for them (the excess's sign, all a pass needs, is the same)."""
    s_l = 0.0
    mag = 0.0
    l_sum = 0.0
    cap = 0.0
    s_g = 0.0
    d_below = -np.inf
    d_above = -np.inf
    d_abs = 0.0
    for e in range(a, b):
        d = u[succ[e]] - us
        lo = lower[e]
        s_l += lo * d
        mag += lo * abs(d)
        l_sum += lo
        if d < 0.0:
            g = upper[e] - lo
            cap += g
            s_g += g * d
            d_below = max(d_below, d)
        else:
            d_above = max(d_above, d)
        d_abs = max(d_abs, abs(d))
    rem = max(1.0 - l_sum, 0.0)
    if minimizes:
        take = min(rem, cap)
        extra = rem - take
        bound = s_l + (take * d_below if take > 0.0 else 0.0)
        if extra > 0.0:
            if d_above == -np.inf:
                return np.inf
            bound += extra * d_above
        else:
            # every gap below filled and the surplus taken back where ``d`` is lowest
            bound = min(bound, s_l + s_g + (cap - rem) * d_abs)
        mag -= s_g  # the filled gaps' terms, |g d|
    else:
        bound = s_l + rem * max(d_below, d_above)
    n = b - a
    bound += (4 * n + 16) * _UNIT * (mag + abs(s_l) + 2.0 * (2.0 + cap) * d_abs) + 2.0**-1060
    return bound if bound <= 0.0 else np.inf


@numba.njit(cache=True, nogil=True)
def _state_excess(k, layout, u, maximize, minimizes, idx, keys, work) -> float:
    """The bound of the exact excess ``T(U)(s) - U(s)`` at ``s = states[k]`` over its rows
    ``rows[state_rows[k]:state_rows[k + 1]]`` (any row when the controller maximises, its
    best row when it minimises); ``-inf`` where ``U(s) >= 1``, which every row respects.
    ``layout``: ``(states, state_rows, rows, row_ptr, succ, lower, upper)``."""
    states, state_rows, rows, row_ptr, succ, lower, upper = layout
    s = states[k]
    if u[s] >= 1.0:
        return -np.inf
    worst = -np.inf if maximize else np.inf
    for j in range(state_rows[k], state_rows[k + 1]):
        r = rows[j]
        a, b = row_ptr[r], row_ptr[r + 1]
        # rows shown clear in one pass skip the sorting and the exact sums
        x = clear_excess(a, b, succ, lower, upper, u, u[s], minimizes)
        if x > 0.0:
            x = row_excess(a, b, succ, lower, upper, u, u[s], minimizes, idx, keys, work)
        worst = max(worst, x) if maximize else min(worst, x)
    return worst


@numba.njit(cache=True, nogil=True)
def state_excesses(
    first, last, states, state_rows, rows, row_ptr, succ, lower, upper, u, maximize, minimizes, out
):
    """``out[k]``, for ``first <= k < last``, the excess bound of :func:`_state_excess`
    at ``u`` as it is: the checks of a pass that raises nothing, which read ``u`` only
    (so that two ranges can be checked at once)."""
    idx, keys = scratch(row_ptr)
    work = np.empty(2 * idx.size + 8)
    layout = (states, state_rows, rows, row_ptr, succ, lower, upper)
    for k in range(first, last):
        out[k] = _state_excess(k, layout, u, maximize, minimizes, idx, keys, work)


@numba.njit(cache=True, nogil=True)
def raise_pass(
    states,
    state_rows,
    rows,
    row_ptr,
    succ,
    lower,
    upper,
    u,
    maximize,
    minimizes,
    due,
    inc_ptr,
    inc_state,
    known,
    stale,
):
    """One Gauss-Seidel pass over ``states`` (each with the rows
    ``rows[state_rows[k]:state_rows[k + 1]]``): where the exact Bellman value may exceed
    ``U(s)`` (any row when the controller maximises, its best row when it minimises),
    ``U(s)`` is raised just above the bound (at most to 1, which every row respects).
    Only the states flagged in ``due`` (per model state) are checked, which clears their
    flag; a raised state flags its predecessors (``inc_ptr``/``inc_state``: the states
    with a row that has it as a successor, from the model's reverse index). A state not
    due passed its last check and none of its successors moved since, so it still passes.
    Returns the number of states raised: once a pass raises none, ``T(U) <= U`` holds
    exactly at every state of ``states``.

    ``known`` (empty: none): per position the excess bound at ``U`` as it was when the
    pass began (:func:`state_excesses`); it is taken for every state not flagged in
    ``stale`` (per model state), which the pass does for the predecessors of each state it
    raises: a state none of whose successors was raised before it in the pass sees the
    values it was checked at, so the pass is the same as one that checks every state."""
    idx, keys = scratch(row_ptr)
    work = np.empty(2 * idx.size + 8)
    use_known = known.size > 0
    layout = (states, state_rows, rows, row_ptr, succ, lower, upper)
    raised = 0
    for k in range(states.size):
        s = states[k]
        if not due[s]:
            continue
        due[s] = False
        if use_known and not stale[s]:
            worst = known[k]
        else:
            worst = _state_excess(k, layout, u, maximize, minimizes, idx, keys, work)
        if worst > 0.0:
            raised += 1
            u[s] = min(1.0, np.nextafter(u[s] + worst * (1.0 + 2.0**-40), np.inf))
            for e in range(inc_ptr[s], inc_ptr[s + 1]):
                due[inc_state[e]] = True
                if use_known:
                    stale[inc_state[e]] = True
    return raised
