"""Graph-exact analyses of interval MDPs: reachability sets, end components, sub-models.

Qualitative questions are decided on the boolean structure of the bounds, never by
comparing computed probabilities with 0 or 1:

* ``upper > 0``: the adversary *may* use the edge (it is in every analysis where the run
  might take it);
* ``lower > 0``: the adversary *must* use the edge;
* the interval constraint of a row: every adversary puts mass at least
  ``max(sum_{j in X} l_j, 1 - sum_{j not in X} u_j)`` into a successor set ``X``; whether
  the second term is positive is decided exactly (the model's constructor has already
  made every single entry's ``lower > 0`` and ``upper > 0`` exact, and made every row
  bracket 1 exactly).

Row masks ``rows`` (shape ``(n_rows,)``) restrict the actions a controller may use (a
sub-model); state masks have shape ``(n_states,)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from planner.errors import SpecificationError
from planner.imdp.closed import closed_accepting
from planner.imdp.kernels import (
    attractor,
    attractor_of_rows,
    drop_states,
    forward_reach,
    layers,
    maximal_end_components_kernel,
    prune_kernel,
    rows_staying_in,
)
from planner.imdp.kernels.exact import row_sum_signs
from planner.imdp.model import IMDP, first_of_runs
from planner.modes import Adversary


@dataclass(frozen=True)
class EndComponent:
    """An end component ``(T, Act)``: its states and the rows (state, action) it keeps.

    Attributes:
        states: sorted state indices of ``T``.
        rows: sorted row indices of ``Act`` (every row of ``model.row_state[rows]`` is in T).
        pair: the Rabin pair an accepting component satisfies (-1: not applicable).
    """

    states: np.ndarray
    rows: np.ndarray
    pair: int = -1
    """For accepting components: the index of the Rabin pair they satisfy."""

    def state_mask(self, n_states: int) -> np.ndarray:
        mask = np.zeros(n_states, dtype=bool)
        mask[self.states] = True
        return mask

    def row_mask(self, n_rows: int) -> np.ndarray:
        mask = np.zeros(n_rows, dtype=bool)
        mask[self.rows] = True
        return mask

    def __len__(self) -> int:
        return int(self.states.size)


def _all_rows(model: IMDP, rows: np.ndarray | None) -> np.ndarray:
    if rows is None:
        return np.ones(model.n_rows, dtype=bool)
    rows = np.asarray(rows, dtype=bool)
    if rows.shape != (model.n_rows,):
        raise SpecificationError(f"row mask must have shape ({model.n_rows},), got {rows.shape}")
    return rows


def rows_from_actions(model: IMDP, allowed: np.ndarray) -> np.ndarray:
    """Row mask of an ``(n_states, n_actions)`` mask of allowed actions."""
    allowed = np.asarray(allowed, dtype=bool)
    if allowed.shape != (model.n_states, model.n_actions):
        raise SpecificationError(
            f"action mask must have shape ({model.n_states}, {model.n_actions}), "
            f"got {allowed.shape}"
        )
    return allowed[model.row_state, model.row_action]


def actions_from_rows(model: IMDP, rows: np.ndarray) -> np.ndarray:
    """``(n_states, n_actions)`` mask of the actions whose rows are set in ``rows``."""
    out = np.zeros((model.n_states, model.n_actions), dtype=bool)
    rows = np.asarray(rows, dtype=bool)
    out[model.row_state[rows], model.row_action[rows]] = True
    return out


def has_row(model: IMDP, rows: np.ndarray) -> np.ndarray:
    """States with at least one row set in ``rows``."""
    # every state has at least one row (the model validates it)
    return np.logical_or.reduceat(np.asarray(rows, dtype=bool), model.state_ptr[:-1])


def _row_any(model: IMDP, entry_flags: np.ndarray) -> np.ndarray:
    # every row has at least one entry (the model validates it), so no segment is empty
    return np.logical_or.reduceat(entry_flags, model.row_ptr[:-1])


def stays_in(model: IMDP, mask: np.ndarray) -> np.ndarray:
    """Rows whose every possible successor (``upper > 0``) lies in ``mask``."""
    leaves = (model.upper > 0) & ~mask[model.successor]
    return ~_row_any(model, leaves)


def forced_into(model: IMDP, mask: np.ndarray) -> np.ndarray:
    """Rows that put positive mass into ``mask`` under *every* adversary.

    True iff some ``lower > 0`` edge enters ``mask``, or an ``upper > 0`` edge enters it
    and the upper bounds of the edges outside ``mask`` sum to less than 1 (exactly).
    """
    inside = mask[model.successor]
    must = _row_any(model, (model.lower > 0) & inside)
    outside = np.where(inside, 0.0, model.upper)
    touches = _row_any(model, inside & (model.upper > 0))
    return must | (touches & (_sum_sign(model, outside) < 0))


def may_stay_in(model: IMDP, mask: np.ndarray) -> np.ndarray:
    """Rows for which *some* adversary keeps all mass in ``mask``.

    No ``lower > 0`` edge leaves ``mask`` and the upper bounds inside sum to at least 1
    (exactly).
    """
    inside = mask[model.successor]
    must_leave = _row_any(model, (model.lower > 0) & ~inside)
    return ~must_leave & (_sum_sign(model, np.where(inside, model.upper, 0.0)) >= 0)


def _sum_sign(model: IMDP, entry_values: np.ndarray) -> np.ndarray:
    """Per row, the sign of the exact ``sum - 1`` of ``entry_values`` (values in ``[0,
    1]``; :func:`planner.imdp.kernels.exact.row_sum_signs`)."""
    return row_sum_signs(model.row_ptr, np.ascontiguousarray(entry_values, dtype=np.float64))


def state_graph(model: IMDP, rows: np.ndarray | None = None) -> sp.csr_matrix:
    """Adjacency ``(n_states, n_states)`` of the edges ``upper > 0`` of the rows in ``rows``."""
    rows = _all_rows(model, rows)
    keep = rows[model.entry_row] & (model.upper > 0)
    # entries are sorted by state: the kept successors already are CSR column indices
    # (duplicates, from several actions, are parallel edges)
    counts = np.bincount(model.row_state[model.entry_row[keep]], minlength=model.n_states)
    indptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    dst = model.successor[keep]
    return sp.csr_matrix(
        (np.ones(dst.size, dtype=np.int8), dst, indptr), shape=(model.n_states,) * 2
    )


def possible_reach(
    model: IMDP,
    target: np.ndarray,
    avoid: np.ndarray | None = None,
    rows: np.ndarray | None = None,
) -> np.ndarray:
    """States with best-case probability > 0 of reaching ``target`` without ``avoid``.

    Backward breadth-first search over ``upper > 0`` edges (one pass, ``O(entries)``).
    """
    target, rows = reach_rows(model, target, avoid, rows)
    return layers(model, rows, target) < np.inf


def recurrence_candidates(
    model: IMDP, good: np.ndarray, states: np.ndarray, rows: np.ndarray | None = None
) -> np.ndarray:
    """The ``states`` reachable from a ``good`` one and able to reach one (the ``good``
    states among ``states`` included) along ``upper > 0`` entries of ``rows`` that stay
    among ``states``: two breadth-first searches, ``O(entries)``. An end component inside
    ``states`` that contains a ``good`` state is strongly connected, so it lies within
    them: the end components that must visit ``good`` can be searched for there alone."""
    rows = _all_rows(model, rows)
    states = np.asarray(states, dtype=bool)
    src = np.asarray(good, dtype=bool) & states
    back = possible_reach(model, src, ~states, rows)
    rows = rows & states[model.row_state]
    fwd = forward_reach(
        src, rows, model.state_ptr, model.row_ptr, model.successor, model.upper, states
    )
    return back & fwd


def robust_positive_reach(
    model: IMDP,
    target: np.ndarray,
    avoid: np.ndarray | None = None,
    rows: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """States whose worst-case probability of ``(!avoid) U target`` is positive.

    Returns ``(mask, row)``: ``row[s]`` is a row of ``s`` that forces positive mass one
    layer closer to ``target`` (-1 for targets and states outside the set).
    """
    target, cand = reach_rows(model, target, avoid, rows)
    return _attractor(model, target.copy(), cand)


def reach_rows(
    model: IMDP, target: np.ndarray, avoid: np.ndarray | None, rows: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """``(target, rows)`` of a ``(!avoid) U target`` search: the target as a mask, and the
    allowed rows (all by default) of the states neither in ``target`` nor in ``avoid``."""
    rows = _all_rows(model, rows)
    target = np.asarray(target, dtype=bool)
    avoid = np.zeros(model.n_states, dtype=bool) if avoid is None else np.asarray(avoid, bool)
    return target, rows & (~avoid & ~target)[model.row_state]


def _attractor(
    model: IMDP, start: np.ndarray, cand_rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Robust attractor: add states with a candidate row forced into the set (a work list
    in compiled code, :func:`planner.imdp.kernels.attractor`): every state that joins
    re-examines only the rows with an entry into it. ``choice[s]``: the row by which ``s``
    joined; it puts positive mass, under every adversary, into states that joined before
    ``s``. Few candidate rows (a strategy's) are searched on their own (their own reverse
    index: :func:`planner.imdp.kernels.attractor_of_rows`)."""
    start, cand_rows = np.asarray(start, dtype=bool), np.asarray(cand_rows, dtype=bool)
    rows = np.flatnonzero(cand_rows)
    if rows.size * COMPACT_FRACTION <= model.n_rows:
        m = model
        return attractor_of_rows(start, rows, m.row_state, m.row_ptr, m.successor, m.lower, m.upper)
    x, choice, _ = attractor(start, cand_rows, *attractor_arrays(model), False, True)
    return x, choice


