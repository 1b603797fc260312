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
    # optimal rows by the attractor from the settled states, as computed in full, against
    # strategy_rows, which skips the attractor where no state has two optimal rows; for
    # some seeds the values are 0 or 1/2 so that rows tie
    from planner.imdp import graph
    from planner.imdp.model import first_of_runs
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
    # the reference: always the attractor
    opt = optimal_rows(q, seg, rs, True, 1e-8)
    first = opt[first_of_runs(rs[opt])]
    want = np.full(m.n_states, -1, dtype=np.int64)
    want[rs[first]] = rows[first]
    in_free = np.zeros(m.n_states, dtype=bool)
    in_free[rs[seg]] = True
    cand = np.zeros(m.n_rows, dtype=bool)
    cand[rows[opt]] = True
    _, attr = graph._attractor(m, ~in_free | (v <= 0), cand)
    want = np.where((attr >= 0) & in_free, attr, want)
    np.testing.assert_array_equal(got, want)
    if seed % 4 >= 2:
        assert first.size == opt.size  # no ties: the skipped case
    else:
        assert first.size < opt.size  # ties: the attractor picks
