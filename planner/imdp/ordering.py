"""The state-ordering adversary of interval MDPs, vectorised over all rows.

For a row with bounds ``l <= p <= u`` and successor values ``v``, the adversary that
*minimises* ``sum_j p_j v_j`` (Lahijanian et al. 2015, Alg. 1; Givan et al. 2000) sorts the
successors by ``v`` ascending, gives each successor ``l_j`` and then hands the remaining mass
``1 - sum(l)`` out in that order, at most ``u_j - l_j`` each:

    p_j = l_j + clip(1 - sum(l) - G_j, 0, u_j - l_j),   G_j = sum_{k before j} (u_k - l_k).

The maximising adversary does the same with ``v`` sorted descending. The chosen
distribution only depends on the *order* of the successors, so :class:`OrderingAdversary`
keeps the sorted layout and the resulting sparse distribution matrix between calls and
re-sorts only the rows whose order the new values break (ties never force a re-sort). The
rows are sorted and their mass handed out by a compiled kernel
(:func:`planner.imdp.kernels.rows.order_rows`: insertion sort from the current order,
one pass where the order still stands).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from planner.imdp.kernels.rows import order_rows, unordered_rows
from planner.imdp.model import IMDP, row_entries


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
        self.rows = np.asarray(np.arange(m.n_rows) if rows is None else rows, dtype=np.int64)
        lens = m.row_ptr[self.rows + 1] - m.row_ptr[self.rows]
        self._row_ptr = np.concatenate(([0], np.cumsum(lens))).astype(np.int64)
        self.n_rows = int(self.rows.size)
        self._remaining = 1.0 - m.row_lower_sum[self.rows]
        self._perm: np.ndarray | None = None
        """The model's entry indices of every row, in the adversary's order."""
        self._succ: np.ndarray | None = None
        self._prob: np.ndarray | None = None
        self._matrix: sp.csr_matrix | None = None
        self.n_sorts = 0
        """How many times rows were (re-)sorted (each update that re-sorted counts once)."""

    def _keys(self, values: np.ndarray) -> np.ndarray:
        # a fresh writable array either way: one kernel signature for every caller
        return values.copy() if self.minimize else -values

    def _order(self, keys: np.ndarray, todo: np.ndarray) -> None:
        m = self.model
        order_rows(
            todo,
            self._row_ptr,
            m.successor,
            m.lower,
            m.upper,
            self._remaining,
            keys,
            self._perm,
            self._prob,
            self._succ,
        )
        self.n_sorts += 1

    def update(self, values: np.ndarray) -> None:
        """Make the stored distributions optimal for ``values`` (shape ``(n_states,)``)."""
        keys = self._keys(np.asarray(values, dtype=np.float64))
        if self._matrix is None:
            m = self.model
            n_entries = int(self._row_ptr[-1])
            self._perm = (
                np.arange(n_entries, dtype=np.int64)
                if self.rows.size == m.n_rows
                else row_entries(m, self.rows)
            )
            self._prob = np.empty(n_entries)
            # the index dtype scipy keeps for any matrix that fits, so that the kernels
            # see one signature (compiled once, by the warm-up)
            self._succ = np.empty(n_entries, dtype=np.int32 if n_entries < 2**31 else np.int64)
            self._order(keys, np.arange(self.n_rows, dtype=np.int64))
            self._matrix = sp.csr_matrix(
                (self._prob, self._succ, self._row_ptr),
                shape=(self.n_rows, m.n_states),
                copy=False,
            )
            # scipy may convert the index arrays: keep writing into the matrix's own arrays
            self._prob = self._matrix.data
            self._succ = self._matrix.indices
            return
        rows = unordered_rows(self._row_ptr, self._succ, keys, self.resort_tolerance)
        if rows.size:
            self._order(keys, rows)

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