COMPACT_FRACTION = 32
"""A robust attractor with at most ``1 / COMPACT_FRACTION`` of the rows as candidates runs
on those rows alone (their own reverse index costs more than the model's saves beyond
that: 26,514 and 20,996 of the 236,403 rows of the benchmark grid's product took 17.7 and
12.5 ms alone, 11.6 and 5.5 ms on the model's index; 64,611 of the random model's 800,000
67 ms against 48 ms, 19,802 of them 15.6 ms against 32 ms)."""


def attractor_arrays(model: IMDP) -> tuple[np.ndarray, ...]:
    """The model's arrays that :func:`planner.imdp.kernels.attractor` reads after its
    start and candidate rows: the rows, the entries and the reverse index."""
    m = model
    return (m.row_state, m.row_ptr, m.successor, m.lower, m.upper, *m.reverse_index())


def robust_almost_sure_reach(
    model: IMDP,
    target: np.ndarray,
    avoid: np.ndarray | None = None,
    rows: np.ndarray | None = None,
    region: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """States whose worst-case probability of ``(!avoid) U target`` is 1 (within ``region``).

    The interval version of the classic probability-1 algorithm: shrink a candidate set
    ``U`` (initially ``region`` minus ``avoid``) to the robust attractor of ``target``
    computed with the rows that cannot leave ``U`` (every ``upper > 0`` edge inside),
    until it no longer shrinks; states left without such a row go at once, with the rows
    into them, in a cascade (:func:`planner.imdp.kernels.drop_states`), so a round is
    needed only for the losses the cascade cannot see (on the 100 x 100 benchmark grid's
    product one round instead of 16). Under the returned strategy every row stays in ``U``
    and moves one attractor layer closer with a probability bounded away from 0 under every
    adversary, so the target is reached almost surely.

    Returns ``(mask, row)``: the set and a strategy (row index per state, -1 on targets
    and outside the set).
    """
    rows = _all_rows(model, rows)
    target = np.asarray(target, dtype=bool)
    m = model
    u = np.ones(m.n_states, bool) if region is None else np.asarray(region, dtype=bool).copy()
    if avoid is not None:
        u &= ~np.asarray(avoid, dtype=bool) | target
    inc_ptr, inc_row, _, _, inc_upper = m.reverse_index()
    # the rows of U (targets excluded) that cannot leave U, U without the states left with
    # none (a cascade that each round's losses continue: O(entries) in all)
    cascade = (m.row_state, m.state_ptr, inc_ptr, inc_row, inc_upper, target)
    out, stay, live = prune_kernel(
        ~u, rows & ~target[m.row_state], m.row_state, m.state_ptr, m.row_ptr,
        m.successor, m.upper, inc_ptr, inc_row, inc_upper, target,
    )  # fmt: skip
    while True:
        u = ~out
        x, choice = _attractor(model, target & u, stay)
        x &= u
        if np.array_equal(x, u):
            choice[~u] = -1
            return u, choice
        drop_states(np.flatnonzero(u & ~x), out, stay, live, *cascade)


def maximal_end_components(
    model: IMDP,
    rows: np.ndarray | None = None,
    states: np.ndarray | None = None,
    mode: Adversary = Adversary.PESSIMISTIC,
) -> list[EndComponent]:
    """Maximal end components, by iterated strongly-connected-component decomposition.

    ``mode="pessimistic"``: a row belongs to an end component only if *every* possible
    successor (``upper > 0``) lies in the component, whatever the adversary does.
    ``mode="optimistic"``: the adversary cooperates; a row belongs if some adversary keeps
    it inside (:func:`may_stay_in`), and the component is strongly connected through
    ``upper > 0`` edges (a cooperative adversary can realise every such edge).

    Note that a pessimistic end component is closed but need not be *visited fully* under
    every adversary (it can cut edges with ``lower == 0``); use
    :func:`accepting_end_components` for the robust acceptance question.
    """
    if mode not in tuple(Adversary):
        raise SpecificationError(f"mode must be 'pessimistic' or 'optimistic', got {mode!r}")
    comp, kept = end_component_labels(model, rows, states, mode)
    return components_from_labels(model, comp, kept)


def end_component_labels(
    model: IMDP,
    rows: np.ndarray | None = None,
    states: np.ndarray | None = None,
    mode: Adversary = Adversary.PESSIMISTIC,
) -> tuple[np.ndarray, np.ndarray]:
    """The maximal end components as labels: ``(comp, rows)``, ``comp[s]`` the component
    of ``s`` (-1: none) and the rows they keep (see :func:`maximal_end_components`;
    compiled: :func:`planner.imdp.kernels.maximal_end_components_kernel`)."""
    r = _all_rows(model, rows)
    s = np.ones(model.n_states, dtype=bool) if states is None else np.asarray(states, bool)
    m = model
    arrays = (m.n_states, m.row_state, m.row_ptr, m.successor, m.lower, m.upper)
    # the reverse index: (ptr, rows, states, lower, upper), the kernel's next arguments
    optimistic = mode == Adversary.OPTIMISTIC
    return maximal_end_components_kernel(*arrays, *m.reverse_index(), r, s, optimistic)


def components_from_labels(model: IMDP, comp: np.ndarray, kept: np.ndarray) -> list[EndComponent]:
    """:class:`EndComponent` objects (sorted by their first state) of component labels."""
    idx = np.flatnonzero(comp >= 0)
    if idx.size == 0:
        return []
    order = np.argsort(comp[idx], kind="stable")
    labels = comp[idx][order]
    starts = first_of_runs(labels)
    groups = np.split(idx[order], starts[1:])
    row_idx = np.flatnonzero(kept)
    row_comp = comp[model.row_state[row_idx]]
    ro = np.argsort(row_comp, kind="stable")
    rstarts = first_of_runs(row_comp[ro])
    row_groups = dict(
        zip(row_comp[ro][rstarts].tolist(), np.split(row_idx[ro], rstarts[1:]), strict=True)
    )
    out = [
        EndComponent(np.sort(g), np.sort(row_groups[int(c)]))
        for c, g in zip(labels[starts].tolist(), groups, strict=True)
    ]
    out.sort(key=lambda ec: int(ec.states[0]))
    return out


def robust_buchi_region(
    model: IMDP,
    good: np.ndarray,
    states: np.ndarray,
    rows: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Largest ``T`` inside ``states`` from which ``good`` is visited infinitely often with
    probability 1 under every adversary, never leaving ``T``.

    Returns ``(mask, rows)``: ``T`` and the rows that stay in ``T``.
    """
    rows = _all_rows(model, rows)
    good = np.asarray(good, dtype=bool)
    t = np.asarray(states, dtype=bool).copy()
    none = np.zeros(model.n_states, dtype=bool)
    while True:
        # the rows of T whose every possible successor lies in T
        r = rows_staying_in(
            t, rows, model.row_state, model.row_ptr, model.successor, model.upper, none
        )
        w, _ = robust_almost_sure_reach(model, good & t & has_row(model, r), rows=r, region=t)
        if np.array_equal(w, t):
            return t, r
        t = w


def accepting_end_components(
    model: IMDP,
    good: np.ndarray,
    bad: np.ndarray,
    rows: np.ndarray | None = None,
) -> list[EndComponent]:
    """Robustly accepting maximal end components of a Rabin pair ``(good, bad)``.

    An end component qualifies if it avoids ``bad`` and, using only its rows, visits
    ``good`` infinitely often with probability 1 under *every* adversary. (An SCC held
    together by edges with ``lower == 0`` does not qualify when the adversary can cut the
    way to ``good``.) Computed by alternating :func:`robust_buchi_region` with the MEC
    decomposition until each component is its own Büchi region, from the states that avoid
    ``bad`` and lie between ``good`` states (:func:`recurrence_candidates`). Where no row
    leaves ``good & ~bad`` (:func:`planner.imdp.closed.closed_accepting`) every end
    component inside it qualifies and no other does: its maximal end components.
    """
    rows = _all_rows(model, rows)
    closed = closed_accepting(model, good, bad, rows)
    if closed is not None:
        return maximal_end_components(model, rows=rows, states=closed)
    good = np.asarray(good, dtype=bool)
    start = recurrence_candidates(model, good, ~np.asarray(bad, dtype=bool), rows)
    out: list[EndComponent] = []
    work = [start]
    while work:
        region = work.pop()
        t, r = robust_buchi_region(model, good, region, rows)
        for ec in maximal_end_components(model, rows=r, states=t, mode=Adversary.PESSIMISTIC):
            mask = ec.state_mask(model.n_states)
            ec_rows = np.zeros(model.n_rows, dtype=bool)
            ec_rows[ec.rows] = True
            t2, _ = robust_buchi_region(model, good, mask, ec_rows)
            if np.array_equal(t2, mask):
                out.append(ec)
            elif t2.any():
                work.append(t2)
    out.sort(key=lambda ec: int(ec.states[0]))
    return out


def optimistic_accepting_end_components(
    model: IMDP,
    good: np.ndarray,
    bad: np.ndarray,
    rows: np.ndarray | None = None,
) -> list[EndComponent]:
    """End components (cooperative adversary) that avoid ``bad`` and contain a ``good``
    state (searched for among :func:`recurrence_candidates`)."""
    comp, kept = _optimistic_accepting_labels(model, good, bad, rows)
    return components_from_labels(model, comp, kept)


def optimistic_accepting_states(
    model: IMDP,
    good: np.ndarray,
    bad: np.ndarray,
    rows: np.ndarray | None = None,
) -> np.ndarray:
    """Union of the states of :func:`optimistic_accepting_end_components` (a mask)."""
    comp, _ = _optimistic_accepting_labels(model, good, bad, rows)
    return comp >= 0


def _optimistic_accepting_labels(model, good, bad, rows):
    good = np.asarray(good, dtype=bool)
    states = recurrence_candidates(model, good, ~np.asarray(bad, dtype=bool), rows)
    comp, kept = end_component_labels(model, rows=rows, states=states, mode=Adversary.OPTIMISTIC)
    accepted = np.unique(comp[good & (comp >= 0)])
    comp = np.where(np.isin(comp, accepted), comp, -1)
    return comp, kept & (comp[model.row_state] >= 0)


@dataclass(frozen=True)
class SubModel:
    """A sub-model: the states kept and the rows (actions) allowed there.

    Attributes:
        states: ``(n_states,)`` mask of the states that keep at least one allowed action.
        rows: ``(n_rows,)`` mask of the allowed rows.
        actions: ``(n_states, n_actions)`` mask of the allowed actions.
    """

    states: np.ndarray
    rows: np.ndarray
    actions: np.ndarray


def pruned_rows(
    model: IMDP, removed: np.ndarray, rows: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The cascade of :func:`prune` without the sub-model: ``(gone, kept)``, the states
    removed (``removed`` and those left without rows) and the rows kept."""
    m = model
    ptr, inc_row, _, inc_upper = m.incoming()
    gone, kept, _ = prune_kernel(
        np.asarray(removed, dtype=bool), _all_rows(m, rows), m.row_state, m.state_ptr,
        m.row_ptr, m.successor, m.upper, ptr, inc_row, inc_upper, np.zeros(m.n_states, bool),
    )  # fmt: skip
    return gone, kept


def prune(model: IMDP, removed: np.ndarray, rows: np.ndarray | None = None) -> SubModel:
    """Remove the rows that may enter ``removed``, then the states left without rows, and
    repeat until nothing changes (Jiang et al. 2023, Algorithm 1)."""
    gone, kept = pruned_rows(model, removed, rows)
    return SubModel(~gone, kept, actions_from_rows(model, kept))
