"""Interval Markov decision processes (IMDPs) stored as sparse rows.

An IMDP is ``I = (Q, A, T_lo, T_up, Q0, AP, L)``: for every enabled (state, action) pair, a
*row*, each successor ``q'`` has an interval ``[T_lo(q, a, q'), T_up(q, a, q')]`` that
contains the unknown transition probability. An adversary picks, each time a row is used,
a distribution ``p`` with ``T_lo <= p <= T_up`` and ``sum p = 1``.

Storage (CSR-like, rows sorted by state then action, entries by successor):

* ``row_state[r]``, ``row_action[r]``: the (state, action) of row ``r``;
  ``state_ptr[s] : state_ptr[s + 1]`` are the rows of state ``s``;
* ``row_ptr[r] : row_ptr[r + 1]`` are the entries of row ``r`` in ``successor``,
  ``lower``, ``upper`` (and ``entry_row`` gives each entry's row).

A row must bracket 1: ``sum(lower) <= 1 + tol`` and ``sum(upper) >= 1 - tol`` with
``tol = BOUND_TOLERANCE`` (1e-9) unless the caller states another tolerance. The
constructor then makes the bounds exact where the analyses read them
(:func:`planner.imdp.entries.tighten_rows`, in exact arithmetic): a row that brackets 1
only within ``tol`` is widened by the missing mass on its largest bound so that it brackets
1 exactly (its polytope ``{l <= p <= u, sum p = 1}`` would be empty); an entry with
``lower == 0`` that the other upper bounds force (they sum to less than 1) gets that mass
as its lower bound, rounded down; an entry with ``upper > 0`` that the other lower bounds
leave no room for gets ``upper = 0``. The polytopes are unchanged, and graph analyses use
the exact boolean structure ``lower > 0`` (must) / ``upper > 0`` (may); an entry with
``upper == 0`` is allowed and means "never". Every other bound is stored as given.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from planner.errors import (
    DuplicateSuccessorError,
    IndexOutOfRangeError,
    IntervalBoundsError,
    MissingRowError,
    ModelError,
    RowSumError,
    UnknownLabelError,
)
from planner.imdp.entries import (
    check_entries,
    entry_rows,
    fresh_copy,
    row_layout,
    rows_to_tighten,
    sorted_entries,
    tighten_rows,
)


def first_of_runs(sorted_keys: np.ndarray) -> np.ndarray:
    """Indices of the first element of every run of equal values in a sorted array."""
    if sorted_keys.size == 0:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(np.concatenate(([True], sorted_keys[1:] != sorted_keys[:-1])))


def run_ids(sorted_keys: np.ndarray) -> np.ndarray:
    """For every element of a sorted array, the index of its run of equal values."""
    if sorted_keys.size == 0:
        return np.zeros(0, dtype=np.int64)
    return np.cumsum(np.concatenate(([0], (sorted_keys[1:] != sorted_keys[:-1]).astype(np.int64))))


BOUND_TOLERANCE = 1e-9
"""Slack allowed when checking that a row brackets 1 (``sum l <= 1 <= sum u``)."""


def _distinct_label_sets(
    labels: Iterable[Iterable[str]],
) -> tuple[list[frozenset[str]], np.ndarray]:
    """``(distinct, ids)``: the distinct label sets (labels as strings) and, per state, the
    index of its set. A state's labels given as a tuple or frozenset of strings (or one
    string) are converted once per distinct value; other iterables once each."""
    seen: dict[object, int] = {}
    distinct: list[frozenset[str]] = []
    ids: list[int] = []
    for ls in labels:
        try:
            j = seen.get(ls)
        except TypeError:  # unhashable, e.g. a list
            j = None
        if j is None:
            j = len(distinct)
            distinct.append(frozenset(str(x) for x in ls))
            # only keys of strings: equal keys then hold equal strings
            kind = type(ls)
            if kind is str or (
                (kind is tuple or kind is frozenset) and all(type(x) is str for x in ls)
            ):
                seen[ls] = j
        ids.append(j)
    return distinct, np.asarray(ids, dtype=np.int64)


def _int_array(x: object, name: str) -> np.ndarray:
    a = np.asarray(x)
    if a.ndim != 1:
        raise ModelError(f"{name} must be a 1-D array, got shape {a.shape}")
    if a.size and not np.issubdtype(a.dtype, np.integer):
        raise ModelError(f"{name} must hold integers, got dtype {a.dtype}")
    return a.astype(np.int64, copy=False)


def _float_array(x: object, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 1:
        raise ModelError(f"{name} must be a 1-D array, got shape {a.shape}")
    return a


class IMDP:
    """An interval MDP built from COO arrays of equal length.

    Args:
        n_states: number of states ``|Q|``.
        state, action, successor: integer arrays, one entry per transition interval.
        lower, upper: the interval bounds ``T_lo``, ``T_up`` (floats in ``[0, 1]``).
        n_actions: size of the action alphabet (default: ``max(action) + 1``).
        labels: per-state iterables of proposition names (default: no labels).
        propositions: the declared proposition names; every label must be one of them
            (default: the union of the labels, in sorted order).
        initial: the initial states ``Q0`` (default: ``(0,)``).
        action_names: names of the actions (default: ``"a0", "a1", ...``).
        tolerance: the slack of the row-sum check.

    Raises:
        IndexOutOfRangeError: a state, action or successor index outside the model.
        IntervalBoundsError: a bound outside ``[0, 1]``, not finite, or ``lower > upper``.
        DuplicateSuccessorError: one row names a successor twice.
        RowSumError: a row with ``sum(lower) > 1 + tol`` or ``sum(upper) < 1 - tol``.
        MissingRowError: a state without any enabled action.
        UnknownLabelError: a label that is not a declared proposition.
        ModelError: arrays of unequal length or wrong type.
    """

    def __init__(
        self,
        n_states: int,
        state: Sequence[int] | np.ndarray,
        action: Sequence[int] | np.ndarray,
        successor: Sequence[int] | np.ndarray,
        lower: Sequence[float] | np.ndarray,
        upper: Sequence[float] | np.ndarray,
        *,
        n_actions: int | None = None,
        labels: Sequence[Iterable[str]] | None = None,
        propositions: Sequence[str] | None = None,
        initial: Iterable[int] = (0,),
        action_names: Sequence[str] | None = None,
        tolerance: float = BOUND_TOLERANCE,
    ) -> None:
        n = int(n_states)
        if n <= 0:
            raise ModelError(f"an IMDP needs at least one state, got n_states={n_states}")
        s = _int_array(state, "state")
        a = _int_array(action, "action")
        t = _int_array(successor, "successor")
        lo = _float_array(lower, "lower")
        up = _float_array(upper, "upper")
        sizes = {len(s), len(a), len(t), len(lo), len(up)}
        if len(sizes) != 1:
            raise ModelError(
                f"state, action, successor, lower, upper must have equal length, got "
                f"{len(s)}, {len(a)}, {len(t)}, {len(lo)}, {len(up)}"
            )
        n_act = int(n_actions) if n_actions is not None else (int(a.max()) + 1 if a.size else 1)
        code, i, perm = check_entries(s, a, t, lo, up, n, n_act)
        if code:
            _raise_entry_error(code, i, s, a, t, lo, up, n, n_act)
        if perm.size:  # builders that emit sorted entries skip the reordering
            t, lo, up = sorted_entries(perm, t, lo, up)
        code, r, row_ptr, row_state, row_action, sum_lo, sum_up = row_layout(
            s, a, t, lo, up, perm, float(tolerance)
        )
        if code == 1:
            e = perm[r] if perm.size else r
            raise DuplicateSuccessorError(
                f"state {s[e]}, action {a[e]} lists successor {t[r]} more than once"
            )
        if code == 2:
            raise RowSumError(
                f"state {row_state[r]}, action {row_action[r]}: bounds do not bracket 1 "
                f"(sum of lower bounds {sum_lo[r]:.12g}, sum of upper bounds "
                f"{sum_up[r]:.12g}, tolerance {tolerance:g})"
            )
        loose = rows_to_tighten(row_ptr, lo, up, sum_lo, sum_up)
        if loose.size:
            if not perm.size:  # the caller's arrays: change copies
                lo, up = fresh_copy(lo), fresh_copy(up)
            tighten_rows(loose, row_ptr, lo, up, sum_lo, sum_up)
        rows_per_state = np.bincount(row_state, minlength=n)
        empty = np.flatnonzero(rows_per_state == 0)
        if empty.size:
            raise MissingRowError(
                f"state {empty[0]} has no enabled action ({empty.size} such states); "
                "give absorbing states a self-loop action"
            )
        self._init_arrays(
            n, n_act, float(tolerance), row_state, row_action, row_ptr, t, lo, up, sum_lo, sum_up
        )
        self._set_labels(labels, propositions)
        self._set_rest(initial, action_names)

    @classmethod
    def _trusted(
        cls,
        n_states: int,
        row_state: np.ndarray,
        row_action: np.ndarray,
        row_ptr: np.ndarray,
        successor: np.ndarray,
        lower: np.ndarray,
        upper: np.ndarray,
        *,
        n_actions: int,
        label_matrix: np.ndarray,
        propositions: tuple[str, ...],
        initial: Iterable[int],
        action_names: Sequence[str],
        tolerance: float,
        entry_row: np.ndarray,
        row_sums: tuple[np.ndarray, np.ndarray],
    ) -> IMDP:
        """A model from arrays already in the internal layout and known valid (rows
        sorted by state then action, entries by successor, bounds checked), with each
        entry's row and the sums of each row's lower and upper bounds: for constructions
        inside the planner (products) that would otherwise validate millions of entries
        again."""
        self = cls.__new__(cls)
        sum_lo, sum_up = row_sums
        self._init_arrays(
            int(n_states),
            int(n_actions),
            float(tolerance),
            row_state,
            row_action,
            row_ptr,
            successor,
            lower,
            upper,
            sum_lo,
            sum_up,
            entry_row,
        )
        mask = np.asarray(label_matrix, dtype=bool)
        mask.setflags(write=False)
        self.propositions = tuple(propositions)
        self.label_matrix = mask
        self._labels = None
        self._set_rest(initial, action_names)
        return self

    def _init_arrays(
        self,
        n: int,
        n_act: int,
        tolerance: float,
        row_state: np.ndarray,
        row_action: np.ndarray,
        row_ptr: np.ndarray,
        successor: np.ndarray,
        lower: np.ndarray,
        upper: np.ndarray,
        sum_lo: np.ndarray,
        sum_up: np.ndarray,
        entry_row: np.ndarray | None = None,
    ) -> None:
        rows_per_state = np.bincount(row_state, minlength=n)
        self.n_states: int = n
        self.n_actions: int = n_act
        self.tolerance: float = tolerance
        self.row_state: np.ndarray = row_state
        self.row_action: np.ndarray = row_action
        self.row_ptr: np.ndarray = row_ptr
        self.state_ptr: np.ndarray = np.concatenate(([0], np.cumsum(rows_per_state))).astype(
            np.int64
        )
        self.successor: np.ndarray = successor
        self.lower: np.ndarray = lower
        self.upper: np.ndarray = upper
        self.entry_row: np.ndarray = entry_rows(row_ptr) if entry_row is None else entry_row
        self.row_lower_sum: np.ndarray = sum_lo
        self.row_upper_sum: np.ndarray = sum_up
        self.enabled: np.ndarray = np.zeros((n, n_act), dtype=bool)
        self.enabled[row_state, row_action] = True
        self.row_index: np.ndarray = np.full((n, n_act), -1, dtype=np.int64)
        self.row_index[row_state, row_action] = np.arange(len(row_state))
        self._incoming: tuple[np.ndarray, ...] | None = None

    def _set_rest(self, initial: Iterable[int], action_names: Sequence[str] | None) -> None:
        n, n_act = self.n_states, self.n_actions
        init = np.unique(_int_array(list(initial), "initial"))
        bad = np.flatnonzero((init < 0) | (init >= n))
        if bad.size or init.size == 0:
            raise IndexOutOfRangeError(f"initial states {init.tolist()} must be in [0, {n})")
        self.initial: np.ndarray = init
        if action_names is None:
            action_names = tuple(f"a{i}" for i in range(n_act))
        if len(action_names) != n_act:
            raise ModelError(f"{len(action_names)} action names for {n_act} actions")
        self.action_names: tuple[str, ...] = tuple(str(x) for x in action_names)
        for arr in (
            self.row_state,
            self.row_action,
            self.row_ptr,
            self.state_ptr,
            self.successor,
            self.lower,
            self.upper,
            self.entry_row,
            self.enabled,
            self.row_index,
        ):
            arr.setflags(write=False)

    def _set_labels(
        self, labels: Sequence[Iterable[str]] | None, propositions: Sequence[str] | None
    ) -> None:
        """The label matrix from per-state label sets, each distinct set converted once
        (:func:`_distinct_label_sets`; the per-state sets of :attr:`labels` are made from
        the matrix when first asked for). States share few distinct sets: on the random
        100k-state benchmark model a frozenset per state took 90-120 ms of the
        constructor's 200 ms, the distinct sets 6-8 ms."""
        if labels is None:
            props = tuple(str(p) for p in propositions) if propositions is not None else ()
            mask = np.zeros((self.n_states, len(props)), dtype=bool)
        else:
            distinct, ids = _distinct_label_sets(labels)
            if ids.size != self.n_states:
                raise ModelError(f"{ids.size} label sets for {self.n_states} states")
            if propositions is None:
                props = tuple(sorted(set().union(*distinct)))
            else:
                props = tuple(str(p) for p in propositions)
                known = set(props)
                for j, ls in enumerate(distinct):
                    unknown = ls - known
                    if unknown:
                        i = int(np.flatnonzero(ids == j)[0])
                        raise UnknownLabelError(
                            f"state {i} carries label(s) {sorted(unknown)} that are not "
                            f"among the declared propositions {props}"
                        )
            index = {p: i for i, p in enumerate(props)}
            table = np.zeros((len(distinct), len(props)), dtype=bool)
            for j, ls in enumerate(distinct):
                table[j, [index[p] for p in ls]] = True
            mask = table[ids]
        self.propositions: tuple[str, ...] = props
        mask.setflags(write=False)
        self.label_matrix: np.ndarray = mask
        self._labels: tuple[frozenset[str], ...] | None = None

    @property
    def labels(self) -> tuple[frozenset[str], ...]:
        """Per-state label sets (from :attr:`label_matrix`; computed once)."""
        if self._labels is None:
            mask = self.label_matrix
            if not self.propositions:
                self._labels = (frozenset(),) * self.n_states
                return self._labels
            # one set per distinct row of the matrix (rows coded as integers where they fit)
            if mask.shape[1] < 63:
                codes = mask.astype(np.int64) @ (np.int64(1) << np.arange(mask.shape[1]))
                _, first, ids = np.unique(codes, return_index=True, return_inverse=True)
                table = mask[first]
            else:
                table, ids = np.unique(mask, axis=0, return_inverse=True)
            names = np.array(self.propositions, dtype=object)
            sets = [frozenset(names[row].tolist()) for row in table]
            self._labels = tuple([sets[j] for j in ids.ravel().tolist()])
        return self._labels

    # ------------------------------------------------------------------ queries
    @property
    def n_rows(self) -> int:
        return int(self.row_state.shape[0])

    @property
    def n_entries(self) -> int:
        return int(self.successor.shape[0])

    def incoming(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Reverse index ``(ptr, rows, lower, upper)``: positions ``ptr[s]:ptr[s+1]`` list
        the entries whose successor is ``s``, by their row and bounds (stored in that
        order, so walking a state's predecessors reads memory sequentially; computed once,
        then cached)."""
        ptr, rows, _, lower, upper = self.reverse_index()
        return ptr, rows, lower, upper

    def reverse_index(self) -> tuple[np.ndarray, ...]:
        """:meth:`incoming` with each entry's row state: ``(ptr, rows, states, lower,
        upper)``, ``states = row_state[rows]`` stored in the same order (cached)."""
        if self._incoming is None:
            from planner.imdp.kernels import incoming_index  # kernels import this module

            fields = (self.successor, self.entry_row, self.row_state, self.lower, self.upper)
            view = incoming_index(*fields, self.n_states)
            for a in view:
                a.setflags(write=False)
            self._incoming = view
        return self._incoming

    def states_labelled(self, name: str) -> np.ndarray:
        """Boolean mask ``(n_states,)`` of the states that carry label ``name``.

        Raises:
            UnknownLabelError: if ``name`` is not a declared proposition.
        """
        if name not in self.propositions:
            raise UnknownLabelError(
                f"label {name!r} is not among the model's propositions {self.propositions}"
            )
        return self.label_matrix[:, self.propositions.index(name)].copy()

    def coo(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The transitions as COO arrays ``(state, action, successor, lower, upper)``."""
        return (
            self.row_state[self.entry_row],
            self.row_action[self.entry_row],
            self.successor.copy(),
            self.lower.copy(),
            self.upper.copy(),
        )

    def with_initial(self, initial: Iterable[int]) -> IMDP:
        """A copy of this model with other initial states."""
        s, a, t, lo, up = self.coo()
        return IMDP(
            self.n_states,
            s,
            a,
            t,
            lo,
            up,
            n_actions=self.n_actions,
            labels=self.labels,
            propositions=self.propositions,
            initial=initial,
            action_names=self.action_names,
            tolerance=self.tolerance,
        )

    def __repr__(self) -> str:
        return (
            f"IMDP(states={self.n_states}, actions={self.n_actions}, rows={self.n_rows}, "
            f"entries={self.n_entries}, propositions={self.propositions})"
        )


