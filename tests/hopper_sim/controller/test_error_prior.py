"""The landing-error prior derived from the hopper, its controller and the scene."""

import numpy as np
import pytest

from hopper_sim.controller import error_prior as ep
from hopper_sim.navigation.environment import HopperGridEnv
from planner.imdp.grid import ACTION_OFFSETS
from planner.scenario import load_scenario


@pytest.fixture(scope="module")
def env():
    return HopperGridEnv(load_scenario("a"))


def test_shipped_calibration_matches_the_shipped_controller(env, monkeypatch):
    ep._CACHE.clear()

    def no_calibration(*args, **kwargs):
        raise AssertionError("the shipped calibration should have been used")

    monkeypatch.setattr(ep, "calibrate", no_calibration)
    cal = ep.load_calibration(env.model, env.controller)
    assert cal.controller_hash == ep.controller_hash(env.controller)
    assert cal.model_hash == env.model.param_hash()
    bias = np.array(cal.bias)
    # every action undershoots along its direction, two-cell hops more than one-cell hops
    along = (bias * np.sign(ACTION_OFFSETS)).sum(axis=1)
    assert (along < -0.03).all()
    assert (along[1::2] < along[0::2] - 0.05).all()


def test_prior_is_built_from_the_scene(env):
    pp = env.model.perturbation
    cal = ep.load_calibration(env.model, env.controller)
    prior = ep.error_prior(env.model, env.controller)
    assert prior.field_std == pytest.approx(pp.terrain_amplitude * cal.sensitivity)
    assert prior.lengthscale == pp.terrain_lengthscale
    assert (prior.noise.sigma, prior.noise.bound) == (pp.noise_sigma, pp.noise_bound)
    np.testing.assert_allclose(prior.bias, np.array(cal.bias))
    np.testing.assert_allclose(prior.residual, np.array(cal.spread))
    assert ep.error_prior(env.model, env.controller, terrain=False).field_std == 0.0
    assert ep.error_prior(env.model, env.controller, bias_std=0.3).bias_std == 0.3


def test_a_short_calibration_agrees_with_the_shipped_one(env):
    short = ep.calibrate(env.model, env.controller, states=6, seed=3)
    shipped = ep.load_calibration(env.model, env.controller)
    # the largest sensitivity over 6 chain states (and the steady gait) against 150 states
    assert short.sensitivity == pytest.approx(shipped.sensitivity, rel=0.1)
    assert short.sensitivity <= shipped.sensitivity * 1.1
    table = np.array(short.sensitivity_table)
    assert table.shape == (8, 2) and (table > 0).all() and table.max() <= short.sensitivity
    assert np.abs(np.array(short.bias) - np.array(shipped.bias)).max() < 0.1
    again = ep.calibrate(env.model, env.controller, states=6, seed=3)
    assert again == short  # the same seed gives the same calibration
    text = short.to_json()
    assert ep.ErrorCalibration.from_json(text) == short
