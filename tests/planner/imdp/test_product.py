import numpy as np
import pytest

from planner.automaton import RabinAutomaton
from planner.errors import ProductError
from planner.imdp import IMDP
from planner.imdp.analysis import (
    accepting_end_components,
    choose_mec,
    end_components,
    failure_states,
    goal_strategy,
    nonviolating,
    satisfaction,
    satisfying,
    steer_strategy,
)
from planner.imdp.grid import ACTIONS, GridWorld
from planner.imdp.product import ProductIMDP
from planner.modes import Adversary
from tests.planner.imdp.helpers import corridor_intervals, until_automaton


def corridor(n=5):
    labels = [("Haz",)] + [()] * (n - 2) + [("Goal",)]
    g = GridWorld(n, 1, labels=labels)
    return g, g.imdp_from_intervals(*corridor_intervals(g), initial=[1])


def test_product_structure_and_initial_state():
    g, m = corridor()
    p = ProductIMDP(m, until_automaton(), reward=np.arange(m.n_states, dtype=float))
    assert p.n_states == m.n_states * 3
    assert p.initial == p.state_index(1, 0)
    assert p.entry_state(4) == p.state_index(4, 1)  # starting on the goal
    assert p.step(p.state_index(1, 0), 0) == p.state_index(0, 2)  # entering the hazard
    assert p.step(p.state_index(1, 0), g.out) == p.state_index(g.out, 2)
    assert p.reward[p.state_index(3, 2)] == 3.0
    # E1 from cell 1 at q0: successors cells 1, 2, 3 at q0 with the base intervals
    r = p.model.row_index[p.state_index(1, 0), ACTIONS.index("E1")]
    sl = slice(p.model.row_ptr[r], p.model.row_ptr[r + 1])
    assert p.model.successor[sl].tolist() == [p.state_index(c, 0) for c in (1, 2, 3)]
    assert p.model.lower[sl].tolist() == [0.0, 0.8, 0.0]


@pytest.mark.parametrize("split", [False, True])
def test_the_product_model_is_the_one_its_constructor_would_build(split, monkeypatch):
    from planner.imdp import product
    from tests.planner.imdp.reference import random_imdp

    # split: the two-thread layout of large products, on a small one
    monkeypatch.setattr(product, "SPLIT_ENTRIES", 1 if split else 10**12)
    m = random_imdp(np.random.default_rng(5), n_states=60, max_succ=5, zero_lower=True)
    labels = [("Haz",) if s % 7 == 3 else ("Goal",) if s % 11 == 5 else () for s in range(60)]
    m = IMDP(
        m.n_states,
        m.row_state[m.entry_row],
        m.row_action[m.entry_row],
        m.successor,
        m.lower,
        m.upper,
        n_actions=m.n_actions,
        labels=labels,
    )
    aut = until_automaton()
    p = ProductIMDP(m, aut)
    nq, delta, letters = p.n_q, aut.transitions, p.letters
    q = np.arange(nq)
    # every model entry once per automaton state, from (s, q) to (t, delta(q, L(t)))
    src = (m.row_state[m.entry_row][:, None] * nq + q).ravel()
    act = np.repeat(m.row_action[m.entry_row], nq)
    dst = (m.successor[:, None] * nq + delta[q[None, :], letters[m.successor][:, None]]).ravel()
    want = IMDP(
        p.n_states,
        src,
        act,
        dst,
        np.repeat(m.lower, nq),
        np.repeat(m.upper, nq),
        n_actions=m.n_actions,
    )
    got = p.model
    for name in (
        "row_state",
        "row_action",
        "row_ptr",
        "successor",
        "lower",
        "upper",
        "entry_row",
        "row_lower_sum",
        "row_upper_sum",
        "state_ptr",
    ):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


