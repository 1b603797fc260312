"""Expected stays of chains (planner.imdp.stay): the rounding allowance and the
short-stay strategies."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from planner.imdp.evaluate import reaching


def test_stay_allowance_without_a_factorisation_bounds_the_direct_one():
    # a corridor 0..19: up with 0.5 (19 -> the goal 20), down with 0.4 (0 stays), a sink
    # 21 with 0.1; one action per state, point intervals
    from planner.imdp import IMDP
    from planner.imdp.ordering import OrderingAdversary
    from planner.imdp.stay import chain_stay_allowance

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
    # the chain's expected stay instead of a factorisation: a bound, of the same size
    stay = np.zeros(n)
    step = np.arange(20)
    sub = chain[:, :20].toarray()
    stay[step] = np.linalg.solve(np.eye(20) - sub, np.ones(20))
    bounded = chain_stay_allowance(chain, m.row_state[rows], upper, 1e-15, stay=stay)
    assert np.all(bounded[free] >= direct[free]) and np.all(bounded[free] <= 3 * direct[free])
    assert bounded[20] == bounded[21] == 0.0
    never = stay.copy()
    never[3] = 1e300  # a stay that never ends: the factorisation again
    np.testing.assert_array_equal(
        chain_stay_allowance(chain, m.row_state[rows], upper, 1e-15, stay=never), direct
    )


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
    from planner.imdp.stay import surest_exit_start

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


def _greedy_exits(matrix: sp.csr_matrix, rs: np.ndarray) -> np.ndarray:
    """The greedy of ``surest_exit_choice`` by its definition, with no heap: each step
    places the unplaced state whose best row has the most mass out or into the placed
    states (-1 for the states never placed)."""
    n = matrix.shape[1] - 1
    dense = matrix.toarray()
    placed = np.zeros(n + 1, dtype=bool)
    placed[n] = True  # the exit
    choice = np.full(n, -1)
    while True:
        mass = dense[:, placed].sum(axis=1)
        mass[placed[rs]] = 0.0
        if mass.max() <= 0.0:
            return choice
        r = int(np.argmax(mass))
        choice[rs[r]] = r
        placed[rs[r]] = True


@pytest.mark.parametrize("seed", range(6))
def test_surest_exit_start_is_the_greedy_of_most_mass_towards_the_exit(seed):
    # rows scaled by continuous factors (the rest of their mass goes nowhere): no two rows
    # tie, not even once all their successors are placed, so the greedy's order is unique
    from planner.imdp.stay import surest_exit_start

    rng = np.random.default_rng(100 + seed)
    matrix, rs = _candidates(rng, 40, 5)
    matrix = (sp.diags(rng.uniform(0.5, 1.0, rs.size)) @ matrix).tocsr()
    choice = surest_exit_start(matrix, rs)
    expected = _greedy_exits(matrix, rs)
    assert (expected >= 0).sum() > 20
    assert np.array_equal(choice, expected)


def test_surest_exit_start_prefers_the_sure_step_to_a_creeping_one():
    # a corridor 0..9: per state a row that creeps (1e-9 on, the rest stays) and one that
    # jumps (0.5 on, 0.5 back); the last state's rows leave
    from planner.imdp.stay import shortest_stay, surest_exit_start

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
    assert np.array_equal(shortest_stay(matrix, rs, creeping)[0], choice)


@pytest.mark.parametrize("seed", range(8))
def test_shortest_stay_reaches_the_enumerated_minimum(seed):
    import itertools

    from planner.imdp.stay import shortest_stay, surest_exit_start

    rng = np.random.default_rng(100 + seed)
    n = 6
    matrix, rs = _candidates(rng, n, 0)
    start = surest_exit_start(matrix, rs)
    assert np.all(start >= 0)
    per_state = [np.flatnonzero(rs == s) for s in range(n)]
    best = np.full(n, np.inf)
    for combo in itertools.product(*per_state):
        best = np.minimum(best, _stays(matrix, rs, np.array(combo)))
    choice, stay = shortest_stay(matrix, rs, start)
    got = _stays(matrix, rs, choice)
    # the stay returned is the choice's
    np.testing.assert_allclose(stay[:n], got, rtol=1e-10)
    assert stay[n] == 0.0
    assert np.all(got <= _stays(matrix, rs, start) * (1 + 1e-12))
    assert np.allclose(got, best, rtol=1e-8)
    # a limit the start already meets keeps the start
    assert np.array_equal(
        shortest_stay(matrix, rs, start, limit=1.001 * _stays(matrix, rs, start).max())[0],
        start,
    )


def test_a_stopped_stay_search_ends_at_once():
    from planner.imdp.stay import block_stay_bound, shortest_stay

    sub = sp.csr_matrix([[1.0 - 1e-3]])
    assert block_stay_bound(sub, limit=1e6) < np.inf
    assert block_stay_bound(sub, limit=1e6, stop=lambda: True) == np.inf
    matrix = sp.csr_matrix(np.array([[0.5, 0.0], [0.9, 0.0]]))
    rs = np.array([0, 0])
    start = np.array([1])
    choice, stay = shortest_stay(matrix, rs, start, limit=1.0, stop=lambda: True)
    assert np.array_equal(choice, start) and stay is None
    # not stopped, the search takes the row that leaves sooner
    assert shortest_stay(matrix, rs, start)[0][0] == 0


def test_the_block_bound_asks_its_stop_between_its_checks():
    # a stop that comes before the first check (32 steps) ends the products within
    # ``_STOP_EVERY`` of them, not at the next check (where 256 products may lie between)
    from planner.imdp import stay

    products: list[int] = []

    class Counted(sp.csr_matrix):
        def __matmul__(self, other):
            products.append(1)
            return super().__matmul__(other)

    sub = Counted(sp.csr_matrix([[1.0 - 1e-3]]))
    assert stay.block_stay_bound(sub, limit=1e6, stop=lambda: True) == np.inf
    assert len(products) == stay._STOP_EVERY < stay._BLOCK_FIRST
    products.clear()
    assert stay.block_stay_bound(sub, limit=1e6, stop=lambda: False) < np.inf
    assert len(products) >= stay._BLOCK_FIRST


def test_block_stay_bound_of_a_self_loop_is_tight_and_sound():
    from planner.imdp.stay import block_stay_bound

    p = 1.0 - 1e-3  # expected stay 1 / (1 - p) = 1000
    sub = sp.csr_matrix([[p]])
    bound = block_stay_bound(sub, limit=1e6)
    # one state: the summed masses of the first block over what leaves in it are exact
    assert 1000.0 <= bound <= 1000.0 * (1.0 + 1e-9)
    # a limit below any block's bound, or below the first block: no bound
    assert block_stay_bound(sub, limit=999.0) == np.inf
    assert block_stay_bound(sub, limit=10.0) == np.inf
    # a closed class never leaves
    assert block_stay_bound(sp.csr_matrix([[0.5, 0.5], [0.0, 1.0]]), limit=1e12) == np.inf
    assert block_stay_bound(sp.csr_matrix((0, 0)), limit=1.0) == 0.0


@pytest.mark.parametrize("seed", range(6))
def test_block_stay_bound_bounds_the_exact_stays(seed):
    from planner.imdp.stay import block_stay_bound

    rng = np.random.default_rng(200 + seed)
    n = 40
    dense = rng.random((n, n)) * (rng.random((n, n)) < 0.15)
    dense /= dense.sum(axis=1, keepdims=True) + 1e-300
    leave = rng.random(n) < 0.2  # a fifth of the states leave with 1 %
    dense[leave] *= 0.99
    dense[~dense.any(axis=1), 0] = 0.99
    sub = sp.csr_matrix(dense)
    live = reaching(sub, 1.0 - dense.sum(axis=1) > 1e-12)
    assert live.all()
    exact = np.linalg.solve(np.eye(n) - dense, np.ones(n))
    bound = block_stay_bound(sub, limit=1e9, max_steps=1 << 16)
    assert exact.max() <= bound < np.inf


def test_shortest_stay_settles_on_the_block_bound_within_the_limit():
    from planner.imdp.stay import shortest_stay, surest_exit_start

    rng = np.random.default_rng(7)
    n = 6
    matrix, rs = _candidates(rng, n, 0)
    start = surest_exit_start(matrix, rs)
    exact = _stays(matrix, rs, start)
    choice, stay = shortest_stay(matrix, rs, start, limit=1e9)
    # the start already fits: kept, with a bound of its stays
    assert np.array_equal(choice, start)
    assert np.all(stay[:n] >= exact) and np.all(stay[:n] <= 1e9) and stay[n] == 0.0
    # without the block bound: the stays themselves, by LU
    choice, stay = shortest_stay(matrix, rs, start, limit=1e9, block_limit=0.0)
    assert np.array_equal(choice, start)
    np.testing.assert_allclose(stay[:n], exact, rtol=1e-10)


def _tiny_exit_chain(goal: float, bad: float):
    """One free state that keeps ``1 - goal - bad`` and leaves with ``goal`` to a target
    and ``bad`` to a trap; point intervals, exact value ``goal / (goal + bad)``."""
    from planner.imdp import IMDP

    keep = 1.0 - goal - bad
    s, t, p = [0, 0, 0, 1, 2], [0, 1, 2, 1, 2], [keep, goal, bad, 1.0, 1.0]
    labels = [(), ("goal",), ("bad",)]
    return IMDP(3, s, [0] * 5, t, p, p, labels=labels, propositions=("bad", "goal")), keep


@pytest.mark.parametrize(("goal", "bad"), [(2.0**-50, 6.87e-13), (2.0**-51, 5e-13)])
def test_exits_below_1e_12_per_step_count_as_exits(goal, bad):
    # Leaving with under 1e-12 per step is still leaving (within ~1e12 steps), and it can
    # carry the whole value: here about 1e-3, gained at under 1e-15 per step, which the
    # checks' rounding allowance hides. The widening must sum that allowance over the stay;
    # it once treated such states as never leaving (value 0, no allowance) and certified
    # [6e-14, 2.5e-9].
    from fractions import Fraction

    from planner.imdp import Problem, ReachAvoid, Specification, solve
    from planner.imdp.ordering import OrderingAdversary
    from planner.imdp.stay import chain_stay_allowance

    m, keep = _tiny_exit_chain(goal, bad)
    exact = Fraction(goal) / (1 - Fraction(keep))
    sol = solve(Problem(m, Specification(ReachAvoid("goal", "bad"))))
    assert Fraction(sol.lower[0]) <= exact <= Fraction(sol.upper[0])
    assert not sol.converged  # 1e-15 per step over ~1e12 steps: no 1e-8 bracket
    # the allowance itself: the noise summed over the expected stay
    rows = np.array([0])
    upper = np.array([1e-9, 1.0, 0.0])
    chain = OrderingAdversary(m, True, rows=rows).matrix(upper)
    allowance = chain_stay_allowance(chain, m.row_state[rows], upper, 1e-15)
    assert allowance[0] >= 1e-15 / (1.0 - keep)


def test_float_leftover_of_a_closed_class_is_not_an_exit():
    # a distribution that sums to 1 - 1e-16 in floating point leads nowhere: the class
    # it keeps is closed, its value 0, and it takes no allowance
    from planner.imdp.stay import chain_stay_allowance

    short = 0.25 - 2.0**-53  # the rows sum to 1 - 2^-53
    chain = sp.csr_matrix(np.array([[0.5, 0.25, short, 0.0]] * 3))
    assert chain[0].sum() < 1.0
    upper = np.array([0.5, 0.5, 0.5, 1.0])
    allowance = chain_stay_allowance(chain, np.array([0, 1, 2]), upper, 1e-15)
    assert np.all(allowance == 0.0)
    # one real entry of 1e-300 towards the target opens the class
    chain = sp.csr_matrix(np.array([[0.5, 0.25, short, 1e-300]] * 3))
    allowance = chain_stay_allowance(chain, np.array([0, 1, 2]), upper, 1e-15)
    assert np.all(allowance[:3] > 0.0)
