from __future__ import annotations

import io

import numpy as np
import pytest

from planner._util.sealed import seal
from planner.errors import QTableError, SpecificationError
from planner.imdp import IMDP, DiscountedReward, Problem, Specification, ValueIteration, solve
from planner.imdp.solve import ReachAvoid
from planner.qlearning import (
    SEAL_KIND,
    GreedyQ,
    QLearningConfig,
    RobustQLearner,
    greedy_action,
    robust_q_iteration,
)


def _tiny() -> IMDP:
    # s0: a0 -> s1 in [0.3, 0.6], s2 in [0.4, 0.7]; a1 -> s2 surely. s1, s2 absorbing.
    return IMDP(
        3,
        state=[0, 0, 0, 1, 2],
        action=[0, 0, 1, 0, 0],
        successor=[1, 2, 2, 1, 2],
        lower=[0.3, 0.4, 1.0, 1.0, 1.0],
        upper=[0.6, 0.7, 1.0, 1.0, 1.0],
        n_actions=2,
    )


def test_robust_q_iteration_matches_hand_computation():
    sol = robust_q_iteration(_tiny(), np.array([0.0, 10.0, 1.0]), discount=0.5, tolerance=1e-12)
    # V(s1) = 10 / 0.5 = 20, V(s2) = 1 / 0.5 = 2; landing targets W + gamma V: 20 and 2;
    # the adversary puts its largest share 0.7 on s2: 0.3 * 20 + 0.7 * 2 = 7.4
    assert sol.converged
    np.testing.assert_allclose(sol.values, [7.4, 20.0, 2.0], atol=1e-9)
    np.testing.assert_allclose(sol.q[0], [7.4, 2.0], atol=1e-9)
    assert np.isnan(sol.q[1, 1])
    allowed = np.array([[False, True], [True, False], [True, False]])
    sol = robust_q_iteration(_tiny(), np.array([0.0, 10.0, 1.0]), discount=0.5, allowed=allowed)
    assert sol.values[0] == pytest.approx(2.0, abs=1e-7)


def _random_model(rng: np.random.Generator, n: int = 12, k: int = 3) -> IMDP:
    rows = []
    for s in range(n):
        for a in range(k):
            succ = rng.choice(n, size=3, replace=False)
            p = rng.dirichlet(np.ones(3))
            lo = np.clip(p - rng.uniform(0, 0.2, 3), 0, 1)
            hi = np.clip(p + rng.uniform(0, 0.2, 3), 0, 1)
            rows += [(s, a, t, lo_, hi_) for t, lo_, hi_ in zip(succ, lo, hi, strict=True)]
    s, a, t, lo, hi = (np.array(x) for x in zip(*rows, strict=True))
    return IMDP(n, s, a, t, lo, hi, n_actions=k)


def test_robust_q_iteration_agrees_with_discounted_value_iteration_and_warm_starts():
    rng = np.random.default_rng(0)
    model = _random_model(rng)
    w = rng.normal(size=model.n_states)
    mine = robust_q_iteration(model, w, discount=0.9, tolerance=1e-10)
    ref = solve(Problem(model, Specification(DiscountedReward(w, 0.9))), ValueIteration(1e-10))
    np.testing.assert_allclose(mine.values, ref.values, atol=1e-8)
    warm = robust_q_iteration(model, w, discount=0.9, tolerance=1e-10, initial=mine.q)
    assert warm.iterations < 5 < mine.iterations
    np.testing.assert_allclose(warm.values, mine.values, atol=1e-8)


def test_robust_q_iteration_is_the_uncertified_discounted_solve_with_a_warm_start():
    rng = np.random.default_rng(4)
    model = _random_model(rng)
    w = rng.normal(size=model.n_states)
    allowed = model.enabled & (rng.random(model.enabled.shape) < 0.6)
    cold = robust_q_iteration(model, w, discount=0.9, allowed=allowed, tolerance=1e-7)
    start = np.nanmax(np.where(allowed, cold.q, np.nan), axis=1, initial=-np.inf)
    start = np.where(np.isfinite(start), start, 0.0) + 0.25
    q0 = np.where(allowed, cold.q + 0.25, np.nan)
    warm = robust_q_iteration(model, w, discount=0.9, allowed=allowed, initial=q0, tolerance=1e-7)
    spec = Specification(DiscountedReward(w, 0.9))
    ref = solve(Problem(model, spec, allowed), ValueIteration(1e-7, certified=False, initial=start))
    np.testing.assert_array_equal(warm.values, ref.values)
    assert warm.iterations == ref.iterations and warm.residual == ref.residual
    np.testing.assert_allclose(warm.values, cold.values, atol=1e-5)
    # the Q-table also values the rows outside ``allowed`` (under the same values)
    assert np.isfinite(warm.q[model.enabled & ~allowed]).all()
    with pytest.raises(SpecificationError, match="discounted reward"):
        solve(
            Problem(model, Specification(ReachAvoid([0]))),
            ValueIteration(initial=np.zeros(model.n_states)),
        )
    with pytest.raises(SpecificationError, match="initial values"):
        solve(Problem(model, spec), ValueIteration(initial=np.zeros(2)))


