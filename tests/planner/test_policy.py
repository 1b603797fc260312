from __future__ import annotations

import numpy as np
import pytest

from planner.errors import PolicyError
from planner.modes import Phase, Source
from planner.policy import PhasePlan, SwitchingConfig, SwitchingPolicy
from planner.qlearning import GreedyQ, QLearningConfig, RobustQLearner
from planner.tour import ComponentTour

N, K = 30, 8


def _plan(rng: np.random.Generator, density: float) -> PhasePlan:
    allowed = rng.random((N, K)) < density
    allowed[np.arange(N), rng.integers(0, K, N)] = True
    ltl = np.array([rng.choice(np.flatnonzero(row)) for row in allowed])
    ltl[rng.random(N) < 0.1] = -1
    return PhasePlan(allowed, ltl)


def _policy(seed: int = 0, **settings) -> tuple[SwitchingPolicy, PhasePlan, PhasePlan]:
    rng = np.random.default_rng(seed)
    learner = RobustQLearner(N, K, N, settings=QLearningConfig(epsilon=0.3))
    learner.q[:] = rng.normal(size=(N, K))
    policy = SwitchingPolicy(SwitchingConfig(**settings), learner)
    explore, goal = _plan(rng, 0.6), _plan(rng, 0.3)
    policy.resynthesise(explore, goal, rng.uniform(0.0, 1.0, N))
    return policy, explore, goal


def test_only_allowed_actions_of_the_current_phase():
    policy, explore, goal = _policy(p_sat=0.9)
    rng = np.random.default_rng(1)
    phases = set()
    for state in rng.integers(0, N, 600):
        d = policy.decide(int(state), rng)
        plan = goal if d.phase == Phase.GOAL_REACHING else explore
        assert plan.allowed[state, d.action]
        assert d.allowed == tuple(np.flatnonzero(plan.allowed[state]).tolist())
        if d.source == Source.LTL:
            assert d.action == plan.ltl_action[state]
        phases.add(d.phase)
    assert phases == {Phase.EXPLORATION, Phase.GOAL_REACHING}


def test_switch_when_worst_case_probability_exceeds_p_sat():
    policy, explore, goal = _policy(p_sat=0.65)
    sat = np.full(N, 0.3)
    sat[[2, 3]] = [0.65, 0.7]
    policy.resynthesise(explore, goal, sat)
    rng = np.random.default_rng(0)
    assert policy.decide(0, rng).phase == Phase.EXPLORATION
    assert policy.decide(2, rng).phase == Phase.EXPLORATION  # equal is not "exceeds"
    d = policy.decide(3, rng)
    assert d.phase == Phase.GOAL_REACHING and d.switched and d.phase_step == 0
    assert policy.switch_step == 2 and policy.switch_probability == pytest.approx(0.7)
    d = policy.decide(0, rng)  # stays in goal reaching where the probability is low again
    assert d.phase == Phase.GOAL_REACHING and not d.switched and d.phase_step == 1
    policy.reset()
    assert policy.phase == Phase.EXPLORATION and policy.switch_step is None


def _without(plan: PhasePlan, states: list[int]) -> PhasePlan:
    allowed = plan.allowed.copy()
    allowed[states] = False
    return PhasePlan(allowed, np.where(np.isin(np.arange(N), states), -1, plan.ltl_action))


def test_goal_plan_of_the_switch_is_kept_until_the_state_leaves_it():
    policy, explore, goal = _policy(p_sat=0.65)
    sat = np.full(N, 0.9)
    policy.resynthesise(explore, goal, sat)
    rng = np.random.default_rng(0)
    assert policy.decide(3, rng).switched and policy.switch_probability == pytest.approx(0.9)
    # a re-synthesis that drops state 5 from the goal plan does not replace the kept plan
    later = _without(goal, [5])
    policy.resynthesise(explore, later, np.full(N, 0.2))
    d = policy.decide(5, rng)
    assert d.phase == Phase.GOAL_REACHING and not d.switched and goal.allowed[5, d.action]
    assert d.sat_probability == pytest.approx(0.9)  # under the synthesis of the switch
    assert policy.left_plan_step is None
    # a state outside the kept plan: the run leaves it (reported), back to exploration
    policy.reset()
    policy.resynthesise(explore, _without(goal, [7]), sat)
    assert policy.decide(3, rng).phase == Phase.GOAL_REACHING
    policy.resynthesise(explore, goal, np.full(N, 0.2))
    d = policy.decide(7, rng)
    assert d.phase == Phase.EXPLORATION and d.switched and policy.left_plan_step == 1
    assert policy.switch_step == 0 and policy.switches == 1
    # from there the latest synthesis may switch again; the first switch stays reported
    policy.resynthesise(explore, goal, sat)
    d = policy.decide(7, rng)
    assert d.phase == Phase.GOAL_REACHING and d.switched and policy.switches == 2
    assert policy.switch_step == 0 and policy.left_plan_step == 1


def test_replanning_goal_reaching_returns_to_exploration():
    policy, explore, goal = _policy(p_sat=0.65, keep_goal_plan=False)
    sat = np.full(N, 0.9)
    policy.resynthesise(explore, goal, sat)
    rng = np.random.default_rng(0)
    assert policy.decide(3, rng).phase == Phase.GOAL_REACHING
    policy.resynthesise(explore, _without(goal, [5]), np.full(N, 0.2))
    d = policy.decide(5, rng)
    assert d.phase == Phase.EXPLORATION and d.switched and policy.left_plan_step is None


