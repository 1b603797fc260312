"""The compiled kernels against plain-Python references."""

import numpy as np
import pytest

from planner.imdp import IMDP
from planner.imdp.graph import _attractor, forced_into
from planner.imdp.kernels import ReachSweeper, search, sweeps
from tests.planner.imdp.reference import random_imdp, ref_expectation, rows_of


def _sweeper(m: IMDP, adversary_minimizes: bool) -> ReachSweeper:
    rows = np.arange(m.n_rows)
    key = np.random.default_rng(0).random(m.n_states)  # any sweep order
    return ReachSweeper(m, rows, key, True, adversary_minimizes)


def _moving_values(rng: np.random.Generator, n: int, steps: int, drift: float):
    """Value vectors that alternately jump (most stored thresholds break) and drift by
    ``drift`` (most stand), 30 % of them tied at 0.5 each time."""
    v = rng.random(n)
    for step in range(steps):
        v = v + rng.normal(0.0, drift, n) if step % 2 else rng.random(n)
        v[rng.random(n) < 0.3] = 0.5
        yield v


@pytest.mark.parametrize("minimize", [True, False])
@pytest.mark.parametrize("zero_lower", [True, False])
def test_row_values_match_reference_while_values_change(minimize, zero_lower):
    rng = np.random.default_rng(11)
    m = random_imdp(rng, n_states=40, max_succ=7, zero_lower=zero_lower)
    rows = rows_of(m)
    sw = _sweeper(m, minimize)
    for v in _moving_values(rng, m.n_states, 8, 0.02):
        got = sw.row_values(v)
        for r in range(m.n_rows):
            row = rows[(int(m.row_state[r]), int(m.row_action[r]))]
            assert got[r] == pytest.approx(ref_expectation(row, v, minimize), abs=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_lazy_upper_pass_equals_the_full_pass_while_values_decrease(seed):
    # the same passes, from the same decreasing vectors, with and without the row cache
    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=60, n_actions=5, max_succ=6)
    eager, lazy = _sweeper(m, True), _sweeper(m, True)
    cache = lazy.upper_cache()
    u = np.ones(m.n_states)
    evaluated = []
    for _ in range(12):
        a, b = u.copy(), u.copy()
        before = cache.copy()
        dec_a, bad_a = eager.upper_pass(a)
        dec_b, bad_b = lazy.upper_pass(b, cache=cache)
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-15)
        assert bad_a == bad_b and dec_b == pytest.approx(dec_a, abs=1e-15)
        evaluated.append(int((cache != before).sum()))
        # any decrease, not only the pass's own: values must merely never rise
        u = np.minimum(a, a * rng.uniform(0.7, 1.0, m.n_states))
    assert evaluated[0] == m.n_rows  # the first pass evaluates every row
    assert min(evaluated[1:]) < m.n_rows  # later passes skip rows


@pytest.mark.parametrize("minimize", [True, False])
@pytest.mark.parametrize("seed", range(3))
def test_top_row_passes_give_the_lazy_passes_values_bit_for_bit(seed, minimize, monkeypatch):
    # the same lazy passes with and without the top rows' copy; the copy made after every
    # pass, and again once a tenth of it is stale, so that both of its paths run
    monkeypatch.setattr(sweeps, "TOP_ROWS_EVALUATIONS", 1e9)
    monkeypatch.setattr(sweeps, "TOP_ROWS_STALE", 0.1)
    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=80, n_actions=5, max_succ=6)
    plain, top = _sweeper(m, minimize), _sweeper(m, minimize)
    cache_a, cache_b = plain.upper_cache(), top.upper_cache()
    u = np.ones(m.n_states)
    used = stale = 0
    for step in range(16):
        a, b = u.copy(), u.copy()
        copy = top._top
        dec_a, bad_a = plain.upper_pass(a, cache=cache_a)
        dec_b, bad_b = top.upper_pass(b, cache=cache_b)
        np.testing.assert_array_equal(b, a)
        np.testing.assert_array_equal(cache_b, cache_a)
        assert (dec_a, bad_a) == (dec_b, bad_b)
        if copy is not None:
            used += 1
            stale += int(copy[3].sum())
        # small falls keep the top rows; a fall that keeps the order of the values (the
        # adversary's critical entries stand) changes which row is highest at some states,
        # a fall at half of the states moves the critical entries too
        if step % 3 == 1:
            u = a**2
        elif step % 3 == 2:
            u = a * np.where(rng.random(m.n_states) < 0.5, 0.3, 1.0)
        else:
            u = a * 0.999
    assert used >= 14 and 0 < stale


def test_a_top_row_that_falls_below_another_row_gives_way(monkeypatch):
    # state 0 chooses between state 1 (row A) and state 2 (row B), each absorbing; the
    # copy made with A on top, then state 1 falls below state 2: the maximum is B's
    monkeypatch.setattr(sweeps, "TOP_ROWS_EVALUATIONS", 1e9)
    # (intervals [0.5, 1] on the one successor: a point interval is never read from the
    # stored critical entry, and the copy would not be used)
    m = IMDP(3, [0, 0, 1, 2], [0, 1, 0, 0], [1, 2, 1, 2], [0.5] * 4, [1.0] * 4, n_actions=2)
    sw = _sweeper(m, True)
    cache = sw.upper_cache()
    u = np.array([1.0, 0.9, 0.5])
    sw.upper_pass(u, cache=cache)
    assert u[0] == 0.9 and sw._top is not None
    u[1] = 0.2
    sw.upper_pass(u, cache=cache)
    assert u[0] == 0.5


def test_top_rows_are_copied_only_after_passes_of_about_one_row_per_state():
    rng = np.random.default_rng(4)
    m = random_imdp(rng, n_states=80, n_actions=5, max_succ=6)
    sw = _sweeper(m, True)
    cache = sw.upper_cache()
    u = np.ones(m.n_states)
    sw.upper_pass(u, cache=cache)  # every row evaluated
    assert sw._top is None
    for _ in range(30):
        sw.upper_pass(u, cache=cache)  # values settle: one row a state
    assert sw._top is not None and sw._top[0] is cache
    other = sw.upper_cache()
    before, flags = sw._top, sw._top[3].copy()
    sw.upper_pass(u.copy(), cache=other)  # another cache: the copy is not used
    assert sw._top is before
    np.testing.assert_array_equal(before[3], flags)


