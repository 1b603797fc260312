"""The support of an interval row is decided exactly: which successors every adversary must
use, which none can, and whether a set of successors can hold all the mass. Masses far
below the model's bound tolerance (1e-9) still count; before, a forced mass under the
tolerance was taken for none and certified brackets missed the exact value (a value 0
certified where every step forces ``2**-44`` into the goal)."""

from fractions import Fraction

import numpy as np

from planner.imdp import IMDP, Problem, ReachAvoid, Specification, graph, solve
from planner.modes import Adversary

D = 2.0**-44


def _model(rows, n_states, labels):
    """``rows``: per state, a list of ``(successor, lower, upper)``; absorbing states get a
    self-loop."""
    s, a, t, lo, up = [], [], [], [], []
    for x, row in rows.items():
        for j, low, high in row:
            s.append(x)
            a.append(0)
            t.append(j)
            lo.append(low)
            up.append(high)
    for x in range(n_states):
        if x not in rows:
            s += [x]
            a += [0]
            t += [x]
            lo += [1.0]
            up += [1.0]
    return IMDP(n_states, s, a, t, np.array(lo), np.array(up), labels=labels)


def _entry(m, state, succ):
    r = m.row_index[state, 0]
    e = m.row_ptr[r] + np.flatnonzero(m.successor[m.row_ptr[r] : m.row_ptr[r + 1]] == succ)[0]
    return e


def test_an_entry_forced_by_the_other_upper_bounds_gets_a_positive_lower_bound():
    # state 0 keeps at most 1 - 2**-40 and may send 2**-44 to the goal: the trap (lower
    # bound 0) gets at least 15 * 2**-44 every step
    lo = np.array([0.5, 0.0, 0.0, 1.0, 1.0])
    up = np.array([1 - 2.0**-40, D, 2.0**-40, 1.0, 1.0])
    given = (lo.copy(), up.copy())
    lo.setflags(write=False)  # the caller's arrays, sorted already: read-only is fine
    up.setflags(write=False)
    m = IMDP(3, [0, 0, 0, 1, 2], [0] * 5, [0, 1, 2, 1, 2], lo, up)
    forced = m.lower[_entry(m, 0, 2)]
    assert 0 < forced <= 15 * D and forced >= 15 * D * (1 - 1e-14)
    assert np.array_equal(lo, given[0]) and np.array_equal(up, given[1])  # inputs untouched


def test_an_entry_without_room_gets_upper_bound_zero():
    m = _model({0: [(0, 0.5, 0.5), (1, 0.5, 0.5), (2, 0.0, 0.3)]}, 3, None)
    assert m.upper[_entry(m, 0, 2)] == 0.0
    assert m.upper[_entry(m, 0, 1)] == 0.5


def test_a_row_bracketing_one_within_the_tolerance_is_made_to_bracket_it_exactly():
    third = 1 / 3  # three of them sum to less than 1 exactly
    assert Fraction(third) * 3 < 1
    m = _model({0: [(0, third, third), (1, third, third), (2, third, third)]}, 3, None)
    r = m.row_index[0, 0]
    lo, up = m.lower[m.row_ptr[r] : m.row_ptr[r + 1]], m.upper[m.row_ptr[r] : m.row_ptr[r + 1]]
    assert sum(map(Fraction, up.tolist())) >= 1 >= sum(map(Fraction, lo.tolist()))
    assert np.all(lo == third) and np.all(up - lo <= 2e-16)


def test_a_slow_forced_exit_below_the_tolerance_counts():
    # state 0 may send 2**-44 to the goal and must send the rest of what it cannot keep,
    # 15 * 2**-44, to the trap: against a goal-seeking adversary the goal gets 1/16, and
    # the trap, sought against one that avoids it, 15/16 (certified 1 and 0 before; the
    # stay of 2**40 steps is beyond the solver's certificate, so only containment is
    # asked)
    m = _model(
        {0: [(0, 0.5, 1 - 2.0**-40), (1, 0.0, D), (2, 0.0, 2.0**-40)]},
        3,
        [(), ("goal",), ("bad",)],
    )
    assert graph.robust_positive_reach(m, np.array([False, False, True]))[0][0]
    for target, avoid, strategy, exact in (
        ("goal", "bad", "minimize", 1 / 16),
        ("bad", "goal", "maximize", 15 / 16),
    ):
        spec = Specification(ReachAvoid(target, avoid), Adversary.PESSIMISTIC, strategy)
        sol = solve(Problem(m, spec))
        assert sol.lower[0] <= exact <= sol.upper[0]


def test_mass_forced_into_a_set_but_into_no_single_successor():
    # state 0 keeps at most 1 - 2**-45; each goal may take 2**-45, neither must, but
    # together they get 2**-45 every step: the goal is reached surely
    d = 2.0**-45
    m = _model(
        {0: [(0, 0.5, 1 - d), (1, 0.0, d), (2, 0.0, d)]}, 4, [(), ("goal",), ("goal",), ("bad",)]
    )
    goals = np.array([False, True, True, False])
    assert m.lower[_entry(m, 0, 1)] == 0.0  # not forced alone
    assert graph.forced_into(m, goals)[m.row_index[0, 0]]
    assert graph.robust_positive_reach(m, goals)[0][0]
    sol = solve(Problem(m, Specification(ReachAvoid("goal", "bad"))))
    assert sol.lower[0] == 1.0 and sol.converged


def test_staying_in_a_set_needs_upper_bounds_summing_to_one_exactly():
    # the upper bounds inside sum to 1 - 2**-54, which rounds to 1.0 in floating point
    inner = 0.5 - 2.0**-54
    assert 0.5 + inner == 1.0 and Fraction(0.5) + Fraction(inner) < 1
    row = [(0, 0.0, 0.5), (1, 0.0, inner), (2, 0.0, 0.5), (3, 0.0, 0.5)]
    m = _model({0: row, 1: [(0, 1.0, 1.0)]}, 4, None)
    inside = np.array([True, True, False, False])
    assert not graph.may_stay_in(m, inside)[m.row_index[0, 0]]
    comps = graph.maximal_end_components(m, mode=Adversary.OPTIMISTIC)
    assert all(0 not in c.states for c in comps)
    exact = _model({0: [(0, 0.0, 0.5), (1, 0.0, 0.5), (2, 0.0, 0.5)], 1: [(0, 1.0, 1.0)]}, 3, None)
    assert graph.may_stay_in(exact, np.array([True, True, False]))[exact.row_index[0, 0]]
    assert any(0 in c.states for c in graph.maximal_end_components(exact, mode="optimistic"))


def test_a_long_row_is_tightened_in_linear_time():
    # 20,000 successors with [0, 1/20000] each: every one is forced (the others leave
    # 1/20000); one expansion per row, one more term per entry (an expansion of the others
    # per entry took 45 s for ten such rows)
    k = 20_000
    m = _model({0: [(j, 0.0, 1.0 / k) for j in range(k)]}, k, None)
    r = m.row_index[0, 0]
    lo = m.lower[m.row_ptr[r] : m.row_ptr[r + 1]]
    assert np.all(lo > 0) and np.all(lo <= 1.0 / k)