def _ring() -> IMDP:
    # 3 states in a ring; action 0 moves on, action 1 stays; deterministic
    s = np.repeat(np.arange(3), 2)
    a = np.tile([0, 1], 3)
    t = np.where(a == 0, (s + 1) % 3, s)
    return IMDP(3, s, a, t, np.ones(6), np.ones(6), n_actions=2)


def test_online_q_learning_converges_on_a_deterministic_ring():
    model = _ring()
    w = np.array([0.0, 1.0, 3.0])
    exact = robust_q_iteration(model, w, discount=0.8, tolerance=1e-12)
    learner = RobustQLearner(
        3, 2, 3, settings=QLearningConfig(discount=0.8, epsilon=0.3, prior_reward=10.0)
    )
    rng = np.random.default_rng(1)
    s = 0
    for _ in range(1500):
        a = learner.act(s, np.ones(2, bool), rng)
        nxt = int(model.successor[model.row_ptr[model.row_index[s, a]]])
        learner.update(model, s, a, nxt, w[nxt])
        s = nxt
    np.testing.assert_allclose(learner.cell_reward(), w)
    np.testing.assert_allclose(learner.q, exact.q, atol=1e-3)
    assert greedy_action(learner.q[1], np.ones(2, bool)) == 0  # move on to the 3-cell


def test_unvisited_cells_carry_the_prior_and_sweeps_use_learned_rewards():
    model = _ring()
    learner = RobustQLearner(3, 2, 3, settings=QLearningConfig(discount=0.5, prior_reward=2.0))
    learner.observe_reward(1, 4.0)
    learner.observe_reward(1, 2.0)
    np.testing.assert_allclose(learner.cell_reward(), [2.0, 3.0, 2.0])
    sol = learner.sweep(model, tolerance=1e-12)
    ref = robust_q_iteration(model, np.array([2.0, 3.0, 2.0]), discount=0.5, tolerance=1e-12)
    np.testing.assert_allclose(sol.q, ref.q, atol=1e-9)
    np.testing.assert_allclose(learner.q, ref.q, atol=1e-9)


def test_product_states_share_cell_rewards():
    learner = RobustQLearner(4, 2, 2, state_cell=np.array([0, 1, 0, 1]))
    learner.observe_reward(2, 7.0)
    np.testing.assert_allclose(learner.state_reward()[[0, 2]], 7.0)


def test_same_seed_same_actions():
    learner = RobustQLearner(3, 4, 3, settings=QLearningConfig(epsilon=0.5))
    learner.q[:] = np.arange(12).reshape(3, 4)
    allowed = np.array([True, False, True, True])
    runs = [
        [learner.act(1, allowed, rng) for _ in range(50)]
        for rng in (np.random.default_rng(9), np.random.default_rng(9))
    ]
    assert runs[0] == runs[1]
    assert set(runs[0]) <= {0, 2, 3} and len(set(runs[0])) > 1
    assert GreedyQ(learner.q).act(1, allowed, np.random.default_rng(0)) == 3


def test_persistence_round_trip(tmp_path):
    learner = RobustQLearner(
        4, 2, 2, state_cell=np.array([0, 1, 0, 1]), settings=QLearningConfig(epsilon=0.2)
    )
    learner.q[:] = np.random.default_rng(2).normal(size=(4, 2))
    learner.observe_reward(3, 5.0)
    path = tmp_path / "q.npz"
    learner.save(path)
    learner.save(path)  # overwrite in place
    assert [p.name for p in tmp_path.iterdir()] == ["q.npz"]
    back = RobustQLearner.load(path)
    np.testing.assert_array_equal(back.q, learner.q)
    np.testing.assert_array_equal(back.cell_reward(), learner.cell_reward())
    np.testing.assert_array_equal(back.state_cell, learner.state_cell)
    assert back.settings == learner.settings


