"""Strategy evaluation by sparse solves: refinement and elementwise rounding bounds."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from planner.imdp.evaluate import ChainOrderings, chain_lu, chain_reach
from planner.imdp.kernels import chain_residual


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
    r = chain_residual(indptr, indices, data, y, np.array([0]))
    assert r[0] == pytest.approx(5e-17, rel=1e-12)
    assert 0.5 * 1.0 + 0.5 * 1e-16 - y[0] == 0.0  # what double precision gives


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


def test_stay_allowance_without_a_factorisation_bounds_the_direct_one():
    # a corridor 0..19: up with 0.5 (19 -> the goal 20), down with 0.4 (0 stays), a sink
    # 21 with 0.1; one action per state, point intervals
    from planner.imdp import IMDP
    from planner.imdp.evaluate import chain_stay_allowance
    from planner.imdp.ordering import OrderingAdversary

    n = 22
    s, a, t, p = [20, 21], [0, 0], [20, 21], [1.0, 1.0]
    for i in range(20):
        s += [i] * 3
        a += [0] * 3
        t += [i + 1, max(i - 1, 0) if i > 0 else 0, 21]
        p += [0.5, 0.4, 0.1]
    m = IMDP(n, s, a, t, p, p, labels=[()] * 20 + [("g",), ()])
    rows = np.flatnonzero(m.row_state < 20)
    upper = np.concatenate((np.linspace(0.1, 0.9, 20), [1.0, 0.0]))
    chain = OrderingAdversary(m, True, rows=rows).matrix(upper)
    direct = chain_stay_allowance(chain, m.row_state[rows], upper, 1e-15)
    jacobi = chain_stay_allowance(chain, m.row_state[rows], upper, 1e-15, direct_limit=0)
    free = np.arange(20)
    assert np.all(direct[free] > 0) and np.all(np.isfinite(jacobi[free]))
    assert np.all(jacobi[free] >= direct[free]) and np.all(jacobi[free] <= 1.06 * direct[free])
    assert direct[20] == direct[21] == 0.0


def _candidates(rng: np.random.Generator, n: int, closed: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """Two or three random candidate rows per state over ``n`` states plus an exit column
    ``n``; the last ``closed`` states only ever move among themselves; the first row of
    every fifth other state leaves with 0.3."""
    rows, cols, vals, row_states = [], [], [], []
    r = 0
    for s in range(n):
        for j in range(rng.integers(2, 4)):
            pool = np.arange(n - closed, n) if s >= n - closed else np.arange(n + 1)
            k = min(rng.integers(1, 4), pool.size)
            succ = rng.choice(pool, size=k, replace=False)
            p = rng.dirichlet(np.ones(k))
            if s < n - closed and j == 0 and s % 5 == 0:
                succ, p = np.append(succ[succ != n], n), np.append(0.7 * p[succ != n], 0.3)
                p /= p.sum()
            elif s < n - closed and rng.random() < 0.6:
                p[succ == n] = 0.0  # most rows of open states do not leave directly
                if p.sum() == 0.0:
                    p[0], succ[0] = 1.0, (s + 1) % (n - closed)
                p /= p.sum()
            rows += [r] * len(succ)
            cols += list(succ)
            vals += list(p)
            row_states.append(s)
            r += 1
    return sp.csr_matrix((vals, (rows, cols)), shape=(r, n + 1)), np.array(row_states)


def _stays(matrix: sp.csr_matrix, row_states: np.ndarray, choice: np.ndarray) -> np.ndarray:
    """Expected steps among the states before leaving (inf where the chain may stay for
    ever: it can reach states without a path out)."""
    from planner.imdp.evaluate import reaching

    n = matrix.shape[1] - 1
    states = np.unique(row_states)
    sub = matrix[choice][:, states].toarray()
    live = reaching(sp.csr_matrix(sub), 1.0 - sub.sum(axis=1) > 1e-12)
    stuck = reaching(sp.csr_matrix(sub), ~live)
    out = np.full(states.size, np.inf)
    idx = np.flatnonzero(~stuck)
    out[idx] = np.linalg.solve(np.eye(idx.size) - sub[np.ix_(idx, idx)], np.ones(idx.size))
    assert n == states.size
    return out


@pytest.mark.parametrize("seed", range(6))
def test_surest_exit_start_leaves_from_every_state_that_can_leave(seed):
    from planner.imdp.evaluate import reaching, surest_exit_start

    rng = np.random.default_rng(seed)
    n, closed = 30, 4
    matrix, rs = _candidates(rng, n, closed)
    choice = surest_exit_start(matrix, rs)
    edges = sp.csr_matrix(((matrix.data > 0).astype(float), matrix.indices, matrix.indptr))
    union = sp.csr_matrix((np.ones(rs.size), (rs, np.arange(rs.size))), (n, rs.size)) @ edges
    can_leave = reaching(union[:, :n], np.asarray(union[:, n].todense()).ravel() > 0)
    assert can_leave.sum() > n // 2
    assert np.array_equal(choice >= 0, can_leave)
    placed = np.flatnonzero(choice >= 0)
    assert np.all(rs[choice[placed]] == placed)
    # the chosen rows alone keep a path out from every placed state
    chosen = edges[np.where(choice >= 0, choice, np.searchsorted(rs, np.arange(n)))]
    leaves = reaching(chosen[:, :n], np.asarray(chosen[:, n].todense()).ravel() > 0)
    assert np.array_equal(leaves, can_leave)


def test_surest_exit_start_prefers_the_sure_step_to_a_creeping_one():
    # a corridor 0..9: per state a row that creeps (1e-9 on, the rest stays) and one that
    # jumps (0.5 on, 0.5 back); the last state's rows leave
    from planner.imdp.evaluate import shortest_stay_choice, surest_exit_start

    n = 10
    rows, cols, vals = [], [], []
    for s in range(n):
        on = s + 1
        rows += [2 * s, 2 * s, 2 * s + 1, 2 * s + 1]
        cols += [on, s, on, max(s - 1, 0)]
        vals += [1e-9, 1 - 1e-9, 0.5, 0.5]
    matrix = sp.csr_matrix((vals, (rows, cols)), shape=(2 * n, n + 1))
    rs = np.repeat(np.arange(n), 2)
    choice = surest_exit_start(matrix, rs)
    assert np.array_equal(choice, 2 * np.arange(n) + 1)
    creeping = 2 * np.arange(n)
    assert _stays(matrix, rs, creeping).max() > 1e9
    assert _stays(matrix, rs, choice).max() < 200
    # policy iteration from the creeping rows finds the jumping ones as well
    assert np.array_equal(shortest_stay_choice(matrix, rs, creeping), choice)


@pytest.mark.parametrize("seed", range(8))
def test_shortest_stay_choice_reaches_the_enumerated_minimum(seed):
    import itertools

    from planner.imdp.evaluate import shortest_stay_choice, surest_exit_start

    rng = np.random.default_rng(100 + seed)
    n = 6
    matrix, rs = _candidates(rng, n, 0)
    start = surest_exit_start(matrix, rs)
    assert np.all(start >= 0)
    per_state = [np.flatnonzero(rs == s) for s in range(n)]
    best = np.full(n, np.inf)
    for combo in itertools.product(*per_state):
        best = np.minimum(best, _stays(matrix, rs, np.array(combo)))
    choice = shortest_stay_choice(matrix, rs, start)
    got = _stays(matrix, rs, choice)
    assert np.all(got <= _stays(matrix, rs, start) * (1 + 1e-12))
    assert np.allclose(got, best, rtol=1e-8)
    # a limit the start already meets keeps the start
    assert np.array_equal(
        shortest_stay_choice(matrix, rs, start, limit=1.001 * _stays(matrix, rs, start).max()),
        start,
    )


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