def test_the_product_answers_the_automaton_questions_of_a_product_state():
    # corridor: cell 0 Haz, cell 4 Goal; automaton 0 waiting, 1 accepted, 2 rejected
    g, m = corridor()
    p = ProductIMDP(m, until_automaton())
    s = p.state_index(3, 0)
    assert (p.base_state_of(s), p.automaton_state_of(s)) == (3, 0)
    assert p.letter_of(p.state_index(4, 1)) == 1 and p.letter_of(p.state_index(0, 2)) == 2
    assert p.letter_of(s) == 0
    # the sinks (accepted, rejected) are absorbing, the waiting state is not
    assert p.absorbing.tolist() == [q != 0 for q in p.automaton_state]
    nxt = np.array([4, 0, 2, g.out])
    stepped = p.steps(np.full(4, s), nxt)
    assert stepped.tolist() == [p.step(s, int(t)) for t in nxt]
    assert stepped.tolist() == [
        p.state_index(4, 1),
        p.state_index(0, 2),
        p.state_index(2, 0),
        p.state_index(g.out, 2),
    ]


def test_failure_nonviolating_and_satisfaction():
    g, m = corridor()
    p = ProductIMDP(m, until_automaton())
    fail = failure_states(p)
    q = p.automaton_state
    assert fail[q == 2].all() and not fail[q == 1].any()
    assert not fail[p.state_index(np.arange(1, 5), 0)].any()
    sub = nonviolating(p)
    # at q0 an action is allowed iff its target is not next to the hazard cell 0
    for c in range(1, 4):
        s = p.state_index(c, 0)
        expect = [bool(g.enabled[c, a] and g.target_cell[c, a] >= 2) for a in range(8)]
        assert sub.actions[s].tolist() == expect
    sat = satisfaction(p)
    assert sat.values[p.state_index(np.arange(1, 5), 0)].tolist() == [1.0] * 4
    assert (sat.values[q == 2] == 0).all() and (sat.values[q == 1] == 1).all()
    # every accepting component lives at q1
    assert all((q[ec.states] == 1).all() for ec in accepting_end_components(p))
    # exploration candidates: end components of the nonviolating sub-model
    for ec in end_components(p, sub.actions):
        assert not fail[ec.states].any()
        assert sub.actions[p.model.row_state[ec.rows], p.model.row_action[ec.rows]].all()
    # at q0 every allowed hop may spill towards the goal (q1): no end component there
    assert end_components(p, sub.actions)
    assert not any((q[ec.states] == 0).any() for ec in end_components(p, sub.actions))
    strat = goal_strategy(p, allowed=sub.actions)
    for c in (1, 2, 3):
        a = strat[p.state_index(c, 0)]
        assert a >= 0 and sub.actions[p.state_index(c, 0), a]


def test_satisfying_submodel_threshold():
    # 0 start, 1 hazard, 2 free, 3 goal; spill .3 around every target
    g = GridWorld(4, 1, labels=[(), ("Haz",), (), ("Goal",)])
    m = g.imdp_from_intervals(*corridor_intervals(g, spill=0.3), initial=[0])
    p = ProductIMDP(m, until_automaton())
    sol = satisfaction(p)
    v = sol.values
    assert np.all(v <= satisfaction(p, Adversary.OPTIMISTIC).values + 1e-12)
    s0, s2 = p.state_index(0, 0), p.state_index(2, 0)
    # from 0: E2 aims at 2, the adversary sends .3 into the hazard and .7 to cell 2 (value 1)
    assert v[s2] == 1.0
    assert v[s0] == pytest.approx(0.7, abs=1e-12)
    assert g.enabled[0].tolist() == [False, False, True, True, False, False, False, False]
    e1, e2, w1, w2 = (ACTIONS.index(x) for x in ("E1", "E2", "W1", "W2"))
    assert sol.strategy[s0] == e2
    assert sol.q_values[p.model.row_index[s0, e1]] == pytest.approx(0.0, abs=1e-12)
    sub = satisfying(p, 0.65)
    assert sub.states[s0] and sub.actions[s0].tolist() == [a == e2 for a in range(8)]
    # W2 from 2 is worth .3 * 0 + .7 * 0.7 = 0.49 < .65; W1 aims at the hazard
    assert sub.actions[s2].tolist() == [a == e1 for a in range(8)]
    assert sol.q_values[p.model.row_index[s2, w2]] == pytest.approx(0.49, abs=1e-12)
    assert sol.q_values[p.model.row_index[s2, w1]] == pytest.approx(0.0, abs=1e-12)
    assert not satisfying(p, 0.75).states[s0]
    # the nonviolating sub-model forbids both hops from 0 (each may enter the hazard)
    assert not nonviolating(p).states[s0]


