import numpy as np
import pytest

from planner.errors import SpecificationError
from planner.imdp import IMDP, graph, minimal
from planner.modes import Adversary
from tests.planner.imdp.reference import random_imdp


def model(n, rows, labels=None):
    """rows: list of (state, action, [(succ, lo, up), ...])."""
    s, a, t, lo, up = [], [], [], [], []
    for st, act, entries in rows:
        for succ, l_, u_ in entries:
            s.append(st)
            a.append(act)
            t.append(succ)
            lo.append(l_)
            up.append(u_)
    return IMDP(n, s, a, t, lo, up, labels=labels)


def mask(n, idx):
    m = np.zeros(n, dtype=bool)
    m[list(idx)] = True
    return m


def as_sets(ecs, m):
    return sorted(
        (
            tuple(ec.states.tolist()),
            tuple((int(m.row_state[r]), int(m.row_action[r])) for r in ec.rows),
        )
        for ec in ecs
    )


def test_mec_decomposition_needs_several_rounds():
    # s0 -> s1; s1 -a-> s0, s1 -b-> {s2, s3}; s2 -> s1; s3 absorbing
    m = model(
        4,
        [
            (0, 0, [(1, 1, 1)]),
            (1, 0, [(0, 1, 1)]),
            (1, 1, [(2, 0.5, 0.5), (3, 0.5, 0.5)]),
            (2, 0, [(1, 1, 1)]),
            (3, 0, [(3, 1, 1)]),
        ],
    )
    # round 1: SCC {0,1,2} loses s1.b; round 2: s2 is cut off and loses its only row
    got = as_sets(graph.maximal_end_components(m), m)
    assert got == [((0, 1), ((0, 0), (1, 0))), ((3,), ((3, 0),))]


def _mec_reference(m, rows, states, optimistic):
    """Maximal end components by the textbook fixed point, on networkx's strongly connected
    components: keep the rows that stay in their state's component (every ``upper > 0``
    successor inside; optimistic: no ``lower > 0`` successor outside and the ``upper``
    bounds inside summing to at least 1, exactly), drop the states left without one, and
    decompose again until nothing changes."""
    from fractions import Fraction

    import networkx as nx

    rows, alive = rows.copy(), states.copy()
    while True:
        g = nx.DiGraph()
        g.add_nodes_from(np.flatnonzero(alive).tolist())
        for r in np.flatnonzero(rows & alive[m.row_state]):
            e = np.arange(m.row_ptr[r], m.row_ptr[r + 1])
            for t in m.successor[e][m.upper[e] > 0]:
                if alive[t]:
                    g.add_edge(int(m.row_state[r]), int(t))
        label = {s: i for i, c in enumerate(nx.strongly_connected_components(g)) for s in c}
        changed = False
        for r in np.flatnonzero(rows & alive[m.row_state]):
            s, e = int(m.row_state[r]), np.arange(m.row_ptr[r], m.row_ptr[r + 1])
            inside = [bool(alive[t]) and label[int(t)] == label[s] for t in m.successor[e]]
            if optimistic:
                ok = not any(lo > 0 and not i for lo, i in zip(m.lower[e], inside, strict=True))
                ok = (
                    ok
                    and sum(
                        (Fraction(u) for u, i in zip(m.upper[e], inside, strict=True) if i),
                        Fraction(0),
                    )
                    >= 1
                )
            else:
                ok = all(i for u, i in zip(m.upper[e], inside, strict=True) if u > 0)
            if not ok:
                rows[r] = False
                changed = True
        has_row = np.zeros(m.n_states, dtype=bool)
        has_row[m.row_state[rows]] = True
        lost = alive & ~has_row
        if lost.any():
            alive &= ~lost
            changed = True
        if not changed:
            break
    kept = rows & alive[m.row_state]
    comps = {}
    for s in np.flatnonzero(alive):
        comps.setdefault(label[int(s)], set()).add(int(s))
    return sorted(
        (
            tuple(sorted(c)),
            tuple(
                (int(m.row_state[r]), int(m.row_action[r]))
                for r in np.flatnonzero(kept)
                if int(m.row_state[r]) in c
            ),
        )
        for c in comps.values()
    )


