"""Robust strategy iteration (planner.imdp.strategy)."""

from __future__ import annotations

import numpy as np
import pytest

from planner.imdp import IMDP
from planner.imdp.strategy import strategy_iteration


def _creep_or_jump() -> IMDP:
    """State 0 with two rows tied at ``v = 0.5`` within the tie slack: action 0 creeps
    (stays with ``1 - 1e-9``, the rest to the target 1 and the sink 2, worth 0.499),
    action 1 jumps (target or sink with 0.5 each, worth 0.5). Point intervals."""
    s = [0, 0, 0, 0, 0, 1, 2]
    a = [0, 0, 0, 1, 1, 0, 0]
    t = [0, 1, 2, 1, 2, 1, 2]
    p = [1 - 1e-9, 0.499e-9, 0.501e-9, 0.5, 0.5, 1.0, 1.0]
    return IMDP(3, s, a, t, p, p, labels=[(), ("goal",), ()])


def test_first_strategy_takes_the_sure_exit_among_tied_rows():
    # both rows of state 0 are optimal for v within the slack and both move into settled
    # states, the creeping one only by 1e-9 a step, most of it into the sink: its value is
    # 0.499. The first evaluation is already the jump's 0.5.
    m = _creep_or_jump()
    free_rows = np.flatnonzero(m.row_state == 0)
    v = np.array([0.5, 1.0, 0.0])
    fixed = np.array([0.0, 1.0, 0.0])
    x, _, rounds = strategy_iteration(m, free_rows, v, fixed, True, 1e-8, max_rounds=1)
    assert rounds == 1
    assert x[0] == pytest.approx(0.5, abs=1e-12)


@pytest.mark.parametrize("start", [0.0, 0.499, 0.5])
def test_strategy_iteration_ends_at_the_jump(start):
    m = _creep_or_jump()
    free_rows = np.flatnonzero(m.row_state == 0)
    v = np.array([start, 1.0, 0.0])
    fixed = np.array([0.0, 1.0, 0.0])
    x, sigma, _ = strategy_iteration(m, free_rows, v, fixed, True, 1e-8)
    assert sigma is not None and m.row_action[sigma[0]] == 1
    assert x[0] == pytest.approx(0.5, abs=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_strategy_iteration_from_a_given_start(seed):
    # from any first strategy it ends at the same values; from its own result at once
    from tests.planner.imdp.reference import random_imdp

    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=30, n_actions=3, max_succ=4, zero_lower=False)
    goal = m.states_labelled("goal")
    free = ~goal
    free[0] = False  # the absorbing sink
    free_rows = np.flatnonzero(free[m.row_state])
    fixed = np.where(goal, 1.0, 0.0)
    x, sigma, _ = strategy_iteration(m, free_rows, fixed, fixed, True, 1e-10)
    assert sigma is not None
    rs = m.row_state[free_rows]
    first = free_rows[np.flatnonzero(np.r_[True, rs[1:] != rs[:-1]])]
    assert (first != sigma).any()  # a start that is not optimal
    x2, sigma2, _ = strategy_iteration(m, free_rows, fixed, fixed, True, 1e-10, start=first)
    assert sigma2 is not None
    np.testing.assert_allclose(x2, x, atol=1e-9)
    x3, _, rounds = strategy_iteration(m, free_rows, fixed, fixed, True, 1e-10, start=sigma)
    assert rounds == 1
    np.testing.assert_allclose(x3, x, atol=1e-12)
    # a start that is not one free row per free state is refused
    from planner.errors import SpecificationError

    with pytest.raises(SpecificationError, match="one of the free rows per free state"):
        strategy_iteration(m, free_rows, fixed, fixed, True, 1e-10, start=sigma[:-1])
    with pytest.raises(SpecificationError, match="one of the free rows per free state"):
        strategy_iteration(m, free_rows, fixed, fixed, True, 1e-10, start=sigma[::-1])


