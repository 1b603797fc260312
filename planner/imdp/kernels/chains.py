"""The linear systems of strategy evaluation, assembled (compiled): a chain's distributions
split into the part among the states solved for and the part that leaves them, and the
M-matrix ``A = diag(exits) - P`` in compressed columns, symmetrically permuted."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def split_chain(indptr, indices, data, states, pos, base, dust):
    """The CSR rows ``indptr/indices/data`` (row ``i``: a distribution of state
    ``states[i]`` over all states) without their entries below ``dust``, split.

    ``pos``: each state's index in ``states`` (-1 elsewhere); ``base``: the values of the
    states outside ``states`` (0 on them). Returns ``(kept_ptr, kept_idx, kept_val,
    inner_ptr, inner_idx, inner_val, lost, kept, b)``: the rows without dust (global
    columns); their entries into ``states`` (columns renumbered by ``pos``); per row the
    dust and the non-dust mass that leave its own state (``lost``, ``kept``); and ``b_i =
    sum_j P_ij base_j`` (the non-dust entries in row order)."""
    n = indptr.size - 1
    nnz = indptr[n]
    kept_ptr = np.zeros(n + 1, dtype=np.int64)
    kept_idx = np.empty(nnz, dtype=np.int64)
    kept_val = np.empty(nnz)
    inner_ptr = np.zeros(n + 1, dtype=np.int64)
    inner_idx = np.empty(nnz, dtype=np.int64)
    inner_val = np.empty(nnz)
    lost = np.zeros(n)
    kept = np.zeros(n)
    b = np.zeros(n)
    k = 0
    m = 0
    for i in range(n):
        own = states[i]
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            p = data[e]
            if p < dust:
                if j != own:
                    lost[i] += p
                continue
            if j != own:
                kept[i] += p
            kept_idx[k] = j
            kept_val[k] = p
            k += 1
            b[i] += p * base[j]
            if pos[j] >= 0:
                inner_idx[m] = pos[j]
                inner_val[m] = p
                m += 1
        kept_ptr[i + 1] = k
        inner_ptr[i + 1] = m
    return (
        kept_ptr,
        kept_idx[:k],
        kept_val[:k],
        inner_ptr,
        inner_idx[:m],
        inner_val[:m],
        lost,
        kept,
        b,
    )


@numba.njit(cache=True, nogil=True)
def exit_matrix(indptr, indices, data, exits, perm):
    """``A = diag(exits) - P`` (``P`` the square CSR ``indptr/indices/data`` without its
    diagonal, which ``exits`` replaces: each row's mass leaving its own state) as
    ``B = A[perm][:, perm]`` in compressed columns with sorted row indices (``perm``: the
    old index of every new one). Returns ``(indptr, indices, data)`` of ``B``."""
    n = indptr.size - 1
    new = np.empty(n, dtype=np.int64)
    for i in range(n):
        new[perm[i]] = i
    ptr = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        ptr[new[i] + 1] += 1
        for e in range(indptr[i], indptr[i + 1]):
            if indices[e] != i:
                ptr[new[indices[e]] + 1] += 1
    for j in range(n):
        ptr[j + 1] += ptr[j]
    fill = ptr[:n].copy()
    idx = np.empty(ptr[n], dtype=np.int64)
    val = np.empty(ptr[n])
    # new rows in increasing order: each column's rows come out sorted
    for r in range(n):
        i = perm[r]
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            if j != i:
                c = new[j]
                idx[fill[c]] = r
                val[fill[c]] = -data[e]
                fill[c] += 1
        c = r
        idx[fill[c]] = r
        val[fill[c]] = exits[i]
        fill[c] += 1
    return ptr, idx, val