def _raise_entry_error(code, i, s, a, t, lo, up, n, n_act) -> None:
    where = f"entry {i} (state {s[i]}, action {a[i]}, successor {t[i]})"
    if code in (1, 2, 3):
        name, arr, hi = {1: ("state", s, n), 2: ("successor", t, n), 3: ("action", a, n_act)}[code]
        raise IndexOutOfRangeError(f"{where}: {name} {arr[i]} is not in [0, {hi})")
    if code == 4:
        raise IntervalBoundsError(f"{where}: bounds [{lo[i]}, {up[i]}] are not inside [0, 1]")
    raise IntervalBoundsError(f"{where}: lower bound {lo[i]} exceeds upper bound {up[i]}")


def row_entries(model: IMDP, rows: np.ndarray) -> np.ndarray:
    """Entry indices of the given rows, row after row."""
    return entries_of_rows(model.row_ptr, rows)[0]


def entries_of_rows(row_ptr: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(entries, ptr)``: the entry indices of ``rows`` (of a layout with ``row_ptr``), row
    after row, and where each row's run of them starts (``ptr[-1]`` their number)."""
    starts = row_ptr[rows]
    ptr = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(row_ptr[rows + 1] - starts, out=ptr[1:])
    offs = np.repeat(starts - ptr[:-1], np.diff(ptr))
    return np.arange(ptr[-1], dtype=np.int64) + offs, ptr
