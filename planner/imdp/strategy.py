"""Strategies of reachability and reward problems: robust strategy iteration for maximal
reachability (exact evaluation against the adversary's best response, strict improvements)
and the optimal rows or actions for given values."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from planner.errors import SpecificationError
from planner.imdp import graph
from planner.imdp.evaluate import strategy_reach_value
from planner.imdp.kernels.rows import greedy_rows
from planner.imdp.model import IMDP, first_of_runs, row_entries, run_ids
from planner.imdp.ordering import OrderingAdversary
from planner.imdp.problem import DiscountedReward, ReachAvoid
from planner.imdp.stay import surest_exit_start

MAX_IMPROVEMENTS = 100
"""Strategy improvement rounds per strategy iteration."""

SI_MAX_STATES = 20_000
"""Strategy iteration (and the stay policy iteration of the rounding widening) only for at
most this many free states: its sparse LU solves can fill in badly on large unstructured
graphs (a 3000-state random model: ~0.5 s each)."""


def strategy_iteration(
    m: IMDP,
    free_rows: np.ndarray,
    v: np.ndarray,
    fixed_val: np.ndarray,
    adversary_minimizes: bool,
    tol: float,
    max_rounds: int | None = None,
    sound: bool = True,
    start: np.ndarray | None = None,
) -> tuple[np.ndarray | None, np.ndarray | None, int]:
    """Robust strategy iteration for maximal reachability, started from a strategy
    greedy for ``v`` (among its optimal rows, the surest exit: :func:`_surest_start`).

    Returns ``(values, strategy, evaluations)``: ``V_sigma`` of the last strategy
    evaluated (``None`` if the first evaluation gave up), that strategy (one row per free
    state) if no state wanted to switch any more, else ``None``, and the number of
    strategies evaluated.

    Each round evaluates ``sigma`` exactly (:func:`strategy_reach_value`: the adversary's
    best response included) and switches a state to its best row only where that row's
    robust value exceeds the current row's by more than ``tol / 100``, both taken at the
    computed values of ``sigma`` (the returned values are those lowered by their error
    bounds: the bounds differ from state to state, by up to 1e-11, and at them near-equal
    rows looked better by their successors' bounds; the repairs of the 100 x 100
    benchmark grid's seeds 0 and 2, on 597 and 466 states, took 4 and 9 evaluations
    instead of 6 and 10). Because switches are strict, ``V_sigma`` never decreases and no
    new end component can trap mass that had a positive value; when no state switches,
    ``V_sigma`` is a fixed point of the Bellman operator (within the slack) and, being a
    strategy's value, at most the least fixed point: it *is* the least fixed point. With a
    cooperating adversary each round evaluates the chain of ``sigma`` and the adversary
    greedy for the last values (a lower bound, not ``V_sigma``): the values stay sound,
    the strategy is not returned.
    ``sound=False``: the evaluations are not lowered by their rounding bound (the values
    are then a candidate, not a lower bound; see :func:`strategy_reach_value`).
    ``start``: the first strategy (one row of ``free_rows`` per free state, in state
    order) instead of the greedy one, e.g. the result of a related strategy iteration.
    """
    rs = m.row_state[free_rows]
    seg = first_of_runs(rs)
    seg_id = run_ids(rs)
    full = OrderingAdversary(m, adversary_minimizes, rows=free_rows)
    if start is None:
        q = full.expectation(v)
        choice = strategy_rows(m, free_rows, q, seg, rs[seg], v, True, True, tol)
        sigma = _surest_start(full.matrix(v), free_rows, rs, q, seg, v, choice[rs[seg]], tol)
    else:
        sigma = np.asarray(start, dtype=np.int64)
        if (
            sigma.shape != seg.shape
            or not np.isin(sigma, free_rows).all()
            or not np.array_equal(m.row_state[sigma], rs[seg])
        ):
            raise SpecificationError(
                "start must give one of the free rows per free state, in state order "
                f"({seg.size} states)"
            )
    slack = tol * 1e-2
    best: np.ndarray | None = None
    limit = MAX_IMPROVEMENTS if max_rounds is None else max_rounds
    for rounds in range(1, limit + 1):
        start = v if best is None else best
        out = strategy_reach_value(m, sigma, fixed_val, adversary_minimizes, start, sound=sound)
        if out is None:
            return best, None, rounds
        x, computed = out
        best = x if best is None else np.maximum(best, x)
        q = full.expectation(computed)
        q_best = np.maximum.reduceat(q, seg)
        q_sigma = q[np.searchsorted(free_rows, sigma)]
        better = q_best > q_sigma + slack
        if not better.any():
            # a cooperating adversary is only evaluated for one order (a lower bound), so
            # only the opposing adversary's case yields an exactly evaluated strategy
            return best, (sigma if adversary_minimizes else None), rounds
        top = np.flatnonzero(q >= q_best[seg_id])
        top = top[first_of_runs(seg_id[top])]  # one best row per state, in state order
        sigma = np.where(better, free_rows[top], sigma)
    return best, None, limit


def independent_parts(m: IMDP, rows: np.ndarray, states: np.ndarray) -> list[np.ndarray]:
    """``rows`` (sorted, the rows of the masked ``states``) in at most two parts of whole
    weakly connected components of the graph the states form through the rows' entries
    that may carry mass (``upper > 0``) to another of ``states``: held at values outside,
    each part's chains never reach the other's states, so :func:`strategy_iteration` on
    the parts finds what it finds on all of them (values, strategy; each part stops after
    its own improvement rounds). Components in decreasing row count go to the first part
    until it holds half of the rows, the rest to the second (the first part is at least
    the largest component)."""
    rs = m.row_state[rows]
    members = rs[first_of_runs(rs)]
    local = np.full(m.n_states, -1, dtype=np.int64)
    local[members] = np.arange(members.size)
    ent = row_entries(m, rows)
    src = np.repeat(local[rs], m.row_ptr[rows + 1] - m.row_ptr[rows])
    dst = m.successor[ent]
    keep = states[dst] & (m.upper[ent] > 0.0)
    graph_ = sp.csr_matrix(
        (np.ones(int(keep.sum()), dtype=np.int8), (src[keep], local[dst[keep]])),
        shape=(members.size, members.size),
    )
    n, label = connected_components(graph_, directed=True, connection="weak")
    if n < 2:
        return [rows]
    row_label = label[local[rs]]
    weight = np.bincount(row_label, minlength=n)
    order = np.argsort(-weight, kind="stable")
    before = np.cumsum(weight[order]) - weight[order]
    second = np.zeros(n, dtype=bool)
    second[order] = 2 * before >= rows.size
    in_second = second[row_label]
    return [rows[~in_second], rows[in_second]]


def _surest_start(
    matrix: sp.csr_matrix,
    free_rows: np.ndarray,
    rs: np.ndarray,
    q: np.ndarray,
    seg: np.ndarray,
    v: np.ndarray,
    sigma: np.ndarray,
    tol: float,
) -> np.ndarray:
    """The first strategy of :func:`strategy_iteration`: among the rows optimal for ``v``
    (:func:`optimal_rows`, as in :func:`strategy_rows`), the greedy surest exit
    (:func:`planner.imdp.stay.surest_exit_start`) of the adversary's chain at ``v``
    (``matrix``, one distribution per free row), mass into states of value 0 counting as
    staying; ``sigma`` (the robust-attractor rows of :func:`strategy_rows`) where no such
    chain leaves. The attractor alone may take rows whose only way on is a tail of 1e-20
    and that lose their value on the way: on the 100 x 100 benchmark grid the first
    strategy was then worth about 0 where ``v`` was about 1. Only the number of improvement
    rounds depends on this choice; every round is evaluated exactly."""
    near = optimal_rows(q, seg, rs, True, tol)
    chains = sp.csr_matrix(matrix)[near].tocoo()
    dead = v[chains.col] <= 0.0
    cols = np.where(dead, rs[near][chains.row], chains.col)
    chains = sp.csr_matrix((chains.data, (chains.row, cols)), shape=chains.shape)
    pick = surest_exit_start(chains, rs[near], np.searchsorted(free_rows[near], sigma))
    return free_rows[near[pick]]


def optimal_slack(tol: float) -> float:
    """How far below its state's best a row's value may be and the row still count as
    optimal: ``max(10 tol, 1e-12)``."""
    return max(10 * tol, 1e-12)


def state_best(q: np.ndarray, seg: np.ndarray, rs: np.ndarray, maximize: bool) -> np.ndarray:
    """Per row (values ``q``, states ``rs`` in runs starting at ``seg``) its state's best
    value."""
    return (np.maximum if maximize else np.minimum).reduceat(q, seg)[run_ids(rs)]


def optimal_rows(
    q: np.ndarray, seg: np.ndarray, rs: np.ndarray, maximize: bool, tol: float
) -> np.ndarray:
    """Indices of the rows (values ``q``, states ``rs`` in runs starting at ``seg``)
    within :func:`optimal_slack` of their state's best: the rows that count as optimal."""
    best = state_best(q, seg, rs, maximize)
    return np.flatnonzero(np.abs(q - best) <= optimal_slack(tol))


