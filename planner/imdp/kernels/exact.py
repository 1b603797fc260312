"""Residuals of sparse linear systems in double-double arithmetic, compiled.

Strategy evaluation solves ``x = P x + b`` for chains that can mix very slowly (expected
stays of ``1e8`` steps in the free states of a grid product): the LU solution's forward
error is then up to ``1e8`` times its backward error, ``1e-8`` in double precision, and
residuals computed in double precision cannot see it. A residual accumulated without
rounding error (error-free transformations: Knuth's TwoSum, Dekker's split product; the
sum carried as an unevaluated pair ``hi + lo``, about 106 bits) lets iterative refinement
recover the solution to double precision and bounds its error elementwise.
"""

from __future__ import annotations

import numba
import numpy as np

_SPLIT = 134217729.0  # 2**27 + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _two_sum(a: float, b: float) -> tuple[float, float]:
    """``a + b = s + e`` exactly (Knuth)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


@numba.njit(cache=True, nogil=True, inline="always")
def _two_prod(a: float, b: float) -> tuple[float, float]:
    """``a * b = p + e`` exactly (Dekker's split into 26-bit halves)."""
    p = a * b
    c = _SPLIT * a
    ah = c - (c - a)
    al = a - ah
    c = _SPLIT * b
    bh = c - (c - b)
    bl = b - bh
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


@numba.njit(cache=True, nogil=True, inline="always")
def _grow(e, m: int, b: float) -> int:
    """Add ``b`` to the expansion ``e[:m]`` (non-overlapping components, smallest first)
    without error (Shewchuk's grow-expansion, zero components dropped); its new length."""
    q = b
    k = 0
    for i in range(m):
        q, h = _two_sum(q, e[i])
        if h != 0.0:
            e[k] = h
            k += 1
    e[k] = q
    return k + 1


@numba.njit(cache=True, nogil=True)
def sum_sign(terms, n: int, e) -> int:
    """The sign (-1, 0 or 1) of the exact sum of ``terms[:n]`` (``e``: scratch of length
    ``n`` at least)."""
    m = 0
    for i in range(n):
        m = _grow(e, m, terms[i])
    for i in range(m - 1, -1, -1):
        if e[i] != 0.0:
            return 1 if e[i] > 0.0 else -1
    return 0


@numba.njit(cache=True, nogil=True)
def expansion_sum(terms, n: int, e) -> tuple[float, int]:
    """``(approx, m)``: the exact sum of ``terms[:n]`` as an expansion of ``m``
    non-overlapping components (in ``e``, scratch of length ``n`` at least) and their float
    sum from the smallest, which is within ``m + 1`` ulps of the exact sum."""
    m = 0
    for i in range(n):
        m = _grow(e, m, terms[i])
    total = 0.0
    for i in range(m):
        total += e[i]
    return total, m


@numba.njit(cache=True, nogil=True)
def sum_below(terms, n: int, e) -> float:
    """A double at most the exact sum of ``terms[:n]``, within a few units of roundoff of
    it (``e``: scratch of length ``n`` at least)."""
    total, m = expansion_sum(terms, n, e)
    for _ in range(m + 1):
        total = np.nextafter(total, -np.inf)
    return total


@numba.njit(cache=True, nogil=True)
def _at_least(terms, n: int, e) -> bool:
    """Whether the exact sum of ``terms[:n]`` is at least 0."""
    return sum_sign(terms, n, e) >= 0


@numba.njit(cache=True, nogil=True, inline="always")
def near_one(approx: float, k: int) -> bool:
    """Whether a float sum ``approx`` of at most ``2k`` additions and subtractions of
    values in ``[0, 1]`` (partial sums at most ``k``) may lie on the other side of 1 than
    the exact sum: then only exact arithmetic decides."""
    return abs(approx - 1.0) <= (2 * k + 2) * k * 2.0**-53


@numba.njit(cache=True, nogil=True)
def row_sum_signs(row_ptr, values) -> np.ndarray:
    """Per CSR row, the sign (-1, 0 or 1) of the exact ``sum - 1`` of its ``values`` (in
    ``[0, 1]``): the float sum decides where rounding cannot tip it (:func:`near_one`), an
    error-free expansion the rest."""
    n = row_ptr.size - 1
    out = np.empty(n, dtype=np.int64)
    longest = 0
    for r in range(n):
        longest = max(longest, row_ptr[r + 1] - row_ptr[r])
    terms = np.empty(longest + 1)
    e = np.empty(longest + 1)
    for r in range(n):
        a, b = row_ptr[r], row_ptr[r + 1]
        total = 0.0
        for i in range(a, b):
            total += values[i]
        if not near_one(total, b - a):
            out[r] = 1 if total > 1.0 else -1
            continue
        terms[0] = -1.0
        for i in range(a, b):
            terms[1 + i - a] = values[i]
        out[r] = sum_sign(terms, b - a + 1, e)
    return out


@numba.njit(cache=True, nogil=True)
def chain_exit_residual(indptr, indices, data, y, own, lost) -> np.ndarray:
    """``r_i = sum_{k: indices[k] != own[i]} data[k] (y[indices[k]] - y[own[i]]) - lost[i]
    y[own[i]]`` over the CSR rows ``i`` in double-double, rounded once: the residual of ``x
    = P x`` with each row's stay on its own state implied (``1 -`` the mass that leaves,
    ``lost`` to a state of value 0 included), so that a row keeping ``1 - 1e-9`` on itself
    is as exact as its exits (a residual ``sum_k data[k] y[k] - y[own]`` reads the rounded
    stay and keeps nothing of a leak below ``eps``)."""
    n = indptr.size - 1
    r = np.empty(n)
    for i in range(n):
        ys = y[own[i]]
        hi, lo = _two_prod(-lost[i], ys)
        for k in range(indptr[i], indptr[i + 1]):
            if indices[k] == own[i]:
                continue
            d, de = _two_sum(y[indices[k]], -ys)
            p, pe = _two_prod(data[k], d)
            hi, e = _two_sum(hi, p)
            lo += e + pe + data[k] * de
        r[i] = hi + lo
    return r