def test_independent_parts_keep_whole_components():
    from planner.imdp.model import row_entries
    from planner.imdp.strategy import independent_parts
    from tests.planner.imdp.reference import side_by_side, sticky_imdp

    for seed in range(4):
        rng = np.random.default_rng(seed)
        m = side_by_side(sticky_imdp(rng, 60), sticky_imdp(rng, 90))
        states = rng.random(m.n_states) < 0.7
        rows = np.flatnonzero(states[m.row_state])
        parts = independent_parts(m, rows, states)
        assert len(parts) == 2  # at least the two models' states are independent
        assert np.array_equal(np.sort(np.concatenate(parts)), rows)
        assert all(np.array_equal(p, np.sort(p)) for p in parts)
        sizes = []
        for p, q in ((0, 1), (1, 0)):
            other = np.zeros(m.n_states, dtype=bool)
            other[m.row_state[parts[q]]] = True
            ent = row_entries(m, parts[p])
            # no entry that may carry mass from one part's states to the other's
            assert not np.any(other[m.successor[ent]] & (m.upper[ent] > 0.0))
            sizes.append(parts[p].size)
        # the first part is filled to half of the rows (components in decreasing size)
        assert 2 * sizes[0] >= rows.size
    # states that reach each other through their rows stay together
    m = sticky_imdp(np.random.default_rng(9), 40)
    states = np.zeros(m.n_states, dtype=bool)
    states[[0, m.successor[m.row_ptr[0]]]] = True
    rows = np.flatnonzero(states[m.row_state])
    assert len(independent_parts(m, rows, states)) == 1


@pytest.mark.parametrize("seed", range(8))
def test_the_attractor_picks_only_among_tied_rows(seed):
    # the greedy rows (the first of each state's exact best) where their robust attractor
    # from the settled states reaches, elsewhere optimal rows by the attractor from there,
    # as computed in full, against strategy_rows, which skips the attractors where no
    # state has two optimal rows; for some seeds the values are 0 or 1/2 so that rows tie
    from planner.imdp import graph
    from planner.imdp.model import first_of_runs, run_ids
    from planner.imdp.ordering import OrderingAdversary
    from planner.imdp.strategy import optimal_rows, strategy_rows

    from .reference import random_imdp

    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=60, n_actions=4, max_succ=5, zero_lower=bool(seed % 2))
    v = rng.random(m.n_states)
    v[rng.random(m.n_states) < 0.2] = 0.0
    if seed % 4 < 2:
        v = np.where(v > 0.0, 0.5, 0.0)  # rows that avoid the zeros tie
    free = rng.random(m.n_states) < 0.7
    rows = np.flatnonzero(free[m.row_state])
    rs = m.row_state[rows]
    seg = first_of_runs(rs)
    q = OrderingAdversary(m, True, rows=rows).expectation(v)
    got = strategy_rows(m, rows, q, seg, rs[seg], v, True, True, 1e-8)
    # the reference: always both attractors
    opt = optimal_rows(q, seg, rs, True, 1e-8)
    top = np.flatnonzero(q == np.maximum.reduceat(q, seg)[run_ids(rs)])
    greedy = top[first_of_runs(rs[top])]
    want = np.full(m.n_states, -1, dtype=np.int64)
    want[rs[greedy]] = rows[greedy]
    in_free = np.zeros(m.n_states, dtype=bool)
    in_free[rs[seg]] = True
    cand = np.zeros(m.n_rows, dtype=bool)
    cand[rows[greedy]] = True
    left, _ = graph._attractor(m, ~in_free | (v <= 0), cand)
    cand[rows[opt]] = True
    _, attr = graph._attractor(m, left, cand)
    want = np.where((attr >= 0) & in_free & ~left, attr, want)
    np.testing.assert_array_equal(got, want)
    if seed % 4 >= 2:
        assert greedy.size == opt.size  # no ties: the skipped case
    else:
        assert greedy.size < opt.size  # ties: the attractors pick