@pytest.mark.parametrize("optimistic", [False, True])
def test_end_components_equal_the_textbook_fixed_point(optimistic):
    """The compiled decomposition (one component refined at a time, losses cascaded through
    the incoming entries, each component's graph built in one pass) against the textbook
    fixed point on networkx, on random models restricted to random rows and states."""
    rng = np.random.default_rng(7 + optimistic)
    mode = Adversary.OPTIMISTIC if optimistic else Adversary.PESSIMISTIC
    larger = 0
    for _ in range(120):
        # few states, many actions of few successors: components of up to a dozen states
        m = random_imdp(rng, int(rng.integers(5, 14)), 6, 3, bool(rng.integers(2)))
        rows = rng.random(m.n_rows) < 0.9
        states = rng.random(m.n_states) < 0.9
        got = as_sets(graph.maximal_end_components(m, rows=rows, states=states, mode=mode), m)
        assert got == _mec_reference(m, rows, states, optimistic)
        larger += sum(len(c) > 2 for c, _ in got)
    assert larger > 20


def test_zero_lower_bound_lets_adversary_cut_the_cycle():
    # s0 -> {s0 [0,1], s1 [0,1]}; s1 (good) -> s0
    m = model(2, [(0, 0, [(0, 0, 1), (1, 0, 1)]), (1, 0, [(0, 1, 1)])])
    good, bad = mask(2, [1]), mask(2, [])
    assert as_sets(graph.maximal_end_components(m), m) == [((0, 1), ((0, 0), (1, 0)))]
    assert graph.accepting_end_components(m, good, bad) == []
    assert len(graph.optimistic_accepting_end_components(m, good, bad)) == 1
    # a positive lower bound towards s1 makes it robustly accepting
    m2 = model(2, [(0, 0, [(0, 0, 0.9), (1, 0.1, 1)]), (1, 0, [(0, 1, 1)])])
    assert as_sets(graph.accepting_end_components(m2, good, bad), m2) == [
        ((0, 1), ((0, 0), (1, 0)))
    ]


def test_interval_constraint_forces_mass():
    # no lower bound is positive, but the upper bounds outside {1} sum to 0.6 < 1
    m = model(3, [(0, 0, [(0, 0, 0.6), (1, 0, 1)]), (1, 0, [(1, 1, 1)]), (2, 0, [(2, 1, 1)])])
    assert graph.forced_into(m, mask(3, [1])).tolist() == [True, True, False]
    assert graph.forced_into(m, mask(3, [0])).tolist() == [False, False, False]
    sure, choice = graph.robust_almost_sure_reach(m, mask(3, [1]))
    assert sure.tolist() == [True, True, False]
    assert choice[0] == 0


def test_rabin_pair_needs_bad_states_removed_first():
    # s0 (B) -> s1; s1 (G) -a-> s0, -b-> s2; s2 -> s1
    m = model(
        3,
        [(0, 0, [(1, 1, 1)]), (1, 0, [(0, 1, 1)]), (1, 1, [(2, 1, 1)]), (2, 0, [(1, 1, 1)])],
    )
    good, bad = mask(3, [1]), mask(3, [0])
    assert len(graph.maximal_end_components(m)) == 1  # the whole model
    assert as_sets(graph.accepting_end_components(m, good, bad), m) == [((1, 2), ((1, 1), (2, 0)))]


def test_prune_removes_actions_then_states_iteratively():
    # s3 is removed; s2 only goes to s3; s1 -a-> s2 (removed), -b-> s1; s0 -> s1 or s2
    m = model(
        4,
        [
            (0, 0, [(1, 1, 1)]),
            (0, 1, [(1, 0, 0.5), (2, 0.5, 1)]),
            (1, 0, [(2, 1, 1)]),
            (1, 1, [(1, 1, 1)]),
            (2, 0, [(3, 0, 0.1), (2, 0.9, 1)]),
            (3, 0, [(3, 1, 1)]),
        ],
    )
    sub = graph.prune(m, mask(4, [3]))
    assert sub.states.tolist() == [True, True, False, False]
    assert sub.actions.tolist() == [[True, False], [False, True], [False, False], [False, False]]


