"""Upper bounds for reachability values, and their certificate.

The maximal (or minimal) reachability value ``V*`` of an interval MDP is the *least* fixed
point of its Bellman operator ``T`` with the targets held at 1. By Knaster-Tarski every
superharmonic vector, ``T(U) <= U`` (targets at 1), is at least the least fixed point, so
checking ``T(U) <= U`` once certifies ``U`` as an upper bound; no end-component analysis is
needed for the check. :func:`planner.imdp.kernels.upper_sweep` does the check and lowers
``U`` at the same time (a Gauss-Seidel pass that never raises a value; a pass without a
violation leaves a superharmonic vector, up to the floating-point allowance ``ROUNDING``
per state). What counts as the certificate is :func:`verify_upper`: the same inequality
shown in exact arithmetic.

The candidate (:func:`optimistic_candidate`, optimistic value iteration, Hartmanns and
Kaminski 2020) is ``min(1, L + delta)`` from the values ``L`` from below, lowered by a few
checking passes: cheap, and it passes where the values from below have settled to well
within ``delta`` *relative to their own pending change*. It fails where mass circulates
for a long time among free states (a slow leak, or strategies that can hover near a
value): there ``T(L + delta) - (L + delta)`` keeps the pending change of ``L``. The solver
then makes ``L`` exact by strategy iteration (when the model is small enough for its
sparse solves) and checks again: at the least fixed point ``V*`` itself,
``T(V* + delta) <= V* + delta`` always holds.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from planner._util.threads import in_halves
from planner.imdp.graph import end_component_labels, pruned_rows
from planner.imdp.kernels import ReachSweeper, component_exit_bound, counting_order
from planner.imdp.kernels.verify import raise_pass, state_excesses
from planner.imdp.model import IMDP, first_of_runs, row_entries
from planner.modes import Adversary

OVI_PASSES = 8
"""Checking passes per optimistic candidate."""


def check_upper(
    sweeper: ReachSweeper, u: np.ndarray, passes: int, raise_violations: bool = False
) -> tuple[bool, int]:
    """Up to ``passes`` checking passes on ``u`` in place; ``(certified, passes used)``.
    Stops early once the number of violations no longer decreases over two passes, or
    falls by less than ``CHECK_LEAST_FALL`` of it over two passes.
    ``raise_violations``: a violating state takes its Bellman value (a repair of the
    candidate; only a later pass without violations certifies it)."""

    def one_pass() -> int:
        return sweeper.upper_pass(u, raise_violations)[1]

    return _until_clean(one_pass, passes, CHECK_LEAST_FALL)


CHECK_LEAST_FALL = 0.05
""":func:`check_upper` gives up once two passes took off less than this share of the
violations. The failing candidates after a stalled interval iteration on the 100 x 100
benchmark grid (seeds 0-40: 6 candidates, none shown) kept 1,100-9,100 violations that
fell by 0.1-2 % a pass (one by 15 %, then 11 %, then under 6 %) and used all
``OVI_PASSES`` (95-126 ms each). The repairs' candidates there were shown in at most four
passes. :func:`verify_upper`, the proof, keeps the plain rule: one of its shown checks
there went 32, 26, 25, 26 violations before it fell to 0."""


def _until_clean(one_pass, passes: int, least_fall: float = 0.0) -> tuple[bool, int]:
    """Up to ``passes`` calls of ``one_pass`` (a pass returning its count of violations)
    until one finds none: ``(found none, passes made)``; gives up once the count has not
    fallen over two passes, or fell by less than ``least_fall`` of it over two passes."""
    counts: list[int] = []
    stalled = 0
    for k in range(1, passes + 1):
        bad = one_pass()
        if bad == 0:
            return True, k
        stalled = stalled + 1 if counts and bad >= counts[-1] else 0
        if stalled >= 2 or (len(counts) >= 2 and bad > (1.0 - least_fall) * counts[-2]):
            return False, k
        counts.append(bad)
    return False, passes


VERIFY_PASSES = 16
"""Passes of :func:`verify_upper` before it gives up."""


def verify_upper(
    model: IMDP,
    free_rows: np.ndarray,
    u: np.ndarray,
    maximize: bool,
    adversary_minimizes: bool,
    passes: int = VERIFY_PASSES,
    halves_entries: int | None = None,
) -> tuple[bool, np.ndarray]:
    """``(shown, U')``: ``U' >= u`` with ``T(U') <= U'`` shown in exact arithmetic on the
    states of ``free_rows`` (every other state's value is exact), so ``U' >= V*``
    (Knaster-Tarski) whatever floating point did before, for the interval polytopes of
    the rows (which the model's constructor made bracket 1 exactly); ``shown`` is
    ``False`` when
    ``passes`` passes of :func:`planner.imdp.kernels.verify.raise_pass` (each raising
    the states where a row may exceed ``U``) left violations, or when their number
    stopped falling over two passes (mass that circulates among states of nearly equal
    value for very long turns a violation of an ulp into a rise of an ulp per pass).
    From ``halves_entries`` entries of the checked rows on (default
    ``HALVES_ENTRIES``), the first pass's checks are made ahead on two threads."""
    m = model
    out = np.array(u, dtype=np.float64, copy=True)
    rows = np.asarray(free_rows, dtype=np.int64)
    if rows.size == 0:
        return True, out
    rs = m.row_state[rows]
    seg = first_of_runs(rs)
    state_rows = np.append(seg, rows.size).astype(np.int64)
    args = (rs[seg], state_rows, rows, m.row_ptr, m.successor, m.lower, m.upper, out)
    due = np.zeros(m.n_states, dtype=bool)
    due[rs[seg]] = True
    inc_ptr, _, inc_state, _, _ = m.reverse_index()
    sides = (maximize, adversary_minimizes)
    entries = np.concatenate(([0], np.cumsum(m.row_ptr[rows + 1] - m.row_ptr[rows])))
    known, stale = _NOTHING, np.zeros(0, dtype=bool)
    if entries[-1] >= (HALVES_ENTRIES if halves_entries is None else halves_entries):
        # the first pass's checks on two threads, from ``u`` as it is
        known, stale = np.empty(seg.size), np.zeros(m.n_states, dtype=bool)
        in_halves(
            lambda first, last: state_excesses(first, last, *args, *sides, known),
            entries[state_rows],
            "verify",
        )

    def one_pass() -> int:
        nonlocal known
        bad = raise_pass(*args, *sides, due, inc_ptr, inc_state, known, stale)
        known = _NOTHING
        return bad

    shown, _ = _until_clean(one_pass, passes)
    return shown, out


HALVES_ENTRIES = 200_000
"""Entries of the checked rows from which :func:`verify_upper` makes the checks of its
first pass on two threads (:func:`planner.imdp.kernels.verify.state_excesses`; the pass
itself then checks again only the states whose successors it raised before them, and is
the same as checking every state). On the 100 x 100 benchmark grid (1.4M entries) the
check takes 0.038-0.063 s instead of 0.049-0.088 s (seeds 0, 1, 2, 5), with the same
raises in every pass."""

_NOTHING = np.zeros(0)


def optimistic_candidate(
    sweeper: ReachSweeper, lower: np.ndarray, delta: float
) -> tuple[np.ndarray | None, int]:
    """``min(1, lower + delta)`` on the free states, checked; ``(U or None, passes)``."""
    u = lower.copy()
    st = sweeper.states
    u[st] = np.minimum(1.0, lower[st] + delta)
    ok, passes = check_upper(sweeper, u, OVI_PASSES)
    return (u if ok else None), passes


def free_end_components(
    model: IMDP, rows: np.ndarray, free: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`planner.imdp.graph.end_component_labels` (pessimistic) of the ``rows`` at the
    ``free`` states, searched for only among the states that survive the pruning cascade
    (:func:`planner.imdp.graph.pruned_rows`: a state goes once each of its rows may enter
    a state gone or not free). The survivors are the largest set of free states each with
    a row that stays among them, so every end component lies there, with rows that stay
    there: the same components and rows, and where none survives (every benchmark model:
    the cascade ends them all) no decomposition at all. On the random 100k-state benchmark
    model the cascade took 21-39 ms against 89-161 ms for the decomposition of all free
    states; on the 100 x 100 grid 15 ms against 23-25 ms."""
    m = model
    gone, stay = pruned_rows(m, ~free, rows)
    alive = free & ~gone
    if not alive.any():
        return np.full(m.n_states, -1, dtype=np.int64), np.zeros(m.n_rows, dtype=bool)
    return end_component_labels(m, stay, alive, Adversary.PESSIMISTIC)


class EndComponentBounds:
    """Bounds from the maximal end components of the free states, for maximal reachability
    against a minimising adversary (interval iteration with end-component deflation:
    Haddad and Monmege 2018; Eisentraut et al. 2018 for games).

    Components: the pessimistic maximal end components of the free rows (a row *stays* in
    ``C`` when every ``upper > 0`` successor lies in ``C``; targets and settled states lie
    in none). An *exit* of ``C`` is a row of a member state that does not stay.

    **Upper bound** (:meth:`deflate`; sound for *every* set ``C`` of free non-target
    states): ``V*(s) <= E_C(V*) = max`` over the exits ``r`` of ``C`` of ``T_r(V*)`` (0
    without exits). Proof: let ``W = max_C V* > E_C``, ``S`` the states of ``C`` at ``W``.
    A row of ``s`` in ``S`` attaining ``W`` stays (exits give at most ``E_C``) and, all
    successor values being at most ``W``, every feasible distribution of it lies in ``S``.
    Lowering ``V*`` on ``S`` by ``W - E'`` (``E' < W`` the largest value of the rows of
    ``S`` that are not closed in ``S``, and of ``E_C``) gives a vector ``U'`` with
    ``T(U') <= U'``; by Knaster-Tarski the least fixed point ``V*`` is at most ``U' <
    V*`` on ``S``: a contradiction. ``T`` and ``E_C`` are monotone, so from ``U >= V*``
    both ``min(U, T(U))`` and ``min(U, E_C(U))`` stay upper bounds: no certificate pass
    is needed.

    **Lower bound** (:meth:`collapse`, only on *traversable* components: strongly
    connected through the ``lower > 0`` entries of their staying rows): from every state
    of such a component the strategy can reach every other one almost surely without
    leaving it, whatever the adversary does (playing the staying rows uniformly, each
    forced edge is taken with probability at least ``lower / rows``), so ``V*(s) >=
    T_r(V*)`` for every exit ``r`` of the component, and from ``L <= V*``,
    ``max(L, E_C(L)) <= V*``.
    """

    def __init__(self, model: IMDP, sweeper: ReachSweeper, free: np.ndarray) -> None:
        m = model
        self.sweeper = sweeper
        row_mask = np.zeros(m.n_rows, dtype=bool)
        row_mask[sweeper.rows] = True
        comp, kept = free_end_components(m, row_mask, free)
        members = np.flatnonzero(comp >= 0)
        labels, label_of = np.unique(comp[members], return_inverse=True)
        n_comp = labels.size
        self.n_components = int(n_comp)
        if n_comp == 0:
            # no component (the usual case): nothing to deflate or collapse
            none = np.zeros(0, dtype=np.int64)
            _, self._member_ptr = counting_order(none, 0)
            self._members = self._exit_rows = self._all = self._traversable = none
            self._exit_ptr = self._member_ptr
            return
        dense = np.full(m.n_states, -1, dtype=np.int64)
        dense[members] = label_of
        order, self._member_ptr = counting_order(label_of.astype(np.int64), n_comp)
        self._members = members[order].astype(np.int64)
        row_comp = dense[m.row_state[sweeper.rows]]
        exits = np.flatnonzero((row_comp >= 0) & ~kept[sweeper.rows])
        order, self._exit_ptr = counting_order(row_comp[exits], n_comp)
        self._exit_rows = exits[order].astype(np.int64)
        self._all = np.arange(n_comp, dtype=np.int64)
        # traversable: one strongly connected component of the forced (lower > 0) entries
        # of the staying rows
        kept_rows = np.flatnonzero(kept)
        ent = row_entries(m, kept_rows)
        forced = m.lower[ent] > 0.0
        src = np.repeat(m.row_state[kept_rows], m.row_ptr[kept_rows + 1] - m.row_ptr[kept_rows])
        graph = sp.csr_matrix(
            (np.ones(int(forced.sum()), dtype=np.int8), (src[forced], m.successor[ent][forced])),
            shape=(m.n_states, m.n_states),
        )
        _, scc = connected_components(graph, directed=True, connection="strong")
        pairs = np.unique(np.stack([label_of, scc[members]]), axis=1)
        per_comp = np.bincount(pairs[0], minlength=n_comp)
        self._traversable = np.flatnonzero(per_comp == 1).astype(np.int64)

    def _apply(self, v: np.ndarray, comps: np.ndarray, crit: np.ndarray, raise_values: bool):
        sw = self.sweeper
        if comps.size:
            component_exit_bound(
                self._exit_rows,
                self._exit_ptr,
                self._members,
                self._member_ptr,
                comps,
                sw.row_ptr,
                sw.remaining,
                sw.succ,
                sw.lower,
                sw.gap,
                crit,
                v,
                sw.adversary_minimizes,
                raise_values,
            )

    def deflate(self, u: np.ndarray) -> None:
        """``u = min(u, E_C(u))`` on every component, in place (an upper bound stays one)."""
        self._apply(u, self._all, self.sweeper.crit_up, False)

    def collapse(self, v: np.ndarray) -> None:
        """``v = max(v, E_C(v))`` on the traversable components, in place (a lower bound
        stays one)."""
        self._apply(v, self._traversable, self.sweeper.crit, True)
