"""Strategy evaluation by sparse solves: refinement and elementwise rounding bounds."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from planner.imdp.evaluate import ChainOrderings, chain_lu, chain_reach
from planner.imdp.kernels import chain_exit_residual


def _cycle(rng: np.random.Generator, n: int, leak: float) -> sp.csr_matrix:
    """``n`` states circulating in a random cycle (each also jumping 7 ahead), every one
    leaking ``leak`` to the goal (column ``n``) and ``2 leak`` to a sink (``n + 1``):
    every value is exactly 1/3 and the expected stay is about ``1 / (3 leak)`` steps."""
    perm = rng.permutation(n)
    rows, cols, vals = [], [], []
    for k in range(n):
        w = rng.uniform(0.2, 0.8)
        i = perm[k]
        rows += [i] * 4
        cols += [perm[(k + 1) % n], perm[(k + 7) % n], n, n + 1]
        vals += [(1 - 3 * leak) * w, (1 - 3 * leak) * (1 - w), leak, 2 * leak]
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n + 2))


@pytest.mark.parametrize("leak", [1e-6, 1e-8, 1e-10])
def test_bound_covers_the_error_of_an_ill_conditioned_chain(leak):
    n = 200
    p = _cycle(np.random.default_rng(3), n, leak)
    fixed = np.zeros(n + 2)
    fixed[n] = 1.0
    x, err = chain_reach(p, np.arange(n), fixed, error=True)
    bound = err.bound()
    off = np.abs(x[:n] - 1 / 3)
    assert np.all(off <= bound[:n])
    # the bound is a few times the rounding of the chain's own rows ((k + 4) eps per step), not
    # a blanket: 1e-10 leaks give ~3e9 steps
    assert bound[:n].max() < 40 * np.finfo(float).eps / (3 * leak)
    assert x[n:].tolist() == [1.0, 0.0]  # the fixed values are kept


def test_bound_is_small_where_the_slow_part_has_small_values():
    # H (0): half to the goal, half into a trap cycle T (2..11) that circulates for ~5e8
    # steps and leaks 1e-9 to a low state W (1) and 1e-9 to the sink; W reaches the goal
    # with 1e-6. Values: W = 1e-6, T = W / 2, H = 1/2 + T / 2.
    n_t = 10
    n = 2 + n_t
    goal, sink = n, n + 1
    dense = np.zeros((n, n + 2))
    dense[0, goal] = dense[0, 2] = 0.5
    dense[1, goal], dense[1, sink] = 1e-6, 1 - 1e-6
    for k in range(n_t):
        s = 2 + k
        dense[s, 2 + (k + 1) % n_t] = 1 - 2e-9
        dense[s, 1] = dense[s, sink] = 1e-9
    fixed = np.zeros(n + 2)
    fixed[goal] = 1.0
    x, err = chain_reach(sp.csr_matrix(dense), np.arange(n), fixed, error=True)
    exact = np.concatenate(([0.5 + 0.25e-6, 1e-6], np.full(n_t, 0.5e-6)))
    bound = err.bound()[:n]
    assert np.all(np.abs(x[:n] - exact) <= bound)
    steps = np.linalg.solve(np.eye(n) - dense[:, :n], np.ones(n))
    assert steps.max() > 1e8  # a norm bound (steps x 4 eps) would be ~2e-7 everywhere
    assert bound.max() < 1e-11


def test_residual_is_exact_where_double_precision_cancels():
    # 1 - (1 - 1e-17) - 1e-17 ... in double the first sum already rounds away the 1e-17
    indptr = np.array([0, 2])
    indices = np.array([1, 2])
    data = np.array([0.5, 0.5])
    y = np.array([0.5 + 1e-17, 1.0, 1e-16])
    # exact: 0.5 * 1 + 0.5 * 1e-16 - y[0] = 5e-17 - 1e-17 (y[0] rounds to 0.5) = 5e-17
    r = chain_exit_residual(indptr, indices, data, y, np.array([0]), np.zeros(1))
    assert r[0] == pytest.approx(5e-17, rel=1e-12)
    assert 0.5 * 1.0 + 0.5 * 1e-16 - y[0] == 0.0  # what double precision gives


def test_the_residual_implies_the_stay_from_what_leaves():
    # a state keeps 1 - 2**-60 on itself (not representable next to 1: it reads as 1) and
    # leaves with 2**-61 to a state of value 1 and 2**-61 lost (value 0): its value is 1/2,
    # where the residual is exactly 0, and at 1/4 it is 2**-61 (3/4) - 2**-61 (1/4) =
    # 2**-62 (a residual that read the stored stay of 1 would see 2**-61 (1 - y) only)
    indptr = np.array([0, 2])
    indices = np.array([0, 1])
    data = np.array([1.0, 2.0**-61])
    own, lost = np.zeros(1, np.int64), np.array([2.0**-61])
    assert chain_exit_residual(indptr, indices, data, np.array([0.5, 1.0]), own, lost)[0] == 0.0
    quarter = chain_exit_residual(indptr, indices, data, np.array([0.25, 1.0]), own, lost)
    assert quarter[0] == 2.0**-62


def test_certified_bracket_contains_the_exact_value_of_slow_leaks():
    # leaks down to 1e-8 (chains of 1e8 expected steps): the bracket must contain the value
    # computed in exact rational arithmetic (an LP solver's tolerances are too coarse here)
    from planner.imdp import Problem, ReachAvoid, Specification, solve

    from .reference import exact_reach_by_strategies, slow_leak_imdp

    # (a check that tolerated 1e-15 per state without accounting for it was off by up to
    # 8e-9 on 14 of 300 such models, leaks about 3e-7)
    rng = np.random.default_rng(21)
    for _ in range(60):
        n, leak = int(rng.integers(5, 8)), 10 ** rng.uniform(-8, -4)
        # bound tolerance 0: forced masses of 1e-10 (1 - sum of the other upper bounds)
        # count, as in the exact reference
        m = slow_leak_imdp(rng, n_states=n, leak=leak, tolerance=0.0)
        exact = exact_reach_by_strategies(m, m.states_labelled("goal"))
        sol = solve(Problem(m, Specification(ReachAvoid("goal"))))
        assert np.all(sol.lower <= exact + 1e-15) and np.all(exact <= sol.upper + 1e-15)
        if sol.converged:
            assert sol.error < 1e-8


def test_chain_orderings_reuse_the_ordering_of_a_chain_with_the_same_pattern():
    rng = np.random.default_rng(11)
    n = 300
    first = _cycle(rng, n, 1e-3)[:, :n]
    # the same pattern with other probabilities (an adversary's other distribution)
    second = first.copy()
    second.data *= rng.uniform(0.5, 1.0, size=second.data.size)
    # another pattern: one more edge per row
    extra = sp.csr_matrix((np.full(n, 1e-4), (np.arange(n), (np.arange(n) + 3) % n)), shape=(n, n))
    third = (first * 0.9 + extra).tocsr()
    orderings = ChainOrderings()
    b = rng.uniform(0.0, 1.0, size=n)
    for k, sub in enumerate((first, second, second, third)):
        a = (sp.identity(n, format="csc") - sub).tocsc()
        lu = chain_lu(sub, orderings)
        fresh = chain_lu(sub)
        x = lu.solve(b)
        assert np.max(np.abs(a @ x - b)) < 1e-10
        np.testing.assert_allclose(x, fresh.solve(b), rtol=1e-10, atol=1e-12)
        assert orderings.reused == [0, 1, 2, 2][k]


def test_chain_orderings_keep_the_fill_of_a_fresh_ordering():
    rng = np.random.default_rng(5)
    n = 400
    sub = _cycle(rng, n, 1e-2)[:, :n]
    orderings = ChainOrderings()
    chain_lu(sub, orderings)
    reused = chain_lu(sub, orderings)
    fresh = chain_lu(sub)
    assert orderings.reused == 1
    assert reused.fill == fresh.L.nnz + fresh.U.nnz


@pytest.mark.parametrize("seed", range(4))
def test_the_chain_assembly_kernels_equal_their_array_definitions(seed):
    from planner.imdp.kernels.chains import exit_matrix, split_chain

    rng = np.random.default_rng(seed)
    n_all, n = 40, 25
    states = np.sort(rng.choice(n_all, size=n, replace=False))
    pos = np.full(n_all, -1)
    pos[states] = np.arange(n)
    base = np.where(np.isin(np.arange(n_all), states), 0.0, rng.uniform(0, 1, n_all))
    # rows in the adversary's order (unsorted columns), self-loops, dust and exact zeros
    ptr, idx, val = [0], [], []
    for i in range(n):
        cols = rng.choice(n_all, size=int(rng.integers(1, 8)), replace=False)
        if rng.random() < 0.5:
            cols = np.append(cols[cols != states[i]], states[i])
        p = rng.dirichlet(np.ones(cols.size))
        p[rng.random(cols.size) < 0.2] = rng.choice([0.0, 1e-14, 3e-13])
        idx += list(cols)
        val += list(p)
        ptr.append(len(idx))
    ptr, idx, val = np.array(ptr), np.array(idx), np.array(val)
    k_ptr, k_idx, k_val, i_ptr, i_idx, i_val, lost, kept, b = split_chain(
        ptr, idx, val, states, pos, base, 1e-12
    )
    dense = sp.csr_matrix((val, idx, ptr), shape=(n, n_all)).toarray()
    own = np.zeros_like(dense, dtype=bool)
    own[np.arange(n), states] = True
    dust = dense < 1e-12
    clean = np.where(dust, 0.0, dense)
    kept_m = sp.csr_matrix((k_val, k_idx, k_ptr), shape=(n, n_all))
    assert np.array_equal(kept_m.toarray(), clean) and np.all(k_val >= 1e-12)
    inner = sp.csr_matrix((i_val, i_idx, i_ptr), shape=(n, n))
    assert np.array_equal(inner.toarray(), clean[:, states])
    np.testing.assert_allclose(lost, np.where(dust & ~own, dense, 0.0).sum(axis=1), atol=1e-18)
    np.testing.assert_allclose(kept, np.where(~dust & ~own, dense, 0.0).sum(axis=1), rtol=1e-14)
    np.testing.assert_allclose(b, clean @ base, rtol=1e-14)
    # A = diag(kept) - the inner rows off their diagonal, symmetrically permuted
    perm = rng.permutation(n)
    a_ptr, a_idx, a_val = exit_matrix(i_ptr, i_idx, i_val, kept, perm)
    a = sp.csc_matrix((a_val, a_idx, a_ptr), shape=(n, n))
    off = inner.toarray()
    np.fill_diagonal(off, 0.0)
    expected = (np.diag(kept) - off)[np.ix_(perm, perm)]
    assert np.array_equal(a.toarray(), expected)
    # the diagonal is stored even where nothing leaves its state
    assert a.has_sorted_indices and a.nnz == np.count_nonzero(expected + np.eye(n))


def test_strategy_values_are_the_lowered_bound_and_the_computed_values_it_lowers():
    # one row per state, every lower bound positive: mass circulates long, the bounds of
    # the computed values are positive
    from planner.imdp.evaluate import strategy_reach_value

    from .reference import exact_reach_by_strategies, sticky_imdp

    rng = np.random.default_rng(4)
    for _ in range(10):
        m = sticky_imdp(rng, 40)
        goal = m.states_labelled("goal")
        fixed = goal.astype(float)
        rows = np.flatnonzero(~goal[m.row_state])
        start = np.zeros(m.n_states)
        low, computed = strategy_reach_value(m, rows, fixed, True, start)
        raw, same = strategy_reach_value(m, rows, fixed, True, start, sound=False)
        assert np.array_equal(computed, raw) and np.array_equal(raw, same)
        assert np.all(low <= computed) and np.any(low < computed)
        # one row per state: the strategy's value is the value, which the bound is below
        exact = exact_reach_by_strategies(m, goal)
        assert np.all(low <= exact + 1e-15)
