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