def strategy_actions(
    m: IMDP,
    free_rows: np.ndarray,
    q_free: np.ndarray,
    seg: np.ndarray,
    seg_states: np.ndarray,
    v: np.ndarray,
    maximize: bool,
    prop: ReachAvoid | DiscountedReward,
    tol: float,
) -> np.ndarray:
    """Memoryless strategy: an optimal action per free state (-1 elsewhere)."""
    reach_max = isinstance(prop, ReachAvoid) and maximize
    choice = strategy_rows(m, free_rows, q_free, seg, seg_states, v, maximize, reach_max, tol)
    return np.where(choice >= 0, m.row_action[np.maximum(choice, 0)], -1)


def strategy_rows(
    m: IMDP,
    free_rows: np.ndarray,
    q_free: np.ndarray,
    seg: np.ndarray,
    seg_states: np.ndarray,
    v: np.ndarray,
    maximize: bool,
    reach_max: bool,
    tol: float,
) -> np.ndarray:
    """An optimal row per free state (-1 elsewhere).

    Each state takes its greedy row (the first of its best, exactly). For maximal
    reachability that is kept where the greedy rows lead out of the free states under
    every adversary (their robust attractor from the states already settled: value fixed,
    or 0). Elsewhere a row among those that count as optimal is picked by the attractor
    from there, so the strategy cannot idle inside an end component whose optimal rows
    all tie: each chosen row moves one layer closer with positive probability under every
    adversary. (Picking by the attractor among all optimal rows everywhere, rows short of
    the best by up to the slack at every step with a forced way on of tiny probability,
    left the strategy of the 100 x 100 benchmark grid's uncertified solve, seed 0, worth 0
    at 7,393 of its 9,908 free states.) Where no state has two optimal rows there is
    nothing to pick, and no attractor is computed (on the random 100k-state benchmark
    model none has: 0.065 s to 0.012-0.014 s).
    """
    n = m.n_states
    choice = np.full(n, -1, dtype=np.int64)
    if free_rows.size == 0:
        return choice
    # the greedy rows: the first of each state's best (exactly; the others that count as
    # optimal may be short of it by up to the slack at every step)
    greedy, tied = greedy_rows(q_free, seg, maximize, optimal_slack(tol))
    choice[seg_states] = free_rows[greedy]
    if reach_max and tied:
        rs = m.row_state[free_rows]
        opt_local = optimal_rows(q_free, seg, rs, maximize, tol)
        free = np.zeros(n, dtype=bool)
        free[seg_states] = True
        settled = ~free | (v <= 0)
        # the greedy rows where they leave the free states under every adversary (their
        # value is then the states' value: no slack lost); elsewhere rows that count as
        # optimal, picked by the attractor from there
        cand = np.zeros(m.n_rows, dtype=bool)
        cand[free_rows[greedy]] = True
        left, _ = graph._attractor(m, settled, cand)
        if not left[seg_states].all():
            cand[free_rows[opt_local]] = True
            _, attr = graph._attractor(m, left, cand)
            choice = np.where((attr >= 0) & free & ~left, attr, choice)
    return choice