def _write(path, **arrays):
    """A sealed file (valid digest) holding ``arrays``."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path.write_bytes(seal(SEAL_KIND, buf.getvalue()))


def _valid_arrays():
    return {
        "format": np.array("hopnav-robust-q"),
        "version": np.array(1),
        "q": np.zeros((2, 2)),
        "reward_sum": np.zeros(2),
        "reward_count": np.zeros(2, dtype=np.int64),
        "state_cell": np.arange(2),
        "settings": np.array([0.9, 0.5, 0.1, 1.0]),
    }


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"format": np.array("other")}, "format other"),
        ({"q": np.array([[0.0, np.nan], [0.0, 0.0]])}, "'q'"),
        ({"reward_count": np.array([-1, 0])}, "reward_count"),
        ({"settings": np.array([1.5, 0.5, 0.1, 1.0])}, "discount"),
        ({"state_cell": np.array([0, 5])}, "state_cell"),
    ],
)
def test_corrupt_files_raise_specific_errors(tmp_path, change, match):
    path = tmp_path / "bad.npz"
    _write(path, **(_valid_arrays() | change))
    with pytest.raises(QTableError, match=match):
        RobustQLearner.load(path)


def test_truncated_and_incomplete_files(tmp_path):
    good = tmp_path / "good.npz"
    _write(good, **_valid_arrays())
    assert RobustQLearner.load(good).q.shape == (2, 2)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:100])
    with pytest.raises(QTableError, match=r"cut\.npz"):
        RobustQLearner.load(cut)
    partial = tmp_path / "partial.npz"
    arrays = _valid_arrays()
    del arrays["q"]
    _write(partial, **arrays)
    with pytest.raises(QTableError, match=r"missing field\(s\) \['q'\]"):
        RobustQLearner.load(partial)


def test_bad_inputs():
    with pytest.raises(QTableError, match="discount"):
        QLearningConfig(discount=1.0)
    learner = RobustQLearner(3, 2, 3)
    with pytest.raises(QTableError, match="model has 3 states and 3 actions, the learner 3 and 2"):
        learner.update(_random_model(np.random.default_rng(0), 3, 3), 0, 0, 1, 0.0)
    with pytest.raises(QTableError, match="not enabled"):
        RobustQLearner(3, 2, 3).update(_tiny(), 1, 1, 1, 0.0)
    with pytest.raises(QTableError, match="no allowed action"):
        learner.act(0, np.zeros(2, bool), np.random.default_rng(0))


def test_every_single_bit_flip_is_detected(tmp_path):
    """100 random bit flips anywhere in a saved Q-table are each a QTableError."""
    learner = RobustQLearner(40, 8, 20, state_cell=np.arange(40) % 20)
    learner.q[:] = np.random.default_rng(3).normal(size=(40, 8))
    learner.observe_reward(3, 5.0)
    path = tmp_path / "q.npz"
    learner.save(path, metadata={"provenance": {"scenario": "c"}})
    data = path.read_bytes()
    rng = np.random.default_rng(20240519)
    positions = rng.integers(0, len(data), size=100)
    positions[:3] = (0, len(data) // 2, len(data) - 1)
    for pos, bit in zip(positions, rng.integers(0, 8, size=100), strict=True):
        flipped = bytearray(data)
        flipped[pos] ^= 1 << int(bit)
        path.write_bytes(bytes(flipped))
        with pytest.raises(QTableError):
            RobustQLearner.load(path)
    path.write_bytes(data)
    np.testing.assert_array_equal(RobustQLearner.load(path).q, learner.q)


def test_a_table_without_digest_is_refused(tmp_path):
    path = tmp_path / "old.npz"
    with open(path, "wb") as f:
        np.savez(f, **_valid_arrays())
    with pytest.raises(QTableError, match="without a digest"):
        RobustQLearner.load(path)


def test_greedy_ties_go_to_the_preferred_action_else_to_the_generator():
    q = np.array([1.0, 3.0, 3.0 - 1e-9, np.nan, 3.0])
    allowed = np.array([True, True, True, True, False])
    assert greedy_action(q, allowed) == 1  # deterministic without a generator
    assert greedy_action(q, allowed, prefer=2) == 2  # within the tie tolerance
    assert greedy_action(q, allowed, prefer=0) == 1  # not among the best: ignored
    picks = {greedy_action(q, allowed, rng=np.random.default_rng(s)) for s in range(40)}
    assert picks == {1, 2}  # ties drawn, never the allowed-but-worse or disallowed ones
    flat = np.zeros(5)
    assert greedy_action(flat, allowed, prefer=3) == 3
    assert GreedyQ(np.zeros((1, 5))).act(0, allowed, np.random.default_rng(0), prefer=2) == 2
    learner = RobustQLearner(1, 5, 1, settings=QLearningConfig(epsilon=0.0))
    assert learner.act(0, allowed, np.random.default_rng(0), prefer=3) == 3


def test_collected_cells_count_zero_in_the_plan_but_keep_their_learned_reward():
    model = _ring()
    learner = RobustQLearner(3, 2, 3, settings=QLearningConfig(discount=0.5, prior_reward=0.0))
    learner.observe_reward(2, 4.0)
    before = learner.sweep(model, tolerance=1e-12).values.copy()
    learner.collected[2] = True
    np.testing.assert_allclose(learner.cell_reward(), [0.0, 0.0, 4.0])
    np.testing.assert_allclose(learner.state_reward(), [0.0, 0.0, 0.0])
    after = learner.sweep(model, tolerance=1e-12).values
    assert (after < before - 1e-6).all() and np.allclose(after, 0.0)
    # a repeat landing teaches nothing about the reward, yet updates Q
    learner.collected[:] = False
    q = learner.update(model, 1, 0, 2, 0.0, learn_reward=False)
    assert learner.reward_count[2] == 1 and q > 0.0
    with pytest.raises(QTableError, match="state 7"):
        learner.update(model, 1, 0, 7, 0.0, learn_reward=False)
