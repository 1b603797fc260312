"""Compiled checks and layout of an interval MDP's entries (:class:`planner.imdp.IMDP`).

The constructor's per-entry work runs here: range and bound checks, the sorting permutation
(a counting sort on (state, action), then each row by successor), the sorted copies of the
entries and the row layout with its bound sums. The sorted copies come from numba's
allocator, not numpy's: numpy advises the kernel to back arrays of 4 MB and more with
transparent huge pages, and on a VM whose kernel then compacts memory at every page fault a
fresh 57.6 MB gather took 0.75 s instead of 0.07 s (the 7.2M-entry random model of
``benchmarks/bench_vi.py``: 2.7-3.6 s to build with numpy gathers, 0.39 s now).
"""

from __future__ import annotations

import numba
import numpy as np

from planner.imdp.kernels.exact import _grow, sum_below, sum_sign
from planner.imdp.kernels.rows import longest_row


@numba.njit(cache=True, nogil=True)
def check_entries(s, a, t, lo, up, n, n_act):
    """Ranges and bounds of every entry, and the order of the entries: ``(code, index,
    permutation)`` with code 0 (fine), 1 state, 2 successor, 3 action out of range,
    4 a bound outside ``[0, 1]`` or not finite, 5 ``lower > upper``; the permutation is
    empty when the entries are already sorted by (state, action, successor), else it
    sorts them (a counting sort on (state, action), then each row by successor)."""
    m = s.size
    empty = np.zeros(0, dtype=np.int64)
    for i in range(m):
        if s[i] < 0 or s[i] >= n:
            return 1, i, empty
        if t[i] < 0 or t[i] >= n:
            return 2, i, empty
        if a[i] < 0 or a[i] >= n_act:
            return 3, i, empty
        li = lo[i]
        ui = up[i]
        if not (np.isfinite(li) and np.isfinite(ui)) or li < 0.0 or ui > 1.0:
            return 4, i, empty
        if li > ui:
            return 5, i, empty
    ordered = True
    for i in range(1, m):
        k0 = s[i - 1] * n_act + a[i - 1]
        k1 = s[i] * n_act + a[i]
        if k1 < k0 or (k1 == k0 and t[i] < t[i - 1]):
            ordered = False
            break
    if ordered:
        return 0, 0, empty
    n_keys = n * n_act
    ptr = np.zeros(n_keys + 1, dtype=np.int64)
    for i in range(m):
        ptr[s[i] * n_act + a[i] + 1] += 1
    for k in range(n_keys):
        ptr[k + 1] += ptr[k]
    fill = ptr[:-1].copy()
    perm = np.empty(m, dtype=np.int64)
    for i in range(m):
        k = s[i] * n_act + a[i]
        perm[fill[k]] = i
        fill[k] += 1
    for k in range(n_keys):
        # insertion sort of the row by successor (rows are short)
        for j in range(ptr[k] + 1, ptr[k + 1]):
            e = perm[j]
            key = t[e]
            h = j - 1
            while h >= ptr[k] and t[perm[h]] > key:
                perm[h + 1] = perm[h]
                h -= 1
            perm[h + 1] = e
    return 0, 0, perm


@numba.njit(cache=True, nogil=True)
def sorted_entries(perm, t, lo, up):
    """``t[perm], lo[perm], up[perm]`` (fresh arrays from numba's allocator: see the
    module docstring)."""
    m = perm.size
    t2 = np.empty(m, dtype=np.int64)
    lo2 = np.empty(m)
    up2 = np.empty(m)
    for i in range(m):
        e = perm[i]
        t2[i] = t[e]
        lo2[i] = lo[e]
        up2[i] = up[e]
    return t2, lo2, up2


