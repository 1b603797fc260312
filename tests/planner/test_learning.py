from __future__ import annotations

import numpy as np
import pytest

from planner.errors import PolicyError
from planner.gp import GPConfig, LandingErrorGP
from planner.imdp import IMDP
from planner.imdp.grid import GridWorld
from planner.intervals import TruncatedGaussianNoise
from planner.learning import PlannerConfig, replan_reward, resynthesise
from planner.modes import Candidates, Phase
from planner.policy import PhasePlan, SwitchingConfig, SwitchingPolicy
from planner.qlearning import GreedyQ, QLearningConfig, RobustQLearner
from planner.synthesis import frontier_strategy
from tests.planner.conftest import smooth_error
from tests.planner.imdp.helpers import until_automaton

N = 8


def _world() -> tuple[GridWorld, np.ndarray]:
    labels = np.empty((N, N), dtype=object)
    for ij in [(3, 3), (3, 4), (4, 3)]:
        labels[ij] = "Haz"
    labels[6, 6] = "Goal"
    w = np.zeros(N * N + 1)
    w[[1 * N + 5, 2 * N + 5]] = 20.0
    return GridWorld(N, N, 1.0, labels=labels), w


def _run(seed: int, learner: RobustQLearner | None = None, cap: int = 60, batch: int = 15):
    """A simulated run: landing = target centre + 0.6 * smooth_error(departure) + noise."""
    grid, w = _world()
    rng = np.random.default_rng(seed)
    noise = TruncatedGaussianNoise()
    gp = LandingErrorGP(GPConfig(bias_std=0.1))
    settings = PlannerConfig(beta=3.0, q_tolerance=1e-4)
    policy = SwitchingPolicy(SwitchingConfig(p_rl_explore=0.3, c=0.3, eps=0.02))
    pos, err, acts = np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, dtype=int)
    xy = np.array([1.5, 1.5])
    cell = int(grid.locate(xy))
    ps, r = None, None
    events = []
    for step in range(cap):
        if step % batch == 0:
            kw = {"reward": w} if learner is None else {"learner": learner}
            r = resynthesise(
                gp, grid, until_automaton(), pos, err, actions=acts, initial_cell=cell,
                current_state=ps, settings=settings, previous=r, **kw,
            )  # fmt: skip
            ps = r.product.entry_state(cell) if ps is None else ps
            policy.resynthesise(r.exploration, r.goal, r.satisfaction.values, r.fallback, r.rl)
        d = policy.decide(ps, rng)
        target = grid.target_centres[cell, d.action]
        land = target + 0.6 * smooth_error(xy[None])[0] + noise.sample(rng, 2)
        pos, err = np.vstack([pos, xy]), np.vstack([err, land - target])
        acts = np.append(acts, d.action)
        nxt = int(grid.locate(land))
        if learner is not None:
            nps = r.product.step(ps, nxt)
            learner.update(r.product.model, ps, d.action, nps, w[nxt])
        xy, cell, ps = land, nxt, r.product.step(ps, nxt)
        events.append((d.phase, d.source, d.action, cell))
        if grid.labels[cell] & {"Haz", "Goal"}:
            break
    return events, grid.labels[cell], policy, r


def test_simulated_run_reaches_the_goal_safely_and_is_reproducible():
    events, last, policy, r = _run(0)
    assert "Goal" in last and "Haz" not in last
    assert policy.switch_probability is not None and policy.switch_probability > 0.65
    assert any(e[0] == Phase.GOAL_REACHING for e in events)
    assert set(r.timings) == {"gp_fit", "abstraction", "synthesis"}
    assert r.intervals.num_states == N * N + 1
    again, *_ = _run(0)
    assert again == events


def test_unknown_reward_run_learns_rewards_of_visited_cells():
    _, w = _world()
    product_states = (N * N + 1) * until_automaton().n_states
    learner = RobustQLearner(
        product_states,
        8,
        N * N + 1,
        state_cell=np.arange(product_states) // until_automaton().n_states,
        settings=QLearningConfig(epsilon=0.2, prior_reward=1.0),
    )
    events, *_ = _run(1, learner=learner)
    visited = np.unique([e[3] for e in events])
    np.testing.assert_array_equal(learner.cell_reward()[visited], w[visited])
    assert (learner.reward_count[visited] > 0).all()


