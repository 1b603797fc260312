"""The state-ordering adversary of interval MDPs, vectorised over all rows.

For a row with bounds ``l <= p <= u`` and successor values ``v``, the adversary that
*minimises* ``sum_j p_j v_j`` (Lahijanian et al. 2015, Alg. 1; Givan et al. 2000) sorts the
successors by ``v`` ascending, gives each successor ``l_j`` and then hands the remaining mass
``1 - sum(l)`` out in that order, at most ``u_j - l_j`` each:

    p_j = l_j + clip(1 - sum(l) - G_j, 0, u_j - l_j),   G_j = sum_{k before j} (u_k - l_k).

The maximising adversary does the same with ``v`` sorted descending. The chosen
distribution only depends on the *order* of the successors, so :class:`OrderingAdversary`
keeps the sorted layout and the resulting sparse distribution matrix between calls and
re-sorts only the rows whose order the new values break (ties never force a re-sort).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from planner.imdp.model import IMDP, first_of_runs


def segmented_cumsum(x: np.ndarray, pos: np.ndarray, max_len: int) -> np.ndarray:
    """Inclusive prefix sums of ``x`` restarted at every segment start.

    ``pos[i]`` is the position of element ``i`` inside its (contiguous) segment. A
    Hillis-Steele scan: ``ceil(log2(max_len))`` vectorised passes, each sum only over
    elements of one segment (no cancellation across segments).
    """
    out = x.astype(np.float64, copy=True)
    d = 1
    while d < max_len:
        shifted = np.zeros_like(out)
        shifted[d:] = out[:-d]
        out += np.where(pos >= d, shifted, 0.0)
        d *= 2
    return out


def row_entries(model: IMDP, rows: np.ndarray) -> np.ndarray:
    """Entry indices of the given rows, row after row."""
    starts = model.row_ptr[rows]
    lens = model.row_ptr[rows + 1] - starts
    total = int(lens.sum())
    offs = np.repeat(starts - np.concatenate(([0], np.cumsum(lens)[:-1])), lens)
    return np.arange(total, dtype=np.int64) + offs


def _ranks(keys: np.ndarray) -> np.ndarray:
    rank = np.empty(keys.size, dtype=np.int64)
    rank[np.argsort(keys, kind="stable")] = np.arange(keys.size)
    return rank


def _sort_rows(keys: np.ndarray, lens: np.ndarray, pos: np.ndarray, max_len: int) -> np.ndarray:
    """Permutation that sorts ``keys`` within each of the consecutive rows of ``lens``
    entries (stable), through a padded ``(rows, max_len)`` array sorted along its rows."""
    n_rows = lens.size
    row = np.repeat(np.arange(n_rows, dtype=np.int64), lens)
    if n_rows * max_len > 4 * keys.size + 1024:
        # long rows among short ones: padding would waste memory, sort (row, rank) keys
        return np.argsort(row * max(keys.size, 1) + _ranks(keys), kind="stable")
    padded = np.full((n_rows, max_len), np.inf)
    padded[row, pos] = keys
    order = np.argsort(padded, axis=1, kind="stable")
    starts = np.concatenate(([0], np.cumsum(lens)[:-1]))
    # +inf padding sorts last; keys equal to +inf keep their place before the padding
    valid = np.arange(max_len)[None, :] < lens[:, None]
    return (starts[:, None] + order)[valid]


class OrderingAdversary:
    """The minimising (or maximising) state-ordering adversary of one model.

    Args:
        model: the interval MDP.
        minimize: ``True`` for the adversary that minimises the expectation (pessimistic
            for a maximising controller), ``False`` for the one that maximises it.
        rows: optional row indices (sorted) to work on; :meth:`expectation` then returns
            one value per given row.
        resort_tolerance: successors whose values are out of order by at most this much
            are not re-sorted; the returned expectation is then off by at most
            ``resort_tolerance`` times the row length. 0 (default) keeps the order exact.
    """

    def __init__(
        self,
        model: IMDP,
        minimize: bool = True,
        rows: np.ndarray | None = None,
        resort_tolerance: float = 0.0,
    ) -> None:
        self.model = model
        self.minimize = bool(minimize)
        self.resort_tolerance = float(resort_tolerance)
        m = model
        if rows is None:
            self.rows = np.arange(m.n_rows, dtype=np.int64)
            entries = np.arange(m.n_entries, dtype=np.int64)
            self._row_ptr = m.row_ptr
            self._entry_row = m.entry_row
        else:
            self.rows = np.asarray(rows, dtype=np.int64)
            entries = row_entries(m, self.rows)
            lens = m.row_ptr[self.rows + 1] - m.row_ptr[self.rows]
            self._row_ptr = np.concatenate(([0], np.cumsum(lens))).astype(np.int64)
            self._entry_row = np.repeat(np.arange(self.rows.size, dtype=np.int64), lens)
        self.n_rows = int(self.rows.size)
        self._successor = m.successor[entries]
        self._lower = m.lower[entries]
        self._gap = m.upper[entries] - self._lower
        self._pos = np.arange(entries.size, dtype=np.int64) - self._row_ptr[self._entry_row]
        lens = np.diff(self._row_ptr)
        self._lens = lens
        self._max_len = int(lens.max()) if lens.size else 0
        self._remaining = 1.0 - m.row_lower_sum[self.rows]
        self._perm: np.ndarray | None = None
        self._succ = np.empty(entries.size, dtype=np.int64)
        self._prob = np.empty(entries.size, dtype=np.float64)
        self._matrix: sp.csr_matrix | None = None
        self.n_sorts = 0
        """How many times rows were (re-)sorted (a full sort counts once)."""

    def _keys(self, values: np.ndarray) -> np.ndarray:
        return values if self.minimize else -values

    def _assign(self, idx: np.ndarray | slice) -> None:
        """Recompute the distribution of the (whole) rows whose sorted entries are ``idx``."""
        perm = self._perm[idx]
        lo = self._lower[perm]
        gap = self._gap[perm]
        pos = self._pos[idx]
        before = segmented_cumsum(gap, pos, self._max_len) - gap
        er = self._entry_row[idx]
        rem = self._remaining[er]
        self._prob[idx] = lo + np.clip(rem - before, 0.0, gap)
        self._succ[idx] = self._successor[perm]

    def _sort_all(self, keys: np.ndarray) -> None:
        m = self.model
        self._perm = _sort_rows(
            keys[self._successor], np.diff(self._row_ptr), self._pos, self._max_len
        )
        self._assign(slice(None))
        self._matrix = sp.csr_matrix(
            (self._prob, self._succ, self._row_ptr),
            shape=(self.n_rows, m.n_states),
            copy=False,
        )
        # scipy may convert the index arrays: keep writing into the matrix's own arrays
        self._prob = self._matrix.data
        self._succ = self._matrix.indices
        self.n_sorts += 1

    def update(self, values: np.ndarray) -> None:
        """Make the stored distributions optimal for ``values`` (shape ``(n_states,)``)."""
        keys = self._keys(np.asarray(values, dtype=np.float64))
        if self._perm is None:
            self._sort_all(keys)
            return
        ks = keys[self._succ]
        broken = (ks[:-1] - ks[1:] > self.resort_tolerance) & (self._pos[1:] > 0)
        if not broken.any():
            return
        rows = self._entry_row[1:][broken]
        rows = rows[first_of_runs(rows)]
        if rows.size * 4 > self.n_rows:
            self._sort_all(keys)
            return
        starts = self._row_ptr[rows]
        lens = self._row_ptr[rows + 1] - starts
        idx = np.arange(int(lens.sum()), dtype=np.int64) + np.repeat(
            starts - np.concatenate(([0], np.cumsum(lens)[:-1])), lens
        )
        local = _sort_rows(ks[idx], lens, self._pos[idx], self._max_len)
        self._perm[idx] = self._perm[idx][local]
        self._assign(idx)
        self.n_sorts += 1

    def matrix(self, values: np.ndarray) -> sp.csr_matrix:
        """The adversary's distributions as a sparse ``(n_rows, n_states)`` matrix (one row
        per selected row). A live view: a later :meth:`update` changes it in place."""
        self.update(values)
        assert self._matrix is not None
        return self._matrix

    def expectation(self, values: np.ndarray) -> np.ndarray:
        """``min`` (or ``max``) over the intervals of ``sum_j p_j values_j`` for every row."""
        values = np.asarray(values, dtype=np.float64)
        return self.matrix(values) @ values


def worst_case_expectation(model: IMDP, values: np.ndarray) -> np.ndarray:
    """``min_{l <= p <= u, sum p = 1} sum_j p_j values[j]`` for every row, shape ``(n_rows,)``."""
    return OrderingAdversary(model, minimize=True).expectation(values)


def best_case_expectation(model: IMDP, values: np.ndarray) -> np.ndarray:
    """``max_{l <= p <= u, sum p = 1} sum_j p_j values[j]`` for every row, shape ``(n_rows,)``."""
    return OrderingAdversary(model, minimize=False).expectation(values)