@numba.njit(cache=True, nogil=True)
def row_layout(s, a, t, lo, up, perm, tol):
    """Rows of sorted entries: ``(code, index, row_ptr, row_state, row_action, sum_lower,
    sum_upper)``; code 1: a duplicate successor at sorted entry ``index``, 2: row ``index``
    does not bracket 1. ``t``, ``lo``, ``up`` are in sorted order; ``s`` and ``a`` are read
    through ``perm`` (the sorting permutation; empty when the entries came sorted)."""
    m = t.size
    sorted_in = perm.size == 0
    n_rows = 0
    prev_s, prev_a = -1, -1
    for i in range(m):
        e = i if sorted_in else perm[i]
        if s[e] != prev_s or a[e] != prev_a:
            n_rows += 1
            prev_s, prev_a = s[e], a[e]
    row_ptr = np.empty(n_rows + 1, dtype=np.int64)
    row_state = np.empty(n_rows, dtype=np.int64)
    row_action = np.empty(n_rows, dtype=np.int64)
    sum_lo = np.zeros(n_rows)
    sum_up = np.zeros(n_rows)
    r = -1
    prev_s, prev_a = -1, -1
    for i in range(m):
        e = i if sorted_in else perm[i]
        if s[e] != prev_s or a[e] != prev_a:
            r += 1
            row_ptr[r] = i
            prev_s, prev_a = s[e], a[e]
            row_state[r] = prev_s
            row_action[r] = prev_a
        elif t[i] == t[i - 1]:
            return 1, i, row_ptr, row_state, row_action, sum_lo, sum_up
        sum_lo[r] += lo[i]
        sum_up[r] += up[i]
    row_ptr[n_rows] = m
    for k in range(n_rows):
        if sum_lo[k] > 1.0 + tol or sum_up[k] < 1.0 - tol:
            return 2, k, row_ptr, row_state, row_action, sum_lo, sum_up
    return 0, 0, row_ptr, row_state, row_action, sum_lo, sum_up


@numba.njit(cache=True, nogil=True)
def entry_rows(row_ptr):
    """The row of every entry."""
    out = np.empty(row_ptr[-1], dtype=np.int64)
    for r in range(row_ptr.size - 1):
        for e in range(row_ptr[r], row_ptr[r + 1]):
            out[e] = r
    return out


_UNIT = 2.0**-53
"""Unit roundoff of double precision."""


@numba.njit(cache=True, nogil=True)
def rows_to_tighten(row_ptr, lo, up, sum_lo, sum_up):
    """The rows that :func:`tighten_rows` may change: those whose float sums cannot show
    that they bracket 1, that no entry with ``lower == 0`` is forced and that every such
    entry has room (the rest provably need nothing)."""
    n_rows = row_ptr.size - 1
    out = np.empty(n_rows, dtype=np.int64)
    k = 0
    for r in range(n_rows):
        a, b = row_ptr[r], row_ptr[r + 1]
        s_lo, s_up = sum_lo[r], sum_up[r]
        # a bound of the rounding of these sums and of ``1 - (s - x_j)``
        err_up = (b - a + 2) * _UNIT * (s_up + 1.0)
        err_lo = (b - a + 2) * _UNIT * (s_lo + 1.0)
        top = 0.0  # the largest upper bound of an entry with lower bound 0
        for i in range(a, b):
            if lo[i] == 0.0 and up[i] > top:
                top = up[i]
        if not (s_up - 1.0 > err_up and 1.0 - s_lo > err_lo and top < s_up - 1.0 - err_up):
            out[k] = r
            k += 1
    return out[:k].copy()


