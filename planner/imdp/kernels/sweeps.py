"""The sweep-ordered layout that robust value iteration sweeps (:class:`ReachSweeper`) and
its sweeps: Gauss-Seidel sweeps from below
(:func:`planner.imdp.kernels.gauss_seidel.gauss_seidel_sweep`) and passes from above
(:func:`planner.imdp.kernels.upper.upper_sweep`).

Layout (built by :class:`ReachSweeper`): the free states in sweep order, their rows
(``state_rows[k]:state_rows[k + 1]`` are the rows of the ``k``-th state) and, per row, its
entries (:mod:`planner.imdp.kernels.rows`). A full sweep of many entries runs as a block
Gauss-Seidel sweep of two halves on two threads (:meth:`ReachSweeper.sweep`).
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from planner._util.threads import concurrently, in_halves
from planner.imdp.kernels.elimination import bounded_row_values, rise_since, rose
from planner.imdp.kernels.gauss_seidel import gauss_seidel_sweep, light_sweep
from planner.imdp.kernels.layers import layers, sweep_order
from planner.imdp.kernels.rows import (
    NO_LAYOUT,
    all_row_values,
    empty_slots,
    fill_layout,
    gather_rows,
    regather_rows,
    row_distributions,
)
from planner.imdp.kernels.upper import flag_predecessors, top_of_cache, upper_sweep
from planner.imdp.model import IMDP

ELIMINATE = True
"""Full sweeps of a maximising strategy skip rows by their last values
(:func:`gauss_seidel_sweep`'s ``qbase``)."""

BOUND_SKIP = True
"""With ``ELIMINATE``, against the minimising adversary: full sweeps do not sort a row
whose critical successor moved where a feasible distribution shows it below the best
(:func:`gauss_seidel_sweep`'s ``bounded``)."""

HALVES_SWEEP_ENTRIES = 100_000
"""Entries of a full sweep (or of a light sweep asked to ``split``) from which
:meth:`ReachSweeper.sweep` runs it in two halves at once. Only plain value iteration
splits its light sweeps (its second core is idle between the full sweeps). Its uncertified
solves, least of 4 in turns against whole light sweeps: the 100 x 100 benchmark grid
(150k entries a light sweep), seeds 0-11, 4.79 s in all instead of 5.13 s, in about the
same sweeps (seed 0 351 against 413 ms; seed 3 571 against 483 ms, its strategy iteration
at sweep 129 on 1,707 moving states instead of 1,499; seed 7 1,017 sweeps instead of 932,
782 against 878 ms); the random 100k-state model (580k), three draws, 0.63 s instead of
0.70 s, in 38-39 sweeps instead of 33.
Interval iteration keeps them whole: its passes from above run on the second core
meanwhile, and a split light sweep of the grid took 0.88 ms there instead of 0.74 ms."""

NARROW_STATES = int(np.iinfo(np.int32).max)
"""Models with at most this many states keep the successors of the sweeps' layout (and of
its light copy) as 32-bit integers, larger ones as 64-bit. The full sweeps stream the
layout: on the random 100k-state benchmark model (4.6M entries) the uncertified solve took
a median 5 % less in one process, alternating with 64-bit successors, the same values."""

TRACK_START = 0.25
"""Tracked passes from above skip states once a pass has moved at most this fraction of
the free states (:meth:`ReachSweeper.track_changes`). On the random 100k-state benchmark
model nearly every state moves in each of its 27 passes, and tracking from the start made
the certified solve 1.5-1.8x slower."""

_NOT_TRACKED = np.empty(0, dtype=np.bool_)
_NO_INDEX = np.empty(0, dtype=np.int64)
_NO_FLAGS = np.empty(0, dtype=np.bool_)
_NO_TOP = (np.empty(0, dtype=np.int64), np.empty(0), np.empty(0, dtype=np.bool_))

TOP_ROWS_EVALUATIONS = 1.05
TOP_ROWS_STALE = 0.05
"""An untracked lazy pass from above that evaluated at most ``TOP_ROWS_EVALUATIONS`` rows
per state copies each state's top row, and later passes with the same row cache read
those rows from the copy (:func:`planner.imdp.kernels.upper.upper_sweep`); the copy is
made again after a pass that left more than ``TOP_ROWS_STALE`` of its states stale."""


class ReachSweeper:
    """The compact, sweep-ordered layout of the free rows of a model, and its sweeps.

    Full sweeps evaluate every row and record each state's best row; light sweeps
    evaluate only those rows, from a contiguous copy that the full sweeps keep (the best
    rows lie scattered in the full layout, which makes them slow to read).

    Args:
        model: the interval MDP.
        free_rows: the rows the strategy may use at the free states (sorted).
        sweep_key: ``(n_states,)`` sort key of the states; sweeps visit the free states in
            increasing key (ties by index).
        maximize: the strategy maximises (else minimises) over rows.
        adversary_minimizes: the adversary minimises (else maximises) the expectation.

    After :meth:`track_changes`, passes from above asked to ``track`` evaluate only the
    states with a successor whose value fell by more than the given amount since their
    last evaluation (see :func:`upper_sweep`), once a pass has moved at most
    ``TRACK_START`` of the free states (before, flagging every moved state's predecessors
    would cost more than the skips save); upper values lowered by other means must be
    reported (:meth:`moved_above`).
    """

    def __init__(
        self,
        model: IMDP,
        free_rows: np.ndarray,
        sweep_key: np.ndarray,
        maximize: bool,
        adversary_minimizes: bool,
    ) -> None:
        m = model
        self.free_rows = free_rows
        """The free rows as given (sorted)."""
        # the free states in increasing key (a stable sort: ``states``), each with its run
        # of rows (``rows``: the model row of every row of the layout)
        order = sweep_order(free_rows, m.row_state, sweep_key, m.row_ptr, m.row_lower_sum)
        self.states, self.state_rows, self._position, rows, self.row_ptr, self.remaining = order
        self.rows = rows
        n_ent = int(self.row_ptr[-1])
        narrow = m.n_states <= NARROW_STATES
        self.succ = np.empty(n_ent, dtype=np.int32 if narrow else np.int64)
        self.lower = np.empty(n_ent)
        self.gap = np.empty(n_ent)
        arrays = (rows, m.row_ptr, m.successor, m.lower, m.upper, self.row_ptr)
        layout = (self.succ, self.lower, self.gap)
        if n_ent >= HALVES_SWEEP_ENTRIES:
            in_halves(lambda a, b: fill_layout(a, b, *arrays, *layout), self.row_ptr, "sweep")
        else:
            fill_layout(0, rows.size, *arrays, *layout)
        self.crit = self.row_ptr[:-1].copy()
        self.crit_up = self.crit.copy()
        self.best_row = self.state_rows[:-1].copy()
        self._model = m
        self._tracking: tuple | None = None
        self._tracked = False
        self.maximize = bool(maximize)
        self.adversary_minimizes = bool(adversary_minimizes)
        self._light: tuple[np.ndarray, ...] | None = None
        self._light_rows = _NO_INDEX  # the best row in each slot of the copy
        # the lazy passes' top rows: (cache they were read from, top, other, stale, copy)
        self._top: tuple | None = None
        self.before_sweep: Callable[[], None] | None = None
        """Called before each sweep from below (to abandon the sweeps, it raises)."""
        self._no_cache = np.empty(0)
        # action elimination from the rows' last values (a maximising strategy; see
        # gauss_seidel_sweep): per layout row its last value less the rise then, the
        # values after the last sweep, and the rise of the values since the first sweep
        self._qbase = np.full(rows.size, np.inf) if self.maximize and ELIMINATE else self._no_cache
        self._qmax = np.full(self.states.size if self._qbase.size else 0, np.inf)
        self._bounded = np.zeros(self._qbase.size, dtype=np.bool_)
        self._last = self._no_cache
        self._rise = 0.0
        # the values and the sum of rises at the start of the last full sweep
        self._snap = self._no_cache
        self._snap_rise = 0.0
        # the first state of the later half of a full sweep in halves (0: whole)
        half = np.searchsorted(self.state_rows, np.searchsorted(self.row_ptr, n_ent // 2))
        self._cut = int(half) if n_ent >= HALVES_SWEEP_ENTRIES and half < self.states.size else 0

    def sweep(
        self,
        v: np.ndarray,
        full: bool = True,
        bound: np.ndarray | None = None,
        split: bool = False,
    ) -> float:
        """One Gauss-Seidel sweep on ``v`` in place (see :func:`gauss_seidel_sweep`): all
        rows (``full``; those whose ``bound``, a per-row upper bound such as the row cache
        of the passes from above, is below the best found are skipped; from
        ``HALVES_SWEEP_ENTRIES`` entries on in two halves at once, :meth:`_full_sweep`) or
        the best rows of the last full sweep, from the contiguous copy it kept
        (:func:`light_sweep`; with ``split``, from ``HALVES_SWEEP_ENTRIES`` entries on in
        two halves at once, as the full sweeps: :meth:`_light_sweep`)."""
        if self.before_sweep is not None:
            self.before_sweep()
        self._track(v)
        if full or self._light is None:
            self._tighten(v, snap=True)
            layout = (self.row_ptr, self.remaining, self.succ, self.lower, self.gap, self.crit)
            if self._light is None:
                # slots as long as the best rows, filled by the sweep (gauss_seidel_sweep)
                self._light, self._light_rows = empty_slots(
                    self.best_row, self.row_ptr, self.succ.dtype
                )
            residual = self._full_sweep(v, layout, self._no_cache if bound is None else bound)
            if self._light_rows.size and self._light_rows.min() < 0:
                # a best row of another length than its slot
                self._light = regather_rows(self.best_row, self._light_rows, self._light, *layout)
                self._light_rows = self.best_row.copy()
        else:
            residual = self._light_sweep(v, split)
        self._rise = rose(self._rise, residual)
        return residual

    def _light_sweep(self, v: np.ndarray, split: bool) -> float:
        """A :func:`light_sweep`; with ``split``, from ``HALVES_SWEEP_ENTRIES`` entries of
        the copy on, a block Gauss-Seidel sweep of two halves of it (about equal entries)
        at once, as :meth:`_full_sweep` runs the full ones."""
        ptr, rem, succ, lower, gap, crit = self._light
        st, n, side = self.states, self.states.size, self.adversary_minimizes
        cut = int(np.searchsorted(ptr, ptr[-1] // 2)) if split else 0
        if ptr[-1] < HALVES_SWEEP_ENTRIES or not 0 < cut < n:
            return float(light_sweep(st, *self._light, v, side, self._last))

        def part(first: int, last: int, values: np.ndarray) -> float:
            rows = (ptr[first : last + 1], rem[first:last], succ, lower, gap, crit[first:last])
            return light_sweep(st[first:last], *rows, values, side, self._last)

        return _block_sweep(part, v, st, cut)

    def _tighten(self, v: np.ndarray, snap: bool = False) -> None:
        """Lower the sum of rises to its value at the start of the last full sweep plus the
        largest rise of a value since then, where that is less (``snap``: then keep ``v``
        as that start). A row's ``qbase`` was stored in a full sweep, relative to the sum
        at its start, from values at least those at its start, so it stays a bound: a rise
        of at most ``max(V' - V)`` since the last full sweep, which started a sum of rises
        that covered every earlier one, covers every later one (the largest rise over two
        spans is at most the sum of theirs). The sweeps between full ones add their
        residuals, the largest change of each, which overstates this when different states
        rise most in different sweeps."""
        if not self._qbase.size:
            return
        if self._snap.size == v.size:
            since = float(np.max(v - self._snap, initial=0.0))
            self._rise = min(self._rise, rose(self._snap_rise, since))
        if snap:
            self._snap = v.copy()
            self._snap_rise = self._rise

    def _track(self, v: np.ndarray) -> None:
        """The rise of ``v`` since the values after the last sweep added to the sum of rises
        (the first call only keeps ``v``)."""
        if self._last.size != v.size:
            self._last = v.copy()
        else:
            self._rise = rose(self._rise, rise_since(v, self._last))

    def _full_sweep(self, v: np.ndarray, layout: tuple, bound: np.ndarray) -> float:
        """A full :func:`gauss_seidel_sweep`; from ``HALVES_SWEEP_ENTRIES`` entries on a
        block Gauss-Seidel sweep of two halves of the states in sweep order (about equal
        entries) at once: the later half on the ``"sweep"`` worker, from a copy of ``v``
        that holds the earlier half's values as they were before the sweep, its values then
        copied into ``v``. Every value read is a lower bound, so every update is one, and
        the result does not depend on the threads' timing."""
        sides = (self.maximize, self.adversary_minimizes, bound, self._qbase)
        st, rows, best, top = self.states, self.state_rows, self.best_row, self._qmax
        light, slots = self._light, self._light_rows

        def part(first: int, last: int, values: np.ndarray) -> float:
            # the states first:last of the sweep order, on ``values``
            return gauss_seidel_sweep(
                st[first:last],
                rows[first : last + 1],
                *layout,
                values,
                best[first:last],
                *sides,
                top[first:last] if top.size else top,
                self._last,
                self._rise,
                light,
                slots[first:last] if slots.size else slots,
                first,
                self._bounded if BOUND_SKIP else _NO_FLAGS,
            )

        cut, n = self._cut, st.size
        if cut == 0:
            return float(part(0, n, v))
        return _block_sweep(part, v, st, cut)

    def track_changes(self, mark_above: float) -> None:
        """Prepare change tracking for the passes from above: a value that falls by more
        than ``mark_above`` makes its predecessors due."""
        ptr, inc_row, _, _ = self._model.incoming()
        due = np.ones(self._model.n_states, dtype=np.bool_)
        self._tracking = (due, ptr, inc_row, self._model.row_state, float(mark_above))
        self._tracked = False
        self._moved = self.states.size

    def moved_above(self, before: np.ndarray, after: np.ndarray) -> None:
        """Report that the upper values went from ``before`` to ``after`` (full vectors)
        outside the tracked passes: the predecessors of the states that moved become
        due."""
        if not self._tracked:
            return
        due, ptr, inc_row, row_state, mark_above = self._tracking
        moved = np.flatnonzero(np.abs(after - before) > mark_above).astype(np.int64)
        if moved.size:
            flag_predecessors(moved, ptr, inc_row, row_state, due)

    def upper_cache(self) -> np.ndarray:
        """A fresh row cache for lazy passes of :meth:`upper_pass` (every row unknown)."""
        return np.full(self.rows.size, np.inf)

    def upper_pass(
        self,
        u: np.ndarray,
        raise_violations: bool = False,
        cache: np.ndarray | None = None,
        track: bool = False,
    ) -> tuple[float, int]:
        """One pass of :func:`upper_sweep` on ``u`` in place: ``(max decrease,
        violations)``. With a ``cache`` (:meth:`upper_cache`; maximising strategies) the
        pass is lazy: ``u`` must not have increased anywhere since the last pass with that
        cache. ``track``: only the due states (after :meth:`track_changes`); such a pass
        skips states, so it certifies nothing and cannot repair a candidate."""
        if track and raise_violations:
            raise ValueError("a tracked pass skips states: it cannot repair a candidate")
        lazy = cache is not None
        track = track and self._tracking is not None
        if track and not self._tracked and self._moved <= TRACK_START * self.states.size:
            self._tracked = True  # every state is due: this pass flags for the next
        if track and self._tracked:
            tracking = self._tracking
        else:
            # untracked; a tracked call still counts the states moved by more than its bound
            above = self._tracking[4] if track else 0.0
            tracking = (_NOT_TRACKED, _NO_INDEX, _NO_INDEX, _NO_INDEX, above)
        untracked = tracking[0].size == 0
        use_top = (
            lazy
            and not raise_violations
            and untracked
            and self._top is not None
            and self._top[0] is cache
        )
        top = self._top[1:4] if use_top else _NO_TOP
        rows = self._top[4] if use_top else NO_LAYOUT
        dec, bad, moved, evaluated = upper_sweep(
            self.states,
            self.state_rows,
            self.row_ptr,
            self.remaining,
            self.succ,
            self.lower,
            self.gap,
            self.crit_up,
            u,
            self.maximize,
            self.adversary_minimizes,
            raise_violations,
            cache if lazy else self._no_cache,
            lazy,
            *tracking,
            *top,
            rows,
        )
        if track:
            self._moved = int(moved)
        if lazy and untracked:
            self._keep_top_rows(cache, int(evaluated), use_top)
        return float(dec), int(bad)

    def _keep_top_rows(self, cache: np.ndarray, evaluated: int, used: bool) -> None:
        """After an untracked lazy pass that evaluated at most ``TOP_ROWS_EVALUATIONS``
        rows per state: copy each state's top row for the next passes with this ``cache``
        (:func:`upper_sweep`), unless a copy in use has at most ``TOP_ROWS_STALE`` of its
        states stale."""
        n = self.states.size
        if evaluated > TOP_ROWS_EVALUATIONS * n:
            return
        if used and np.count_nonzero(self._top[3]) <= TOP_ROWS_STALE * n:
            return
        top, other = top_of_cache(self.state_rows, cache)
        layout = (self.row_ptr, self.remaining, self.succ, self.lower, self.gap, self.crit_up)
        rows = gather_rows(top, *layout)
        self._top = (cache, top, other, np.zeros(n, dtype=np.bool_), rows)

    def frozen(self) -> ReachSweeper:
        """A view for another thread, for :meth:`adversary_matrix` and :meth:`row_values`
        only: its own copy of the critical successors, which sweeps here may move."""
        view = copy.copy(self)
        view.crit = self.crit.copy()
        view.before_sweep = None
        return view

    def adversary_matrix(self, u: np.ndarray, rows: np.ndarray | None = None) -> sp.csr_matrix:
        """The adversary's distribution at ``u`` of every free row in the order of the
        constructor's ``free_rows`` (or at the positions ``rows`` of it), one per matrix
        row: :func:`planner.imdp.kernels.rows.row_distributions`, from the critical
        successors of the sweeps from below (copied): near the end of a solve the bracket
        is narrow and they stand at ``u`` too (on the random benchmark model all of them,
        against 72k of 517k rows stale in the lazy passes from above)."""
        back = np.empty_like(self._position)
        back[self._position] = np.arange(self._position.size)
        if rows is not None:
            back = back[rows]
        ptr, succ, prob = row_distributions(
            back,
            self.row_ptr,
            self.remaining,
            self.succ,
            self.lower,
            self.gap,
            self.crit.copy(),
            u,
            self.adversary_minimizes,
        )
        return sp.csr_matrix((prob, succ, ptr), shape=(back.size, self._model.n_states))

    def row_values(self, v: np.ndarray, slack: float | None = None) -> np.ndarray:
        """The robust expectation of ``v`` for every free row, in the order of the
        ``free_rows`` given to the constructor. With ``slack`` (``v`` the vector swept), a
        row shown worse than its state's best by more than ``slack`` from its last value
        (the sweeps' action elimination) may get a bound instead, at least its value and
        still worse than the best by more than ``slack`` (:func:`bounded_row_values`): the
        rows within ``slack`` of the best, and which they are, are exact."""
        q = np.empty(self.rows.size)
        layout = (self.row_ptr, self.remaining, self.succ, self.lower, self.gap, self.crit)
        bounded = slack is not None and self._qbase.size > 0 and self._last.size == v.size
        if bounded:
            self._track(v)
            self._tighten(v)
            work = self.row_ptr[self.state_rows]
            args = (self.state_rows, self.best_row, self._qbase, self._rise, float(slack))
            # the best rows from the light sweeps' copy, as the full sweeps read them
            light = NO_LAYOUT if self._light is None else self._light

            def fill(first: int, last: int) -> None:
                bounded_row_values(
                    first, last, q, *args, *layout, v, self.adversary_minimizes, light
                )

        else:
            work = self.row_ptr

            def fill(first: int, last: int) -> None:
                all_row_values(first, last, q, *layout, v, self.adversary_minimizes)

        if self.row_ptr[-1] >= HALVES_SWEEP_ENTRIES:
            in_halves(fill, work, "sweep")
        else:
            fill(0, work.size - 1)
        out = np.empty_like(q)
        out[self._position] = q
        return out


def _block_sweep(
    part: Callable[[int, int, np.ndarray], float], v: np.ndarray, states: np.ndarray, cut: int
) -> float:
    """A block Gauss-Seidel sweep of two halves at once: ``part(0, cut, v)`` here and
    ``part(cut, n, later)`` on the ``"sweep"`` worker, ``later`` a copy of ``v`` from
    before the sweep whose values of ``states[cut:]`` are then copied into ``v``; the
    largest change of the two."""
    later = v.copy()
    n = states.size
    rest, first = concurrently(lambda: part(cut, n, later), lambda: part(0, cut, v), "sweep")
    v[states[cut:]] = later[states[cut:]]
    return float(max(rest, first))


def sweep_layout(
    m: IMDP, free_rows: np.ndarray, fixed_val: np.ndarray, maximize: bool, adversary_minimizes: bool
) -> ReachSweeper:
    """The sweeps' layout of the free rows, the states in order of graph distance to the
    value-1 states of ``fixed_val`` (:func:`planner.imdp.kernels.layers.layers`)."""
    dist = layers(m, free_rows, fixed_val == 1.0)
    return ReachSweeper(m, free_rows, dist, maximize, adversary_minimizes)