def _window_grid(rng: np.random.Generator, n: int):
    """An ``n x n`` grid world (3 % hazards, the goal in the far corner) whose actions
    land in a 3x3 or 5x5 window around their target cell, ``[0.8 p, 1.2 p + 1e-3]``
    around a Gaussian ``p``; its product with ``!Haz U Goal``."""
    from planner.automaton import RabinAutomaton
    from planner.imdp.grid import GridWorld
    from planner.imdp.product import ProductIMDP

    labels = np.empty((n, n), dtype=object)
    labels[:] = [[() for _ in range(n)] for _ in range(n)]
    haz = rng.random((n, n)) < 0.03
    haz[:3, :3] = False
    for i, j in zip(*np.nonzero(haz), strict=True):
        labels[i, j] = ("Haz",)
    for i in range(n - n // 10, n):
        for j in range(n - n // 10, n):
            labels[i, j] = ("Goal",)
    grid = GridWorld(n, n, 1.0, labels)
    cells, acts = np.nonzero(grid.enabled[: grid.n_cells])
    ti, tj = grid.cell_ij(grid.target_cell[cells, acts])
    sigma = rng.uniform(0.3, 0.9, size=grid.n_cells)[cells]
    d = np.arange(-2, 3)
    w = np.exp(-0.5 * (d[None, :] / sigma[:, None]) ** 2)
    w *= np.abs(d)[None, :] <= np.where(sigma < 0.55, 1, 2)[:, None]
    w /= w.sum(axis=1, keepdims=True)
    p = (w[:, :, None] * w[:, None, :]).reshape(len(cells), 25)
    di, dj = np.meshgrid(d, d, indexing="ij")
    succ = grid.cell_index(ti[:, None] + di.ravel(), tj[:, None] + dj.ravel())
    row = np.broadcast_to(np.arange(len(cells))[:, None], p.shape)
    keep = p > 0
    key = row[keep] * grid.n_states + succ[keep]
    uniq, inv = np.unique(key, return_inverse=True)
    pm = np.bincount(inv, weights=p[keep])
    r, s = uniq // grid.n_states, uniq % grid.n_states
    model = grid.imdp_from_intervals(
        cells[r], acts[r], s, 0.8 * pm, np.minimum(1.0, 1.2 * pm + 1e-3)
    )
    table = np.array([[0, 1, 2, 1], [1, 1, 1, 1], [2, 2, 2, 2]])
    return ProductIMDP(model, RabinAutomaton(("Goal", "Haz"), table, 0, [({1}, set())]))


@pytest.mark.parametrize("certified", [False, True])
def test_the_strategy_of_a_grid_solve_is_worth_its_values(certified):
    """Played alone (every free state held to its action), the strategy of a worst-case
    reachability solve on a grid product is worth the solve's values (from below). Many rows there
    count as optimal (within the slack of the best); picking among them by the attractor
    alone, rows short of the best at every step with a forced way on of tiny probability,
    left such strategies worth about 0 at most states."""
    from planner.imdp import Problem, ReachAvoid, Specification, ValueIteration, solve
    from planner.imdp.analysis import winning_states

    prod = _window_grid(np.random.default_rng(4), 40)
    m = prod.model
    spec = Specification(ReachAvoid(winning_states(prod)))
    sol = solve(Problem(m, spec), ValueIteration(1e-8, certified=certified))
    acting = sol.strategy >= 0
    allowed = m.enabled.copy()
    allowed[acting] = False
    allowed[np.flatnonzero(acting), sol.strategy[acting]] = True
    played = solve(Problem(m, spec, allowed=allowed), ValueIteration(1e-10))
    assert (~sol.fixed).sum() > 500 and sol.values[prod.initial] > 0.5
    # worth at least the values found from below (the bound from above of the played
    # strategy is its exact value within 1e-10)
    assert (played.upper >= sol.values - 1e-6).all()
