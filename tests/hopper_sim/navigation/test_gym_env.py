"""HopperGridEnv as a Gymnasium environment (the optional `gym` extra; CI installs it)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="gymnasium is the optional extra hopnav[gym]")

import hopper_sim  # noqa: E402  (registers hopnav/HopperGrid-v0)
from hopper_sim.navigation.environment import EpisodeError, HopperGridEnv  # noqa: E402
from planner.imdp.grid import ACTIONS  # noqa: E402


@pytest.fixture(scope="module")
def env():
    e = HopperGridEnv("a", max_steps=4)
    yield e
    e.close()


def test_check_env_passes(env):
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the unbounded Box warnings: positions can leave
        check_env(env, skip_render_check=True)  # the world, speeds are not capped


def test_registered_on_import():
    assert hopper_sim.ENV_ID in gym.registry
    made = gym.make(hopper_sim.ENV_ID, scenario="b", max_steps=3)
    try:
        assert made.unwrapped.scenario.name == "b" and made.unwrapped.max_steps == 3
        obs, _ = made.reset(seed=0)
        assert obs["cell"] == made.unwrapped.scenario.start_cell
    finally:
        made.close()


def test_spaces_and_action_mask(env):
    assert env.action_space == gym.spaces.Discrete(len(ACTIONS))
    obs, info = env.reset(seed=3)
    assert obs in env.observation_space
    mask = info["action_mask"]
    assert mask.dtype == np.int8 and mask.shape == (len(ACTIONS),)
    assert (mask == env.grid.enabled[obs["cell"]]).all()
    # from a corner cell the westward and southward hops leave the world
    obs, info = env.reset(options={"start": (0.5, 0.5)})
    assert obs["cell"] == 0
    names = [a for a, m in zip(ACTIONS, info["action_mask"], strict=True) if m]
    assert names == ["N1", "N2", "E1", "E2"]


def test_truncation_at_the_step_cap_and_same_seed_same_episode(env):
    def episode(seed):
        obs, info = env.reset(seed=seed)
        trace, done = [], False
        while not done:
            action = int(np.flatnonzero(info["action_mask"])[0])
            obs, reward, terminated, truncated, info = env.step(action)
            trace.append((obs["pos"].copy(), reward, terminated, truncated))
            done = terminated or truncated
        return trace

    first = episode(5)
    assert len(first) <= env.max_steps
    if not first[-1][2]:  # not terminated: truncated exactly at the cap
        assert len(first) == env.max_steps and first[-1][3]
    assert not any(t[3] for t in first[:-1])
    again = episode(5)
    assert all(
        np.array_equal(a[0], b[0]) and a[1:] == b[1:] for a, b in zip(first, again, strict=True)
    )
    with pytest.raises(EpisodeError):
        env.step(0)  # the episode is over


def test_masked_action_aims_outside_and_reset_validates(env):
    env.reset(seed=1, options={"start": (0.5, 7.5)})
    obs, _, terminated, truncated, info = env.step(ACTIONS.index("W1"))
    step = info["step"]
    assert step.target[0] < 0.0  # the target centre lies west of the world
    assert step.decision.executed == ACTIONS.index("W1") and step.hop.ok  # no backup needed
    assert obs["pos"][0] < 0.0 and obs["cell"] == env.grid.out
    assert terminated and not truncated and info["outcome"] == "hazard"  # `out` is a hazard
    assert (info["action_mask"] == 0).all()
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"goal": 1})
    with pytest.raises(ValueError, match="inside"):
        env.reset(options={"start": (-1.0, 0.0)})
    env.reset()
    with pytest.raises(EpisodeError, match="not enabled and allowed"):
        env.step(ACTIONS.index("W2"), allowed=[ACTIONS.index("E1")])