@numba.njit(cache=True, nogil=True)
def tighten_rows(rows, row_ptr, lo, up, sum_lo, sum_up):
    """Make the bounds of ``rows`` exact where the graph analyses read them, in place
    (and their sums ``sum_lo``, ``sum_up``); returns the number of entries changed.

    1. A row that brackets 1 only within the model's tolerance is made to bracket it
       exactly (its polytope ``{l <= p <= u, sum p = 1}`` would be empty): the largest upper
       bound is raised by the missing mass (or the largest lower bound lowered by the
       excess), rounded outwards. Point intervals written in floating point (a sum of
       ``1 - 2**-53``) get an interval that wide on one entry.
    2. An entry with ``lower == 0`` is still forced when the other upper bounds sum to
       less than 1 (every distribution puts at least ``1 - sum_{i != j} u_i`` on it): its
       lower bound becomes that mass rounded down (the polytope is unchanged), at least
       the least positive double. An entry with ``upper > 0`` that the other lower bounds
       leave no room for (they sum to 1 or more) gets ``upper = 0``.

    Each is decided in exact arithmetic (error-free expansions), so that ``lower > 0``
    (must) and ``upper > 0`` (may) are exact per entry and the sums of a row's bounds are
    exactly on their side of 1."""
    longest = longest_row(row_ptr)
    terms = np.empty(longest + 2)
    e = np.empty(longest + 2)
    free = np.empty(longest + 2)  # the expansion of 1 - sum(u), once per row
    changed = 0
    for r in rows:
        a, b = row_ptr[r], row_ptr[r + 1]
        if not (_brackets(up, a, b, terms, e, 1) and _brackets(lo, a, b, terms, e, -1)):
            changed += _bracket_exactly(lo, up, a, b, terms, e)
        # an entry with lower bound 0 has room iff the lower bounds sum to less than 1
        # (every entry the same); its forced mass is (1 - sum u) + u_j, one term more than
        # the row's expansion (at most about 40 components: doubles span 2100 binary
        # orders), so a row costs O(k) expansion steps, not O(k^2)
        no_room = _brackets(lo, a, b, terms, e, 0)
        m = _one_minus(up, a, b, terms, free)
        for j in range(a, b):
            if lo[j] != 0.0 or up[j] == 0.0:
                continue
            if no_room:
                up[j] = 0.0
                changed += 1
                continue
            for h in range(m):
                terms[h] = free[h]
            terms[m] = up[j]
            if sum_sign(terms, m + 1, e) > 0:
                lo[j] = min(max(sum_below(terms, m + 1, e), 5e-324), up[j])
                changed += 1
        sum_lo[r], sum_up[r] = 0.0, 0.0
        for i in range(a, b):
            sum_lo[r] += lo[i]
            sum_up[r] += up[i]
    return changed


@numba.njit(cache=True, nogil=True)
def fresh_copy(x):
    """A copy of ``x`` from numba's allocator (see the module docstring)."""
    out = np.empty_like(x)
    for i in range(x.size):
        out[i] = x[i]
    return out


@numba.njit(cache=True, nogil=True)
def _brackets(x, a, b, terms, e, side) -> bool:
    """Whether ``sum x[a:b]`` is exactly at least 1 (``side = 1``), at most 1 (-1) or
    exactly 1 or more with the float sum near it (0: the lower bounds leave no room)."""
    s = 0.0
    for i in range(a, b):
        s += x[i]
    err = (b - a + 2) * _UNIT * (s + 1.0)
    if side != 0 and side * (s - 1.0) > err:
        return True
    if side == 0 and s < 1.0 - err:
        return False
    terms[0] = -1.0
    for i in range(a, b):
        terms[1 + i - a] = x[i]
    sign = sum_sign(terms, b - a + 1, e)
    return sign >= 0 if side == 0 else side * sign >= 0


@numba.njit(cache=True, nogil=True)
def _one_minus(x, a, b, terms, out) -> int:
    """``1 - sum x[a:b]`` exactly, as an expansion in ``out``; its length."""
    terms[0] = 1.0
    for i in range(a, b):
        terms[1 + i - a] = -x[i]
    m = 0
    for i in range(b - a + 1):
        m = _grow(out, m, terms[i])
    return m


@numba.njit(cache=True, nogil=True)
def _bracket_exactly(lo, up, a, b, terms, e) -> int:
    """Raise the largest upper bound of the row ``a:b`` until the upper bounds sum to at
    least 1, lower the largest lower bound until the lower bounds sum to at most 1 (both
    exactly); the entries changed."""
    changed = 0
    while not _brackets(up, a, b, terms, e, 1):
        j = a + np.argmax(up[a:b])
        up[j] = min(np.nextafter(up[j] + _off_one(up, a, b, 1, terms, e), np.inf), 1.0)
        changed += 1
    while not _brackets(lo, a, b, terms, e, -1):
        j = a + np.argmax(lo[a:b])
        lo[j] = max(np.nextafter(lo[j] - _off_one(lo, a, b, -1, terms, e), -np.inf), 0.0)
        changed += 1
    return changed


@numba.njit(cache=True, nogil=True)
def _off_one(x, a, b, side, terms, e) -> float:
    """A double at least ``side (1 - sum x[a:b])``: the mass the upper bounds miss
    (``side = 1``) or by which the lower bounds exceed 1 (-1), one step more for the
    rounding of the sum."""
    terms[0] = -side
    for i in range(a, b):
        terms[1 + i - a] = side * x[i]
    return -sum_below(terms, b - a + 1, e)