def test_possible_and_positive_reach():
    # s0 -> s1 [0, 1] or s2 [0, 1]; s1 target; s2 sink
    m = model(3, [(0, 0, [(1, 0, 1), (2, 0, 1)]), (1, 0, [(1, 1, 1)]), (2, 0, [(2, 1, 1)])])
    tgt = mask(3, [1])
    assert graph.possible_reach(m, tgt).tolist() == [True, True, False]
    pos, _ = graph.robust_positive_reach(m, tgt)
    assert pos.tolist() == [False, True, False]
    assert graph.possible_reach(m, tgt, avoid=mask(3, [0])).tolist() == [False, True, False]


def test_graph_argument_errors():
    m = model(1, [(0, 0, [(0, 1, 1)])])
    with pytest.raises(SpecificationError, match="mode"):
        graph.maximal_end_components(m, mode="robust")
    with pytest.raises(SpecificationError, match="row mask"):
        graph.stays_in(m, np.ones(1, bool)) & graph._all_rows(m, np.ones(3, bool))
    with pytest.raises(SpecificationError, match="action mask"):
        graph.rows_from_actions(m, np.ones((2, 1), bool))


def test_recurrence_candidates_are_the_cycles_through_good():
    # s0 -> s1 (G) -> s2 -> s1; s2 -> s3 (absorbing); s4 -> s1; s5 (bad) -> s1, s1 -b-> s5
    m = model(
        6,
        [
            (0, 0, [(1, 1, 1)]),
            (1, 0, [(2, 1, 1)]),
            (1, 1, [(5, 1, 1)]),
            (2, 0, [(1, 0, 1), (3, 0, 1)]),
            (3, 0, [(3, 1, 1)]),
            (4, 0, [(1, 1, 1)]),
            (5, 0, [(1, 1, 1)]),
        ],
    )
    allowed = ~mask(6, [5])
    got = graph.recurrence_candidates(m, mask(6, [1]), allowed)
    # s0 and s4 only reach s1, s3 is only reached from it, s5 is not allowed
    assert got.tolist() == [False, True, True, False, False, False]
    # with s5 allowed and s2 not, the cycle s1 -b-> s5 -> s1 remains
    assert graph.recurrence_candidates(m, mask(6, [1]), mask(6, [1, 5])).tolist() == [
        False,
        True,
        False,
        False,
        False,
        True,
    ]
    # a good state counts itself (a path of no hops), nothing else does here
    assert graph.recurrence_candidates(m, mask(6, [0]), allowed).tolist() == [True] + [False] * 5


def _accepting_unfiltered(m, good, bad):
    """The robust Büchi / end-component alternation started from every state that avoids
    ``bad`` (no candidate filter)."""
    out, work = [], [~bad]
    while work:
        t, r = graph.robust_buchi_region(m, good, work.pop())
        for ec in graph.maximal_end_components(m, rows=r, states=t):
            ec_rows = np.zeros(m.n_rows, dtype=bool)
            ec_rows[ec.rows] = True
            t2, _ = graph.robust_buchi_region(m, good, ec.state_mask(m.n_states), ec_rows)
            if np.array_equal(t2, ec.state_mask(m.n_states)):
                out.append(ec)
            elif t2.any():
                work.append(t2)
    return out


@pytest.mark.parametrize("zero_lower", [False, True])
def test_accepting_components_equal_the_unfiltered_search(zero_lower):
    rng = np.random.default_rng(41 + zero_lower)
    filtered = 0
    for _ in range(150):
        m = random_imdp(rng, int(rng.integers(5, 30)), 3, 4, zero_lower)
        good = rng.random(m.n_states) < 0.3
        bad = rng.random(m.n_states) < 0.2
        filtered += int((~bad & ~graph.recurrence_candidates(m, good, ~bad)).sum())
        every = graph.maximal_end_components(m, states=~bad, mode=Adversary.OPTIMISTIC)
        with_good = [ec for ec in every if good[ec.states].any()]
        found = graph.optimistic_accepting_end_components(m, good, bad)
        assert as_sets(found, m) == as_sets(with_good, m)
        found = graph.accepting_end_components(m, good, bad)
        assert as_sets(found, m) == as_sets(_accepting_unfiltered(m, good, bad), m)
    assert filtered > 0  # the filter did remove states


