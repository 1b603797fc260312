import numpy as np
import pytest

from planner.errors import SpecificationError
from planner.imdp import IMDP, graph


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