@pytest.mark.parametrize("minimize", [True, False])
@pytest.mark.parametrize("zero_lower", [True, False])
def test_adversary_matrix_is_an_optimal_distribution_of_every_row(minimize, zero_lower):
    # from the layout's thresholds, rows in the constructor's order, ties at the threshold
    # included: within the bounds, summing to 1, attaining the adversary's optimum
    rng = np.random.default_rng(5)
    m = random_imdp(rng, n_states=40, max_succ=7, zero_lower=zero_lower)
    rows = rows_of(m)
    free = np.flatnonzero(m.row_state > 0)
    key = np.random.default_rng(1).random(m.n_states)
    sw = ReachSweeper(m, free, key, True, minimize)
    for v in _moving_values(rng, m.n_states, 6, 0.05):
        sw.sweep(v.copy())  # moves the layout's thresholds, as a solve does
        mat = sw.adversary_matrix(v)
        assert mat.shape == (free.size, m.n_states)
        for i, r in enumerate(free):
            row = rows[(int(m.row_state[r]), int(m.row_action[r]))]
            p = mat.getrow(i).toarray().ravel()
            lo = np.zeros(m.n_states)
            up = np.zeros(m.n_states)
            for t, lo_t, up_t in row:
                lo[t], up[t] = lo_t, up_t
            assert np.all(p >= lo - 1e-15) and np.all(p <= up + 1e-15)
            assert p.sum() == pytest.approx(1.0, abs=1e-12)
            assert p @ v == pytest.approx(ref_expectation(row, v, minimize), abs=1e-12)


def _edge_rows() -> IMDP:
    """Row 0: lower bounds summing to 1 (nothing left to hand out); row 1: a point
    interval; row 2: upper bounds summing to exactly 1 (all successors at their upper
    bound)."""
    return IMDP(
        3,
        [0, 0, 1, 1, 2, 2],
        [0, 0, 0, 0, 0, 0],
        [1, 2, 1, 2, 0, 1],
        [0.25, 0.75, 0.4, 0.6, 0.2, 0.1],
        [1.0, 1.0, 0.4, 0.6, 0.5, 0.5],
    )


def test_adversary_matrix_of_edge_rows():
    m = _edge_rows()
    v = np.array([0.3, 0.2, 0.9])
    for minimize in (True, False):
        mat = _sweeper(m, minimize).adversary_matrix(v).toarray()
        assert mat[0] == pytest.approx([0.0, 0.25, 0.75])
        assert mat[1] == pytest.approx([0.0, 0.4, 0.6])
        assert mat[2] == pytest.approx([0.5, 0.5, 0.0])


def test_row_value_edge_rows():
    m = _edge_rows()
    v = np.array([0.3, 0.2, 0.9])
    rows = rows_of(m)
    for minimize in (True, False):
        got = _sweeper(m, minimize).row_values(v)
        for r in range(m.n_rows):
            row = rows[(int(m.row_state[r]), int(m.row_action[r]))]
            assert got[r] == pytest.approx(ref_expectation(row, v, minimize), abs=1e-15)


@pytest.mark.parametrize("zero_lower", [True, False])
def test_sort_critical_records_the_critical_entry_of_the_sorted_row(zero_lower):
    """The critical entry found without the sorted sum is the one :func:`sorted_value`
    records, for both adversaries, on values with many ties (coarse levels: equal keys,
    where the order among them decides) and on the edge rows (nothing left to hand out,
    point intervals, upper bounds summing to 1)."""
    from planner.imdp.kernels.rows import scratch, sort_critical, sorted_value

    rng = np.random.default_rng(5)
    models = [random_imdp(rng, n_states=100, max_succ=9, zero_lower=zero_lower), _edge_rows()]
    checked = 0
    for m in models:
        for minimize in (True, False):
            sw = _sweeper(m, minimize)
            layout = (sw.row_ptr, sw.remaining, sw.succ, sw.lower, sw.gap)
            idx, keys = scratch(sw.row_ptr)
            sign = 1.0 if minimize else -1.0
            for levels in (3, 1000):
                v = rng.integers(0, levels, size=m.n_states) / (levels - 1)
                want = np.full(sw.rows.size, -7, dtype=np.int64)
                got = np.full(sw.rows.size, -7, dtype=np.int64)
                for k in range(sw.rows.size):
                    sorted_value(k, *layout, v, sign, want, idx, keys)
                    ptr, rem, succ, _, gap = layout
                    sort_critical(k, ptr, rem, succ, gap, v, sign, got, idx, keys)
                    checked += 1
                np.testing.assert_array_equal(got, want)
    assert checked > 500


def _naive_attractor(m: IMDP, start: np.ndarray, cand: np.ndarray) -> np.ndarray:
    x = start.copy()
    while True:
        ok = cand & forced_into(m, x) & ~x[m.row_state]
        if not ok.any():
            return x
        x[m.row_state[ok]] = True


@pytest.mark.parametrize("seed", range(6))
def test_attractor_matches_fixpoint_and_its_choices_make_progress(seed):
    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=60, max_succ=5, zero_lower=bool(seed % 2))
    start = rng.random(m.n_states) < 0.1
    cand = rng.random(m.n_rows) < 0.8
    x, choice = _attractor(m, start, cand)
    assert np.array_equal(x, _naive_attractor(m, start, cand))
    assert np.all(choice[start] == -1) and np.all(choice[~x] == -1)
    # replaying the joins in an order where each chosen row is forced into the states
    # before it must reach the whole attractor
    joined = start.copy()
    pending = set(np.flatnonzero(x & ~start).tolist())
    while pending:
        forced = forced_into(m, joined)
        ready = [s for s in pending if cand[choice[s]] and forced[choice[s]]]
        assert ready, "a chosen row does not lead into earlier states"
        for s in ready:
            assert m.row_state[choice[s]] == s
            joined[s] = True
            pending.discard(s)


@pytest.mark.parametrize("seed", range(5))
def test_chain_reaching_matches_a_breadth_first_search_on_the_transpose(seed):
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order

    from planner.imdp.evaluate import reaching

    rng = np.random.default_rng(seed)
    n = 200
    adj = sp.random(n, n, density=0.01, format="csr", random_state=seed)
    adj.data[rng.random(adj.data.size) < 0.2] = 0.0  # stored zeros are no edges
    seeds = rng.random(n) < 0.03
    got = reaching(adj, seeds)
    rev = (adj > 0).T.tocsr()
    want = seeds.copy()
    for s in np.flatnonzero(seeds):
        want[breadth_first_order(rev, s, directed=True, return_predecessors=False)] = True
    np.testing.assert_array_equal(got, want)
    assert got[seeds].all() and 0 < got.sum() < n