def test_unavoidable_reach_of_a_minimising_controller():
    # 0: target. 1: one action to the target or itself ([0, 0.5] / [0.5, 1]): an opposing
    # adversary may send mass to the target, a cooperating one keeps it all at 1.
    # 2: action 0 absorbing, action 1 into 1. 3: into the target for sure.
    # 4: its self-loop's upper bound is 1 - 1e-10 (within the model's tolerance of 1),
    # so even a cooperating adversary sends 1e-10 to the target: it does not stay
    m = IMDP(
        5,
        [0, 1, 1, 2, 2, 3, 4, 4],
        [0, 0, 0, 0, 1, 0, 0, 0],
        [0, 0, 1, 2, 1, 0, 0, 4],
        [1.0, 0.0, 0.5, 1.0, 1.0, 1.0, 0.0, 0.6],
        [1.0, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0 - 1e-10],
    )
    target = np.array([True, False, False, False, False])
    for cooperative, positive in (
        (False, [True, True, False, True, True]),
        (True, [True, False, False, True, True]),
    ):
        mask, row = minimal.unavoidable_reach(m, target, cooperative=cooperative)
        assert mask.tolist() == positive
        # the states kept at 0 get the row that keeps them there
        assert row[2] == m.row_index[2, 0]
        assert (row[mask] == -1).all()
        assert (row[1] == m.row_index[1, 0]) == cooperative
    # an avoided state never joins, whatever its rows do
    mask, _ = minimal.unavoidable_reach(m, target, avoid=np.array([0, 0, 0, 1, 0], bool))
    assert not mask[3]


@pytest.mark.parametrize("seed", range(6))
def test_an_attractor_over_few_rows_is_the_one_over_the_model(seed, monkeypatch):
    """A strategy's rows are searched with their own reverse index; the states and the
    rows by which they join are those of the search on the model's index."""
    rng = np.random.default_rng(seed)
    m = random_imdp(rng, n_states=120, max_succ=5, zero_lower=bool(seed % 2))
    target = rng.random(m.n_states) < 0.05
    for fraction in (1.0, 0.3, 0.05):
        rows = rng.random(m.n_rows) < fraction
        monkeypatch.setattr(graph, "COMPACT_FRACTION", 10**9)  # the model's index
        want = graph.robust_positive_reach(m, target, rows=rows)
        monkeypatch.setattr(graph, "COMPACT_FRACTION", 0)  # the rows' own
        got = graph.robust_positive_reach(m, target, rows=rows)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        assert want[0].sum() > target.sum() or fraction < 1


def _almost_sure_textbook(m, target, avoid, region):
    """The nested fixpoint round by round: ``U`` shrinks to the robust attractor of the
    target through the rows that stay in ``U``, recomputed from scratch each round."""
    u = region & (~avoid | target)
    while True:
        stay = graph.stays_in(m, u) & u[m.row_state] & ~target[m.row_state]
        x = target & u
        while True:
            grow = x.copy()
            grow[m.row_state[stay & graph.forced_into(m, x)]] = True
            if np.array_equal(grow, x):
                break
            x = grow
        if np.array_equal(x, u):
            return u
        u = x


@pytest.mark.parametrize("zero_lower", [False, True])
def test_almost_sure_reach_is_the_nested_fixpoint(zero_lower):
    """The cascade that drops states left without staying rows changes nothing: the set is
    the round-by-round fixpoint's, and the strategy stays in it and is forced, under every
    adversary, one step closer (into states that joined earlier)."""
    rng = np.random.default_rng(7 + zero_lower)
    shrunk = 0
    for _ in range(200):
        m = random_imdp(rng, int(rng.integers(5, 40)), 3, 4, zero_lower)
        target = rng.random(m.n_states) < 0.15
        avoid = rng.random(m.n_states) < 0.15
        region = rng.random(m.n_states) < 0.9
        sure, choice = graph.robust_almost_sure_reach(m, target, avoid, region=region)
        want = _almost_sure_textbook(m, target, avoid, region)
        np.testing.assert_array_equal(sure, want)
        inner = np.flatnonzero(sure & ~target)
        assert (choice[~sure | target] == -1).all()
        rows = choice[inner]
        assert (rows >= 0).all() and (m.row_state[rows] == inner).all()
        assert graph.stays_in(m, sure)[rows].all()
        assert graph.forced_into(m, sure)[rows].all()
        shrunk += int((region & ~avoid & ~sure).sum() > 0 and (sure & ~target).any())
    assert shrunk > 20