def test_prior_start_in_a_corner_falls_back():
    grid, w = _world()
    gp = LandingErrorGP()
    r = resynthesise(gp, grid, until_automaton(), np.zeros((0, 2)), np.zeros((0, 2)), reward=w)
    corner = r.product.entry_state(0)
    assert not r.exploration.allowed[corner].any()  # every hop may leave the world
    policy = SwitchingPolicy(SwitchingConfig(), r.rl)
    policy.resynthesise(r.exploration, r.goal, r.satisfaction.values, r.fallback)
    d = policy.decide(corner, np.random.default_rng(0))
    assert d.phase == Phase.FALLBACK and grid.enabled[0, d.action]
    policy.resynthesise(r.exploration, r.goal, r.satisfaction.values)
    with pytest.raises(PolicyError, match="no allowed action"):
        policy.decide(corner, np.random.default_rng(0))
    with pytest.raises(PolicyError, match="exactly one"):
        resynthesise(gp, grid, until_automaton(), np.zeros((0, 2)), np.zeros((0, 2)))
    with pytest.raises(PolicyError, match="3 hops given without their executed actions"):
        resynthesise(gp, grid, until_automaton(), np.ones((3, 2)), np.zeros((3, 2)), reward=w)
    other = LandingErrorGP(GPConfig(noise=TruncatedGaussianNoise(0.2, 0.4)))
    with pytest.raises(PolicyError, match="landing noise"):
        resynthesise(other, grid, until_automaton(), np.zeros((0, 2)), np.zeros((0, 2)), reward=w)


def test_frontier_strategy_heads_for_the_target_through_the_whole_model():
    # a line 0 - 1 - 2 - 3; action 0 moves right, action 1 moves left; 3 is the target
    s = np.repeat(np.arange(4), 2)
    a = np.tile([0, 1], 4)
    t = np.clip(np.where(a == 0, s + 1, s - 1), 0, 3)
    model = IMDP(4, s, a, t, np.ones(8), np.ones(8), n_actions=2)
    allowed = np.ones((4, 2), dtype=bool)
    allowed[2, 0] = False  # the step into the target is not safe
    target = np.array([False, False, False, True])
    strategy = frontier_strategy(model, target, allowed)
    assert strategy[:3].tolist() == [0, 0, 1]
    assert (frontier_strategy(model, np.zeros(4, bool), allowed) == -1).all()


def _prior_synthesis(candidates: str):
    """The re-synthesis before any hop, from cell 9 of :func:`_world`."""
    grid, w = _world()
    empty = np.zeros((0, 2))
    settings = PlannerConfig(beta=3.0, candidates=candidates)
    return resynthesise(LandingErrorGP(), grid, until_automaton(), empty, empty, reward=w,
                        initial_cell=9, settings=settings)  # fmt: skip


def test_exploration_candidates_setting():
    r = _prior_synthesis("nonviolating")
    assert r.mec is not None
    assert r.nonviolating.states[r.mec.component.states].all()
    r2 = _prior_synthesis("accepting")
    assert r2.mec is not None
    assert (r2.product.automaton_state[r2.mec.component.states] == 1).all()  # accepted
    with pytest.raises(PolicyError, match="candidates"):
        PlannerConfig(candidates="all")


def test_fallback_never_aims_at_a_hazard_when_another_hop_does_not():
    # under the prior every hop near the wall may end in a hazard or off the world, so these
    # states have no nonviolating action and worst case 0; the fallback must still prefer
    # the hop least likely to violate at once (the best-case-optimal choice ties across all
    # hops under such wide intervals, and in the top row the first enabled action, E1,
    # walked a run along the edge into a wall)
    labels = np.empty((N, N), dtype=object)
    for y in range(4, N):
        labels[4, y] = "Haz"  # a wall from the top edge down to y = 4
    labels[N - 1, 0] = "Goal"
    grid = GridWorld(N, N, 1.0, labels=labels)
    r = resynthesise(
        LandingErrorGP(),
        grid,
        until_automaton(),
        np.zeros((0, 2)),
        np.zeros((0, 2)),
        reward=np.zeros(grid.n_states),
    )
    pm = r.product.model
    haz = np.array(["Haz" in grid.labels[c] for c in range(grid.n_cells)] + [True])
    checked = 0
    for ps in range(pm.n_states):
        cell = int(r.product.base_state[ps])
        if cell >= grid.n_cells or haz[cell] or r.exploration.allowed[ps].any():
            continue
        if r.product.automaton_state[ps] != r.product.entry_state(cell) % r.product.n_q:
            continue
        act = int(r.fallback.ltl_action[ps])
        targets = grid.target_cell[cell, grid.enabled[cell]]
        if (~haz[targets]).any():
            assert grid.enabled[cell, act] and not haz[grid.target_cell[cell, act]], (cell, act)
            checked += 1
    assert checked >= 3