@pytest.mark.parametrize("seed", range(5))
def test_layers_are_breadth_first_hop_counts_over_the_free_rows(seed):
    from planner.imdp.kernels import layers

    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=80, max_succ=4, zero_lower=bool(seed % 2))
    ptr, rows, states, _, _ = m.reverse_index()
    np.testing.assert_array_equal(states, m.row_state[rows])
    assert np.array_equal(ptr, np.searchsorted(np.sort(m.successor), np.arange(m.n_states + 1)))
    free = np.flatnonzero(rng.random(m.n_rows) < 0.6)
    sources = rng.random(m.n_states) < 0.05
    sources[0] = True
    got = layers(m, free, sources)
    np.testing.assert_array_equal(got, _hops(m, free, sources))
    assert np.isfinite(got).sum() > sources.sum()


def _hops(m: IMDP, free: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """Hop counts from each state to ``sources`` over the ``upper > 0`` entries of the
    rows ``free`` (scipy's unweighted shortest paths on the reversed graph)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import shortest_path

    keep = np.isin(m.entry_row, free) & (m.upper > 0)
    src, dst = m.row_state[m.entry_row[keep]], m.successor[keep]
    adj = sp.csr_matrix((np.ones(src.size), (dst, src)), shape=(m.n_states, m.n_states))
    return shortest_path(adj, unweighted=True, indices=np.flatnonzero(sources)).min(axis=0)


@pytest.mark.parametrize("split", [False, True])
@pytest.mark.parametrize("wide", [False, True])
def test_the_reverse_index_groups_the_entries_by_successor_in_entry_order(split, wide, monkeypatch):
    from planner.imdp.kernels import search

    # split: the two-thread scatter (large models) on a small one; wide: the 64-bit rows
    # and states of models with more than 2^31 rows or states
    monkeypatch.setattr(search, "SPLIT_ENTRIES", 1 if split else 10**12)
    if wide:
        monkeypatch.setattr(search, "_incoming_arrays32", search._incoming_arrays)
    m = random_imdp(np.random.default_rng(3), n_states=200, max_succ=6, zero_lower=True)
    ptr, rows, states, lower, upper = search.incoming_index(
        m.successor, m.entry_row, m.row_state, m.lower, m.upper, m.n_states
    )
    order = np.argsort(m.successor, kind="stable")
    np.testing.assert_array_equal(ptr, np.searchsorted(m.successor[order], np.arange(201)))
    np.testing.assert_array_equal(rows, m.entry_row[order])
    np.testing.assert_array_equal(states, m.row_state[m.entry_row[order]])
    np.testing.assert_array_equal(lower, m.lower[order])
    np.testing.assert_array_equal(upper, m.upper[order])
    assert rows.dtype == states.dtype == (np.int64 if wide else np.int32)


@pytest.mark.parametrize("certified", [False, True])
def test_sweeps_on_64_bit_successors_give_the_same_solution(certified, monkeypatch):
    """The sweeps' layout keeps its successors as 32-bit integers where the states fit; a
    model beyond that (forced here) gets 64-bit ones and the same solution, bit for bit."""
    from planner.imdp import Problem, ReachAvoid, Specification, ValueIteration, solve

    m = random_imdp(np.random.default_rng(8), n_states=300, max_succ=6, zero_lower=True)
    problem = Problem(m, Specification(ReachAvoid("goal", "bad")))
    alg = ValueIteration(certified=certified)
    narrow = solve(problem, alg)
    assert _sweeper(m, True).succ.dtype == np.int32
    monkeypatch.setattr(sweeps, "NARROW_STATES", 0)
    assert _sweeper(m, True).succ.dtype == np.int64
    wide = solve(problem, alg)
    for name in ("values", "lower", "upper", "strategy"):
        np.testing.assert_array_equal(getattr(wide, name), getattr(narrow, name))
    assert wide.iterations == narrow.iterations


def _upper_start(m: IMDP) -> tuple[np.ndarray, np.ndarray]:
    """Free rows (not at the goal or the absorbing sink 0) and ``U = 1`` there, the goal at
    1 and the sink at 0."""
    goal = m.states_labelled("goal")
    settled = goal.copy()
    settled[0] = True
    u = np.where(goal, 1.0, 0.0)
    u[~settled] = 1.0
    return np.flatnonzero(~settled[m.row_state]), u


@pytest.mark.parametrize("seed", range(4))
def test_tracked_passes_from_above_equal_untracked_ones(monkeypatch, seed):
    # with every decrease flagged (mark_above = 0), a skipped state is one whose inputs
    # did not change since its last evaluation: the same values, fewer evaluations
    monkeypatch.setattr(sweeps, "TRACK_START", 1.0)  # track from the first pass
    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=60, n_actions=4, max_succ=6)
    free_rows, u = _upper_start(m)
    key = rng.random(m.n_states)
    plain = ReachSweeper(m, free_rows, key, True, True)
    tracked = ReachSweeper(m, free_rows, key, True, True)
    tracked.track_changes(0.0)
    cache_plain, cache_tracked = plain.upper_cache(), tracked.upper_cache()
    a, b = u.copy(), u.copy()
    evaluated = []
    for _ in range(400):
        dec, _ = plain.upper_pass(a, cache=cache_plain)
        before = cache_tracked.copy()
        tracked.upper_pass(b, cache=cache_tracked, track=True)
        evaluated.append(int((cache_tracked != before).sum()))
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-15)
        if dec == 0.0:
            break
    assert dec == 0.0 and a.min() < 1.0  # converged, and the values moved
    before = cache_tracked.copy()
    tracked.upper_pass(b, cache=cache_tracked, track=True)
    assert np.array_equal(cache_tracked, before)  # nothing moved, nothing is due
    assert evaluated[0] > 0 and min(evaluated) < evaluated[0]


def test_tracking_waits_until_few_states_move(monkeypatch):
    # until a pass moves at most TRACK_START of the free states, every state is evaluated
    monkeypatch.setattr(sweeps, "TRACK_START", 0.0)  # only after a pass that moved none
    m = random_imdp(np.random.default_rng(5), n_states=60, n_actions=4, max_succ=6)
    free_rows, u = _upper_start(m)
    sw = ReachSweeper(m, free_rows, np.zeros(m.n_states), True, True)
    ref = ReachSweeper(m, free_rows, np.zeros(m.n_states), True, True)
    sw.track_changes(0.0)
    a, b = u.copy(), u.copy()
    cache_a, cache_b = sw.upper_cache(), ref.upper_cache()
    for _ in range(400):
        seen_a, seen_b = cache_a.copy(), cache_b.copy()
        sw.upper_pass(a, cache=cache_a, track=True)
        dec, _ = ref.upper_pass(b, cache=cache_b)
        np.testing.assert_array_equal(a, b)
        # the same rows evaluated (a skipped state would keep its cached rows)
        np.testing.assert_array_equal(cache_a != seen_a, cache_b != seen_b)
        if dec == 0.0:
            break
    assert dec == 0.0
    # that pass moved no state: tracking starts with every state due, then none is
    sw.upper_pass(a, cache=cache_a, track=True)
    ref.upper_pass(b, cache=cache_b)
    free = np.unique(m.row_state[free_rows])
    t = free[np.argmax(a[free])]  # lower the highest free value: its predecessors follow
    before = a.copy()
    a[t] *= 0.5
    lowered, b = a.copy(), a.copy()
    sw.upper_pass(a, cache=cache_a, track=True)
    np.testing.assert_array_equal(a, lowered)  # not reported: nothing is due
    ref.upper_pass(b, cache=cache_b)
    assert (b < lowered).sum() > 0  # a full pass carries the drop to the predecessors
    sw.moved_above(before, lowered)
    sw.upper_pass(a, cache=cache_a, track=True)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="cannot repair"):
        sw.upper_pass(a, raise_violations=True, track=True)


@pytest.mark.parametrize("seed", range(4))
def test_full_sweeps_skip_rows_bounded_below_the_best_and_nothing_else_changes(seed):
    # the rows' cached values of a lazy pass from above bound them at every lower vector;
    # a row bounded below the best row found so far can neither beat nor tie it
    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=60, n_actions=5, max_succ=6)
    free_rows, u = _upper_start(m)
    key = rng.random(m.n_states)
    plain = ReachSweeper(m, free_rows, key, True, True)
    pruned = ReachSweeper(m, free_rows, key, True, True)
    above = ReachSweeper(m, free_rows, key, True, True)
    cache = above.upper_cache()
    for _ in range(40):
        above.upper_pass(u, cache=cache)
    a = np.where(u == 1.0, u, 0.0)
    a[plain.states] = 0.0
    b = a.copy()
    for _ in range(30):
        plain.sweep(a, True)
        pruned.sweep(b, True, bound=cache)
        np.testing.assert_array_equal(b, a)
        np.testing.assert_array_equal(pruned.best_row, plain.best_row)
    # rows were skippable: bounded below their state's value from below
    assert (cache < a[m.row_state[plain.rows]]).sum() > 0
    # a bound below every value skips all rows but the last best one
    pruned.best_row[:] = pruned.state_rows[:-1]
    low = np.full(cache.size, -1.0)
    c = a.copy()
    pruned.sweep(c, True, bound=low)
    np.testing.assert_array_equal(pruned.best_row, pruned.state_rows[:-1])
    assert (pruned.best_row != plain.best_row).any()


def _equal_rows_imdp(rng: np.random.Generator, n: int, k: int) -> IMDP:
    """Three actions per state, every row ``k`` distinct successors (an interval around a
    random distribution), 10 % of the states labelled goal."""
    succ = np.stack([rng.choice(n, size=k, replace=False) for _ in range(3 * n)])
    p = rng.dirichlet(np.ones(k), size=3 * n)
    lower = p * rng.uniform(0.3, 1.0, size=p.shape)
    upper = np.minimum(1.0, p + rng.uniform(0.0, 0.3, size=p.shape))
    labels = [("goal",) if x < 0.1 else () for x in rng.random(n)]
    return IMDP(
        n,
        np.repeat(np.arange(n), 3 * k),
        np.tile(np.repeat(np.arange(3), k), n),
        succ.ravel(),
        lower.ravel(),
        upper.ravel(),
        n_actions=3,
        labels=labels,
    )


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("equal_rows", [True, False])
def test_full_sweeps_keep_the_light_copy_a_gather_of_the_best_rows(seed, equal_rows, monkeypatch):
    """After every full sweep the light copy equals a fresh gather of the best rows at the
    current critical successors. The sweep copies a changed best row into its slot where
    the lengths agree (rows all of 4 entries: the copy is never gathered, even the first
    sweep fills its slots), and where they do not the copy is gathered anew (rows of 1-6
    entries), the slots that kept their rows from the copy itself."""
    from planner.imdp.kernels.rows import gather_rows, regather_rows

    gathers = []
    monkeypatch.setattr(
        sweeps, "regather_rows", lambda *a: gathers.append(a[1].copy()) or regather_rows(*a)
    )
    rng = np.random.default_rng(300 + seed)
    if equal_rows:
        m = _equal_rows_imdp(rng, 60, 4)
    else:
        m = random_imdp(rng, n_states=60, n_actions=3, max_succ=6, zero_lower=bool(seed % 2))
    sw = _sweeper(m, seed < 2)
    layout = (sw.row_ptr, sw.remaining, sw.succ, sw.lower, sw.gap)
    v = np.where(m.states_labelled("goal"), 1.0, 0.0)
    changed = 0
    for step in range(10):
        before = sw.best_row.copy()
        if step % 3 == 2:  # values jump: other best rows
            v = np.maximum(v, 0.9 * rng.random(v.size) * (v < 1.0))
        sw.sweep(v, True)
        changed += int((before != sw.best_row).sum())
        np.testing.assert_array_equal(sw._light_rows, sw.best_row)
        fresh = gather_rows(sw.best_row, *layout, sw.crit)
        for got, want in zip(sw._light, fresh, strict=True):
            np.testing.assert_array_equal(got, want)
    assert changed > 20
    if equal_rows:
        assert not gathers
    else:  # gathered anew where a slot lost its row, from the copy where it kept it
        assert gathers and all((g < 0).any() and (g >= 0).any() for g in gathers)


def test_row_sum_signs_match_exactly_rounded_sums():
    # rows summing to 1 up to a few ulps, to exactly 1, and far from it: the sign of
    # ``sum - 1`` is the exact one (math.fsum) on every row
    import math

    from planner.imdp.kernels.exact import row_sum_signs

    rng = np.random.default_rng(0)
    rows = []
    for k in rng.integers(1, 12, size=400):
        p = rng.dirichlet(np.ones(k))
        kind = rng.integers(3)
        if kind == 1:
            p = p * (1.0 + rng.choice([-1.0, 1.0]) * 2.0 ** -int(rng.integers(40, 60)))
        elif kind == 2:
            p = np.round(p, 3)
        rows.append(np.clip(p, 0.0, 1.0))
    ptr = np.concatenate(([0], np.cumsum([r.size for r in rows]))).astype(np.int64)
    signs = row_sum_signs(ptr, np.concatenate(rows))
    exact = [int(np.sign(math.fsum([*r.tolist(), -1.0]))) for r in rows]
    assert signs.tolist() == exact and {-1, 0, 1} <= set(exact)


@pytest.mark.parametrize("seed", range(3))
def test_a_full_sweep_in_halves_is_a_block_gauss_seidel_sweep(seed, monkeypatch):
    # forced on a small model: the later half reads the earlier half's values from before
    # the sweep, whatever the threads' timing; the layout is the model's entries
    from planner.imdp.kernels import gauss_seidel_sweep

    monkeypatch.setattr(sweeps, "HALVES_SWEEP_ENTRIES", 1)
    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=120, n_actions=4, max_succ=6, zero_lower=bool(seed % 2))
    sw = _sweeper(m, True)
    cut = sw._cut
    assert 0 < cut < sw.states.size
    ent = np.concatenate([np.arange(m.row_ptr[r], m.row_ptr[r + 1]) for r in sw.rows])
    np.testing.assert_array_equal(sw.succ, m.successor[ent])
    np.testing.assert_array_equal(sw.lower, m.lower[ent])
    np.testing.assert_array_equal(sw.gap, m.upper[ent] - m.lower[ent])
    v = np.where(m.states_labelled("goal"), 1.0, 0.0)
    monkeypatch.setattr(sweeps, "HALVES_SWEEP_ENTRIES", 10**12)
    ref = _sweeper(m, True)
    assert ref._cut == 0
    for _ in range(6):
        want = v.copy()
        later = v.copy()
        layout = (ref.row_ptr, ref.remaining, ref.succ, ref.lower, ref.gap, ref.crit)
        none = np.empty(0)
        sides = (
            True,
            True,
            none,
            none,
            none,
            none,
            0.0,
            sweeps.NO_LAYOUT,
            sweeps._NO_INDEX,
            0,
            sweeps._NO_FLAGS,
        )
        st, rows, best = ref.states, ref.state_rows, ref.best_row
        r0 = gauss_seidel_sweep(st[:cut], rows[: cut + 1], *layout, want, best[:cut], *sides)
        r1 = gauss_seidel_sweep(st[cut:], rows[cut:], *layout, later, best[cut:], *sides)
        want[st[cut:]] = later[st[cut:]]
        got = v.copy()
        assert sw.sweep(got) == max(r0, r1)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(sw.best_row, ref.best_row)
        v = got
    assert v.max() > 0.0


@pytest.mark.parametrize("seed", range(3))
def test_a_split_light_sweep_is_a_block_gauss_seidel_sweep_of_the_copy(seed, monkeypatch):
    """A light sweep asked to ``split`` (forced on a small model) sweeps the two halves of
    the best rows' copy at once: the later half (cut at half the copy's entries) reads the
    earlier half's values from before the sweep, the values, critical successors and record
    of written values are those of the two halves swept one after the other that way; not
    asked to split, it is the whole light sweep."""
    from planner.imdp.kernels.gauss_seidel import light_sweep

    def earlier_half_first(background, foreground, purpose):
        # the worst timing for a later half that read the shared values: after the earlier
        out = foreground()
        return background(), out

    monkeypatch.setattr(sweeps, "HALVES_SWEEP_ENTRIES", 1)
    monkeypatch.setattr(sweeps, "concurrently", earlier_half_first)
    rng = np.random.default_rng(40 + seed)
    m = random_imdp(rng, n_states=150, n_actions=3, max_succ=6, zero_lower=bool(seed % 2))
    sw = _sweeper(m, True)
    v = np.where(m.states_labelled("goal"), 1.0, 0.0)
    sw.sweep(v, True)
    ptr = sw._light[0]
    cut = int(np.searchsorted(ptr, ptr[-1] // 2))
    assert 0 < cut < sw.states.size
    st, n = sw.states, sw.states.size
    for k in range(5):
        split = k != 2
        light = tuple(a.copy() for a in sw._light)
        want, last = v.copy(), sw._last.copy()
        if split:
            p, rem, succ, lo, gap, crit = light
            later = want.copy()
            halves = [(0, cut, want), (cut, n, later)]
            res = [
                light_sweep(
                    st[a:b], p[a : b + 1], rem[a:b], succ, lo, gap, crit[a:b], x, True, last
                )
                for a, b, x in halves
            ]
            want[st[cut:]] = later[st[cut:]]
            r_want = max(res)
        else:
            r_want = light_sweep(st, *light, want, True, last)
        got = v.copy()
        assert sw.sweep(got, False, split=split) == r_want
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(sw._light[5], light[5])
        np.testing.assert_array_equal(sw._last, last)
        v = got
    assert v.max() > 0.0


@pytest.mark.parametrize("seed", range(4))
def test_dropping_states_continues_the_pruning_cascade_as_pruning_anew(seed):
    """Removing states in steps, through the cascade's state, ends where pruning all of
    them at once does: the rows staying among the states kept, and no state outside
    ``keep`` left without one."""
    from planner.imdp.kernels import drop_states, prune_kernel

    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=150, max_succ=3, zero_lower=bool(seed % 2))
    rows = rng.random(m.n_rows) < 0.97
    keep = rng.random(m.n_states) < 0.05
    inc_ptr, inc_row, _, _, inc_upper = m.reverse_index()
    arrays = (m.row_state, m.state_ptr, m.row_ptr, m.successor, m.upper)
    index = (inc_ptr, inc_row, inc_upper)
    removed = rng.random(m.n_states) < 0.01
    bad, stay, live = prune_kernel(removed, rows, *arrays, *index, keep)
    for _ in range(5):
        more = ~bad & (rng.random(m.n_states) < 0.01)
        removed |= more
        drop_states(np.flatnonzero(more), bad, stay, live, m.row_state, m.state_ptr, *index, keep)
        want_bad, want_stay, want_live = prune_kernel(removed, rows, *arrays, *index, keep)
        np.testing.assert_array_equal(bad, want_bad)
        np.testing.assert_array_equal(stay, want_stay)
        np.testing.assert_array_equal(live, want_live)
        entries_out = bad[m.successor] & (m.upper > 0)
        assert not np.any(np.add.reduceat(entries_out, m.row_ptr[:-1])[stay])
        assert not np.any(stay & bad[m.row_state])
        assert np.all((live > 0) | bad | keep)
    assert stay.any() and bad.any()


def _chain_imdp(rng: np.random.Generator, n: int) -> IMDP:
    """States ``0..n-1`` whose rows go ``1..40`` states up (and, in one row of three,
    also to a random state), with some lower bounds 0: an attractor of the top states
    grows against the index order, so a forward pass from state 0 lets few states join."""
    s, a, t, lo, up = [], [], [], [], []
    for q in range(n - 1):
        for act in range(3):
            succ = sorted({min(q + int(j), n - 1) for j in rng.integers(1, 40, size=2)})
            if act == 0:
                succ = sorted(set(succ) | {int(rng.integers(0, n))})
            p = rng.dirichlet(np.ones(len(succ)))
            low = np.where(rng.random(len(succ)) < 0.3, 0.0, 0.5 * p)
            s += [q] * len(succ)
            a += [act] * len(succ)
            t += succ
            lo += low.tolist()
            up += np.minimum(1.0, p + 0.2).tolist()
    s, a, t, lo, up = [*s, n - 1], [*a, 0], [*t, n - 1], [*lo, 1.0], [*up, 1.0]
    return IMDP(n, s, a, t, lo, up)


@pytest.mark.parametrize("seed", range(2))
def test_attractor_after_a_forward_pass_that_does_not_pay(seed):
    """On a model whose attractor grows against the index order the forward passes stop
    early and the work list does the rest: the same fixpoint, and choices that replay."""
    rng = np.random.default_rng(seed)
    m = _chain_imdp(rng, 3000)
    start = np.zeros(m.n_states, dtype=bool)
    start[-5:] = True
    cand = rng.random(m.n_rows) < 0.9
    x, choice = _attractor(m, start, cand)
    assert np.array_equal(x, _naive_attractor(m, start, cand))
    assert x.sum() > 2000
    # the passes alone stop far short: the work list found most of it
    passed = start.copy()
    arrays = (m.row_state, m.row_ptr, m.successor, m.lower, m.upper)
    width = int(np.diff(m.row_ptr).max()) + 1
    scratch = (np.empty(width), np.empty(width))
    search._forward_passes(passed, np.full(m.n_states, -1), cand, *arrays, True, *scratch)
    assert passed.sum() < x.sum() // 2
    joined = start.copy()
    pending = np.flatnonzero(x & ~start)
    while pending.size:
        forced = forced_into(m, joined)
        ready = pending[forced[choice[pending]] & cand[choice[pending]]]
        assert ready.size, "a chosen row does not lead into earlier states"
        assert (m.row_state[choice[ready]] == ready).all()
        joined[ready] = True
        pending = np.setdiff1d(pending, ready)


def _raise_some(rng: np.random.Generator, *vs: np.ndarray) -> None:
    """The same random rise of a few values of each of ``vs``, in place (as strategy
    iteration or an end-component collapse raises values between sweeps)."""
    at = rng.random(vs[0].size) < 0.1
    by = rng.uniform(0.0, 0.5, size=vs[0].size)
    for v in vs:
        v[at] = np.minimum(1.0, v[at] + by[at])


@pytest.mark.parametrize("seed", range(4))
def test_skipping_rows_by_their_last_values_changes_no_sweep(seed, monkeypatch):
    """Full sweeps that skip rows shown worse than the best from their last values (and
    the rises of the values since, those between sweeps included) give the values, best
    rows and residuals of sweeps that evaluate every row; the bounded row values keep the
    optimal rows exact and the others above their value and below the best."""
    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=150, n_actions=5, max_succ=6, zero_lower=bool(seed % 2))
    minimizes = bool(seed < 2)
    monkeypatch.setattr(sweeps, "ELIMINATE", False)
    plain = _sweeper(m, minimizes)
    monkeypatch.setattr(sweeps, "ELIMINATE", True)
    skip = _sweeper(m, minimizes)
    v0 = np.where(m.states_labelled("goal"), 1.0, 0.0)
    v0[0] = 0.0
    a, b = v0.copy(), v0.copy()
    for step in range(40):
        full = step % 3 == 0 or rng.random() < 0.3
        assert plain.sweep(a, full) == skip.sweep(b, full)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(plain.best_row, skip.best_row)
        if rng.random() < 0.3:
            _raise_some(rng, a, b)
    slack = 1e-7
    exact = plain.row_values(a)
    bounded = skip.row_values(b, slack)
    q = exact[skip._position]  # layout order
    qb = bounded[skip._position]
    best = np.maximum.reduceat(q, skip.state_rows[:-1])
    best = np.repeat(best, np.diff(skip.state_rows))
    near = q >= best - slack
    np.testing.assert_array_equal(qb[near], q[near])
    assert (qb[~near] >= q[~near] - 1e-15).all() and (qb[~near] < best[~near] - slack).all()
    assert (~near).sum() > 0 and (qb[~near] != q[~near]).any()


@pytest.mark.parametrize("seed", range(3))
def test_a_full_sweep_lowers_the_sum_of_rises_to_the_largest_rise_since_the_last(seed, monkeypatch):
    """At a full sweep the sum of rises becomes, where that is less, its value at the start
    of the last full sweep plus the largest rise of a value since: it skips more rows (the
    sweeps in between add the largest change of each, from different states), the values
    and best rows staying those of the sweeps without it (the skipping test above checks
    them against sweeps that skip nothing)."""
    rng = np.random.default_rng(40 + seed)
    m = random_imdp(rng, n_states=150, n_actions=5, max_succ=6, zero_lower=bool(seed % 2))
    tight = _sweeper(m, True)
    loose = _sweeper(m, True)
    monkeypatch.setattr(loose, "_tighten", lambda v, snap=False: None)
    a = np.where(m.states_labelled("goal"), 1.0, 0.0)
    b = a.copy()
    lowered = 0
    for step in range(30):
        full = step % 4 == 0
        assert tight.sweep(a, full) == loose.sweep(b, full)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(tight.best_row, loose.best_row)
        assert tight._rise <= loose._rise
        if full and step > 0:
            # the sum at the start of the last full sweep, plus the largest rise since
            assert tight._rise >= tight._snap_rise
            lowered += tight._rise < loose._rise
    assert lowered > 0


def test_the_sum_of_rises_never_falls_below_the_exact_sum():
    """``rose`` rounds every addition up, so the skipping bound's ``c`` stays at least the
    exact sum of the rises however many are added (a float sum falls below it)."""
    from fractions import Fraction

    from planner.imdp.kernels.elimination import rose

    rng = np.random.default_rng(0)
    rises = rng.random(20_000) * 10.0 ** rng.uniform(-17, 0, 20_000)
    c, plain, exact = 0.0, 0.0, Fraction(0)
    below = 0
    for r in rises:
        c = rose(c, float(r))
        plain += float(r)
        exact += Fraction(float(r))
        assert Fraction(c) >= exact
        below += Fraction(plain) < exact
    assert below > 0


@pytest.mark.parametrize("seed", range(3))
def test_full_sweeps_read_the_best_rows_from_the_light_copy(seed):
    """A full sweep that evaluates each state's last best row from the light sweeps'
    contiguous copy gives the values and best rows of one that reads the full layout (up to
    the rounding of an equally valid critical successor), and copies the critical
    successor back so that a patched light layout still equals a fresh gather."""
    from planner.imdp.kernels import gauss_seidel_sweep
    from planner.imdp.kernels.rows import gather_rows

    rng = np.random.default_rng(400 + seed)
    m = random_imdp(rng, n_states=150, n_actions=4, max_succ=6, zero_lower=bool(seed % 2))
    sw = _sweeper(m, bool(seed < 2))
    v = np.where(m.states_labelled("goal"), 1.0, 0.0)
    for step in range(6):
        sw.sweep(v, step % 3 == 0)
    assert sw._light is not None
    layout = (sw.row_ptr, sw.remaining, sw.succ, sw.lower, sw.gap)
    none = np.empty(0)
    results = []
    for use_light in (False, True):
        vv, crit, best = v.copy(), sw.crit.copy(), sw.best_row.copy()
        light = tuple(a.copy() for a in sw._light)
        slots = sw._light_rows.copy() if use_light else sweeps._NO_INDEX
        args = (
            sw.states,
            sw.state_rows,
            *layout,
            crit,
            vv,
            best,
            True,
            sw.adversary_minimizes,
        )
        none4 = (none, none, none, none, 0.0)
        r = gauss_seidel_sweep(
            *args, *none4, light if use_light else sweeps.NO_LAYOUT, slots, 0, sweeps._NO_FLAGS
        )
        results.append((r, vv, best, crit, light))
    (r0, v0, b0, _, _), (r1, v1, b1, crit1, light1) = results
    np.testing.assert_allclose(v1, v0, rtol=0.0, atol=1e-15)
    np.testing.assert_array_equal(b1, b0)
    assert abs(r1 - r0) <= 1e-15 and r1 > 0.0
    # the copied-back critical successors are those of the light copy; a slot whose best
    # row changed holds the new row (or, of another length, is marked -1)
    held = np.where(slots >= 0, slots, sw._light_rows)
    fresh = gather_rows(held, *layout, crit1)
    assert np.array_equal(slots[slots >= 0], b1[slots >= 0])
    np.testing.assert_array_equal(fresh[5][slots >= 0], light1[5][slots >= 0])


@pytest.mark.parametrize("zero_lower", [True, False])
def test_the_feasible_bound_of_a_moved_row_is_never_below_its_value(zero_lower):
    """Where a row's stored critical successor no longer stands, the bound formed around
    it in one pass (no sorting) is at least the row's value under the minimising
    adversary (the reference), and close to it when the values only drifted."""
    from planner.imdp.kernels.rows import feasible_bound, threshold_value

    rng = np.random.default_rng(21)
    m = random_imdp(rng, n_states=40, max_succ=7, zero_lower=zero_lower)
    rows = rows_of(m)
    sw = _sweeper(m, True)
    layout = (sw.row_ptr, sw.remaining, sw.succ, sw.lower, sw.gap)
    moved = 0
    gaps = []
    for v in _moving_values(rng, m.n_states, 10, 0.02):
        stale = sw.crit.copy()
        sw.row_values(v)  # the critical successors at v, for the next step's stale ones
        for k in range(sw.rows.size):
            if not np.isnan(threshold_value(k, *layout, v, 1.0, stale)):
                continue
            moved += 1
            bound = feasible_bound(k, *layout, v, stale)
            r = int(sw.rows[k])
            exact = ref_expectation(rows[(int(m.row_state[r]), int(m.row_action[r]))], v, True)
            assert bound >= exact - 1e-15
            gaps.append(bound - exact)
    assert moved > 50
    assert np.median(gaps) < 0.05


@pytest.mark.parametrize("maximize", [True, False])
def test_greedy_rows_match_the_array_reference(maximize):
    """The compiled greedy rows (first of each state's exact best) and the flag of a state
    with another row within the slack equal the array computation they replace."""
    from planner.imdp.kernels.rows import greedy_rows
    from planner.imdp.model import first_of_runs
    from planner.imdp.strategy import optimal_rows, state_best

    rng = np.random.default_rng(5)
    outcomes = set()
    for trial in range(30):
        rs = np.sort(rng.integers(0, 40, size=200))
        q = np.round(rng.random(200), 2)  # exact ties
        if trial % 3 == 0:
            q = q + rng.random(200) * 1e-6  # rows near but not at the best
        seg = first_of_runs(rs)
        slack = 1e-7 if trial % 2 else 1e-5
        best = state_best(q, seg, rs, maximize)
        top = np.flatnonzero(q == best)
        want = top[first_of_runs(rs[top])]
        got, tied = greedy_rows(q, seg, maximize, slack)
        np.testing.assert_array_equal(got, want)
        near = np.abs(q - best) <= slack
        assert tied == bool(np.bincount(rs[near]).max() > 1)
        assert tied == (want.size < optimal_rows(q, seg, rs, maximize, slack / 10).size)
        outcomes.add(tied)
    assert outcomes == {False, True}


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_sorting_a_row_by_rank_is_a_stable_sort(sign):
    """The branch-free sort of a row's entries (each to its rank) puts them in the order of
    a stable sort by key, ties (exact, and -0.0 against 0.0) in entry order."""
    from planner.imdp.kernels.rows import sort_entries

    rng = np.random.default_rng(8)
    for _ in range(200):
        n = int(rng.integers(1, 26))
        v = np.round(rng.random(30), 1)  # many exact ties
        v[rng.random(30) < 0.1] = -0.0
        succ = rng.integers(0, 30, size=n + 5)
        a = int(rng.integers(0, 6))
        idx, keys = np.full(n, -1, dtype=np.int64), np.full(2 * n, np.nan)
        sort_entries(a, n, succ, v, sign, idx, keys)
        k = sign * v[succ[a : a + n]]
        order = np.argsort(k, kind="stable")
        np.testing.assert_array_equal(idx, a + order)
        np.testing.assert_array_equal(keys[:n], k[order])


@pytest.mark.parametrize("seed", range(4))
def test_the_light_kernel_is_the_generic_sweep_of_the_best_rows(seed):
    """A light sweep (:func:`light_sweep`, the contiguous copy of the best rows) updates the
    values, critical successors and the record of written values as the generic kernel's
    sweep of that copy as a layout of one row per state does, up to the rounding of its
    sums."""
    from planner.imdp.kernels import gauss_seidel_sweep
    from planner.imdp.kernels.gauss_seidel import light_sweep

    rng = np.random.default_rng(700 + seed)
    m = random_imdp(rng, n_states=120, n_actions=3, max_succ=7, zero_lower=bool(seed % 2))
    sw = _sweeper(m, seed < 2)
    v = np.where(m.states_labelled("goal"), 1.0, 0.0)
    sw.sweep(v, True)
    sw.sweep(v, True)
    v = v * (1.0 + 0.5 * rng.random(v.size))  # values moved: some rows need sorting
    one = np.arange(sw.states.size + 1, dtype=np.int64)
    none = np.empty(0)
    out = []
    for generic in (False, True):
        vv, light, last = v.copy(), tuple(a.copy() for a in sw._light), np.zeros(v.size)
        if generic:
            r = gauss_seidel_sweep(
                sw.states, one, *light, vv, np.zeros(one.size, np.int64), True,
                sw.adversary_minimizes,
                none, none, none, last, 0.0, sweeps.NO_LAYOUT, sweeps._NO_INDEX, 0,
                sweeps._NO_FLAGS,
            )  # fmt: skip
        else:
            r = light_sweep(sw.states, *light, vv, sw.adversary_minimizes, last)
        out.append((r, vv, light[5], last))
    (r0, v0, c0, l0), (r1, v1, c1, l1) = out
    assert r0 > 0.0 and abs(r0 - r1) <= 1e-15
    np.testing.assert_allclose(v0, v1, rtol=0.0, atol=1e-15)
    np.testing.assert_allclose(l0, l1, rtol=0.0, atol=1e-15)
    assert np.any(c1 != sw._light[5])  # rows were sorted anew
    keys = [v1[light[2][c]] for c in (c0, c1)]
    np.testing.assert_array_equal(keys[0], keys[1])


@pytest.mark.parametrize("dense", [False, True])
def test_layers_in_either_direction_are_breadth_first_hop_counts(dense):
    """The sweeps' layers, searched level by level top-down or bottom-up (dense models
    reach most states in the first level, so the next goes bottom-up), are the hop counts
    of a breadth-first search, also where some states are unreachable."""
    from planner.imdp.kernels import layers

    rng = np.random.default_rng(31 + dense)
    for _ in range(10):
        if dense:
            m = random_imdp(rng, n_states=300, n_actions=3, max_succ=9, zero_lower=True)
        else:
            m = random_imdp(rng, n_states=120, n_actions=2, max_succ=2, zero_lower=True)
        free = np.flatnonzero(rng.random(m.n_rows) < 0.8)
        sources = rng.random(m.n_states) < 0.05
        sources[0] = True
        row_mask = np.zeros(m.n_rows, dtype=bool)
        row_mask[free] = True
        want = _hops(m, free, sources)
        np.testing.assert_array_equal(layers(m, free, sources), want)
        np.testing.assert_array_equal(layers(m, row_mask, sources), want)
        if dense:
            assert np.mean(want == 1.0) > 0.5
        else:
            assert np.isinf(want).any()


def test_the_sweep_order_is_a_stable_sort_of_the_states_with_their_rows():
    """The layout's index from one compiled pass equals its array definition: the states
    of the free rows stably sorted by key (ties, including ``inf``, in index order), each
    with its run of rows, their entry offsets and remaining masses."""
    from planner.imdp.kernels.layers import sweep_order
    from planner.imdp.model import first_of_runs

    rng = np.random.default_rng(44)
    for _ in range(20):
        m = random_imdp(rng, n_states=60, n_actions=3, max_succ=5, zero_lower=True)
        free = np.flatnonzero(rng.random(m.n_rows) < 0.7)
        key = rng.integers(0, 4, m.n_states).astype(float)  # many ties
        key[rng.random(m.n_states) < 0.1] = np.inf
        states, state_rows, position, rows, row_ptr, remaining = sweep_order(
            free, m.row_state, key, m.row_ptr, m.row_lower_sum
        )
        rs = m.row_state[free]
        first = first_of_runs(rs)
        want_states = rs[first][np.argsort(key[rs[first]], kind="stable")]
        np.testing.assert_array_equal(states, want_states)
        want_position = np.concatenate([np.flatnonzero(rs == s) for s in want_states])
        np.testing.assert_array_equal(position, want_position)
        np.testing.assert_array_equal(rows, free[want_position])
        np.testing.assert_array_equal(np.diff(state_rows), [np.sum(rs == s) for s in states])
        np.testing.assert_array_equal(np.diff(row_ptr), m.row_ptr[rows + 1] - m.row_ptr[rows])
        np.testing.assert_array_equal(remaining, 1.0 - m.row_lower_sum[rows])
        assert state_rows[0] == 0 and row_ptr[0] == 0