def two_loops():
    """s0 start; a0 -> loop L (s1 <-> s2, reward 1 and 3), a1 -> loop R (s3 self, reward 5)
    but a1 reaches R only w.p. in [.5, 1] (else sink s4)."""
    rows = [
        (0, 0, [(1, 1, 1)]),
        (0, 1, [(3, 0.5, 1), (4, 0, 0.5)]),
        (1, 0, [(2, 1, 1)]),
        (2, 0, [(1, 1, 1)]),
        (3, 0, [(3, 1, 1)]),
        (4, 0, [(4, 1, 1)]),
    ]
    s, a, t, lo, up = zip(
        *[(st, ac, su, l_, u_) for st, ac, es in rows for su, l_, u_ in es], strict=True
    )
    return IMDP(5, s, a, t, lo, up, initial=[0])


def trivial_automaton():
    return RabinAutomaton((), np.zeros((1, 1), dtype=int), 0, [({0}, set())])


def test_mec_choice_prefers_sure_reach_then_reward():
    m = two_loops()
    w = np.array([0.0, 1.0, 3.0, 5.0, 0.0])
    p = ProductIMDP(m, trivial_automaton(), reward=w)
    mecs = accepting_end_components(p)
    assert sorted(ec.states.tolist() for ec in mecs) == [[1, 2], [3], [4]]
    cands = [ec for ec in mecs if 4 not in ec.states]
    choice = choose_mec(p, cands)
    assert choice.component.states.tolist() == [1, 2]
    assert choice.probability == 1.0 and choice.average_reward == 2.0
    strat = steer_strategy(p, choice.component)
    assert strat[0] == 0
    # from s3 only R is reachable; among the unreachable-for-sure ones keep the best value
    choice3 = choose_mec(p, cands, state=3)
    assert choice3.component.states.tolist() == [3]
    # without the sure loop: the best worst-case probability (0.5) wins over the sink
    sink = next(ec for ec in mecs if 4 in ec.states)
    right = next(ec for ec in mecs if 3 in ec.states)
    c2 = choose_mec(p, [sink, right], state=0)
    assert c2.component is right and c2.probability == pytest.approx(0.5)


def test_product_errors():
    m = two_loops()
    with pytest.raises(ProductError, match="Goal"):
        ProductIMDP(m, until_automaton())
    with pytest.raises(ProductError, match="reward"):
        ProductIMDP(m, trivial_automaton(), reward=np.zeros(3))
    with pytest.raises(ProductError, match="no candidate"):
        choose_mec(ProductIMDP(m, trivial_automaton()), [])


def test_a_product_beyond_the_size_limits_is_refused_before_it_is_built(monkeypatch):
    import planner.imdp.product as product

    model = IMDP(2, [0, 0, 1], [0, 0, 0], [0, 1, 1], [0.4, 0.4, 1], [0.6, 0.6, 1])
    aut = RabinAutomaton((), np.zeros((3, 1), dtype=np.int64), 0, [({0}, set())])
    ProductIMDP(model, aut)  # 6 states, 9 transitions
    monkeypatch.setattr(product, "MAX_PRODUCT_STATES", 5)
    with pytest.raises(ProductError, match="6 states, more than the limit of 5"):
        ProductIMDP(model, aut)
    monkeypatch.setattr(product, "MAX_PRODUCT_STATES", 6)
    monkeypatch.setattr(product, "MAX_PRODUCT_ENTRIES", 8)
    with pytest.raises(ProductError, match="9 transitions, more than the limit of 8"):
        ProductIMDP(model, aut)
    monkeypatch.setattr(product, "MAX_PRODUCT_ENTRIES", 9)
    assert ProductIMDP(model, aut).model.n_states == 6