def test_default_exploration_tours_the_best_nonviolating_component():
    grid, w = _world()
    empty = np.zeros((0, 2))
    # a narrow prior (the error well known): the start's component is surely reachable
    narrow = GPConfig(bias_std=0.02, field_std=0.02, residual_std=0.02)
    r = resynthesise(LandingErrorGP(narrow), grid, until_automaton(), empty, empty, reward=w,
                     initial_cell=9, settings=PlannerConfig(beta=0.5))  # fmt: skip
    assert r.mec is not None and r.tour is not None and r.mec.probability == 1.0
    start = r.product.entry_state(9)
    comp = r.mec.component
    assert r.nonviolating.states[comp.states].all()
    assert start in comp.states  # sure to reach itself; ties go to the current component
    # the tour starts towards the rewarding cells, not along the lowest-index action
    target = r.tour.targets(start, np.full(r.product.n_states, -1))
    cells = set(r.product.base_state[np.flatnonzero(target)].tolist())
    assert cells == set(np.flatnonzero(w > 0).tolist())


def test_collected_cells_are_worth_nothing_to_the_plan():
    grid, w = _world()
    empty = np.zeros((0, 2))
    settings = PlannerConfig(beta=0.5, q_tolerance=1e-9)
    r = resynthesise(LandingErrorGP(), grid, until_automaton(), empty, empty, reward=w,
                     initial_cell=9, settings=settings)  # fmt: skip
    assert r.q.values.max() > 0  # tight intervals: the rewards count
    done = np.zeros(grid.n_states, dtype=bool)
    done[np.flatnonzero(w > 0)] = True
    q, rl, tour = replan_reward(r, reward=w, collected=done, settings=settings)
    np.testing.assert_allclose(q.values, 0.0, atol=1e-6)  # warm start from above
    assert tour is not None and not (tour.reward > 0).any()
    assert isinstance(rl, GreedyQ) and np.array_equal(rl.q, np.nan_to_num(q.q, nan=-np.inf))
    same, _, _ = replan_reward(r, reward=w, settings=settings)
    np.testing.assert_allclose(same.values, r.q.values, atol=1e-6)
    r2 = resynthesise(LandingErrorGP(), grid, until_automaton(), empty, empty, reward=w,
                      initial_cell=9, collected=done, settings=settings)  # fmt: skip
    np.testing.assert_allclose(r2.q.values, 0.0, atol=1e-9)
    assert not (r2.product.reward > 0).any()
    with pytest.raises(PolicyError, match="collected"):
        replan_reward(r, reward=w, collected=done[:3])


def test_no_reward_is_planned_after_the_run_ends():
    # rewards reachable only after the goal (in the accepting part of the product) must not
    # pull the plan into the goal: the run ends there
    grid, w = _world()
    empty = np.zeros((0, 2))
    r = resynthesise(LandingErrorGP(), grid, until_automaton(), empty, empty, reward=w,
                     initial_cell=9, settings=PlannerConfig(beta=0.5))  # fmt: skip
    p = r.product
    table = p.automaton.transitions
    sink = (table == np.arange(p.n_q)[:, None]).all(axis=1)[p.automaton_state]
    assert sink.any() and not r.q_allowed[sink].any()
    np.testing.assert_allclose(r.q.values[sink], 0.0)
    assert r.q.values[~sink].max() > 0


def test_synthesis_on_two_threads_equals_the_steps_one_after_the_other():
    from planner.imdp import analysis
    from planner.synthesis import exploration_strategy, exploration_target

    r = _prior_synthesis("nonviolating")
    product = r.product
    sat = analysis.satisfaction(product)
    np.testing.assert_array_equal(r.satisfaction.lower, sat.lower)
    np.testing.assert_array_equal(r.satisfaction.upper, sat.upper)
    np.testing.assert_array_equal(r.satisfaction.strategy, sat.strategy)
    nonviolating = analysis.nonviolating(product, analysis.failure_states(product))
    np.testing.assert_array_equal(r.nonviolating.actions, nonviolating.actions)
    start = int(product.initial)
    mec = exploration_target(product, nonviolating, Candidates.NONVIOLATING, start)
    assert r.mec is not None and mec is not None and r.mec.index == mec.index
    plan = PhasePlan.masked(nonviolating.actions, exploration_strategy(product, mec, nonviolating))
    np.testing.assert_array_equal(r.exploration.ltl_action, plan.ltl_action)
    assert list(r.synthesis_detail)[:4] == [
        "satisfaction",
        "nonviolating",
        "mec_choice",
        "steering",
    ]
    assert all(t >= 0.0 for t in r.synthesis_detail.values())