def test_rl_probabilities_follow_the_settings():
    policy, explore, goal = _policy(p_rl_explore=0.0, c=0.8, eps=0.01, p_sat=0.5)
    ltl_ok = np.flatnonzero((explore.ltl_action >= 0) & (goal.ltl_action >= 0))
    policy.resynthesise(explore, goal, np.zeros(N))
    rng = np.random.default_rng(3)
    ds = [policy.decide(int(s), rng) for s in rng.choice(ltl_ok, 300)]
    assert all(d.source == Source.LTL for d in ds)  # P_RL,ee = 0
    policy.resynthesise(explore, goal, np.ones(N))
    policy.reset()
    ds = [policy.decide(int(s), rng) for s in rng.choice(ltl_ok, 400)]
    m = np.arange(400)
    np.testing.assert_allclose([d.p_rl for d in ds], 0.8 * np.exp(-0.01 * m))
    rl_first = np.mean([d.source == Source.RL for d in ds[:100]])
    rl_last = np.mean([d.source == Source.RL for d in ds[300:]])
    assert 0.36 < rl_first < 0.66 and rl_last < 0.12  # expected 0.51 and 0.03


def test_missing_ltl_action_falls_back_to_rl():
    policy, explore, _ = _policy(p_rl_explore=0.0, p_sat=1.0)
    state = int(np.flatnonzero(explore.ltl_action == -1)[0])
    d = policy.decide(state, np.random.default_rng(0))
    assert d.source == Source.RL and explore.allowed[state, d.action]


def test_same_seed_same_decisions():
    runs = []
    for _ in range(2):
        policy, _, _ = _policy(seed=5, p_sat=0.8)
        rng = np.random.default_rng(11)
        runs.append([policy.decide(int(s), rng) for s in rng.integers(0, N, 200)])
    assert runs[0] == runs[1]


def test_bad_plans_and_calls():
    allowed = np.zeros((3, 2), dtype=bool)
    allowed[:, 0] = True
    with pytest.raises(PolicyError, match="state 1: LTL action 1"):
        PhasePlan(allowed, np.array([0, 1, -1]))
    with pytest.raises(PolicyError, match="p_rl_explore"):
        SwitchingConfig(p_rl_explore=1.5)
    masked = PhasePlan.masked(allowed, np.array([0, 1, 7]))
    assert masked.ltl_action.tolist() == [0, -1, -1]
    policy = SwitchingPolicy(SwitchingConfig(), RobustQLearner(3, 2, 3))
    with pytest.raises(PolicyError, match="before resynthesise"):
        policy.decide(0, np.random.default_rng(0))
    with pytest.raises(PolicyError, match="no RL actor"):
        SwitchingPolicy(SwitchingConfig()).resynthesise(
            PhasePlan(allowed, np.zeros(3, dtype=int)),
            PhasePlan(allowed, np.zeros(3, dtype=int)),
            np.zeros(3),
        )
    plan = PhasePlan(allowed, np.array([0, 0, 0]))
    empty = PhasePlan(np.zeros((3, 2), dtype=bool), np.full(3, -1))
    policy.resynthesise(empty, plan, np.zeros(3))
    with pytest.raises(PolicyError, match="state 1 has no allowed action"):
        policy.decide(1, np.random.default_rng(0))


def test_rl_ties_take_the_ltl_action():
    # a reward that is indifferent (all Q equal, e.g. robust Q-values 0 under wide intervals)
    # must not pull the RL action to the lowest-index action
    rng = np.random.default_rng(0)
    explore, goal = _plan(rng, 0.6), _plan(rng, 0.3)
    policy = SwitchingPolicy(SwitchingConfig(p_rl_explore=1.0), GreedyQ(np.zeros((N, K))))
    policy.resynthesise(explore, goal, np.zeros(N))
    for s in np.flatnonzero(explore.ltl_action >= 0):
        d = policy.decide(int(s), rng)
        assert d.source == Source.RL and d.action == explore.ltl_action[s]


def test_exploration_follows_the_tour_inside_its_component_and_remembers_visits():
    from planner.imdp.graph import EndComponent
    from tests.planner.test_tour import _grid

    model = _grid()  # 25 states, 4 actions, deterministic moves
    n = model.n_states
    comp = EndComponent(np.arange(n), np.arange(model.n_rows))
    tour = ComponentTour(
        model, comp, model.enabled, np.arange(n), np.zeros(n), np.zeros(n), "coverage"
    )
    static = PhasePlan(model.enabled.copy(), np.argmax(model.enabled, axis=1))  # lowest index
    policy = SwitchingPolicy(SwitchingConfig(p_rl_explore=0.0), GreedyQ(np.zeros((n, 4))))
    policy.resynthesise(static, static, np.zeros(n), tour=tour)
    rng = np.random.default_rng(0)
    s, seen = 12, {12}
    for _ in range(40):
        d = policy.decide(s, rng)
        assert d.source == Source.LTL and model.enabled[s, d.action]
        s = int(model.successor[model.row_ptr[model.row_index[s, d.action]]])
        seen.add(s)
    assert seen == set(range(n))
    assert policy.last_visit is not None and (policy.last_visit >= 0).sum() == n
    policy.replan_reward(GreedyQ(np.ones((n, 4))))
    assert policy.exploration is not None and policy.exploration.tour is tour
    policy.reset()
    assert (policy.last_visit == -1).all()
    # without the tour the static plan shuttles between two states
    plain = SwitchingPolicy(SwitchingConfig(p_rl_explore=0.0), GreedyQ(np.zeros((n, 4))))
    plain.resynthesise(static, static, np.zeros(n))
    s, seen = 12, {12}
    for _ in range(40):
        a = plain.decide(s, rng).action
        s = int(model.successor[model.row_ptr[model.row_index[s, a]]])
        seen.add(s)
    assert len(seen) < n
