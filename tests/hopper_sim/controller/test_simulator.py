from __future__ import annotations

import numpy as np
import pytest

from hopper_sim.controller.simulator import nominal_energy, simulator_hop_fn
from hopper_sim.controller.steady import steady_state
from hopper_sim.physics.model import HopperModel


@pytest.fixture(scope="module")
def model():
    return HopperModel.load()


def test_thrust_restores_the_nominal_speed(model):
    hop = simulator_hop_fn(model, nominal_speed=3.5, nthread=1)
    vel = np.array([[3.2, 0.0, -0.7], [3.4, 0.0, -0.68], [3.4, 0.0, -0.68]])
    res = hop(vel, np.array([1.25, 1.24, 1.24]), np.array([0.0, -0.1, 0.1]))
    assert res.ok.all()
    speed = np.linalg.norm(res.next_velocity, axis=1)
    np.testing.assert_allclose(speed, 3.5, rtol=1e-4)
    e = model.energy(model.params.rest_length, res.next_velocity)
    np.testing.assert_allclose(e, nominal_energy(model, 3.5), rtol=1e-5)
    # beta > 0 puts the foot to the left of the heading, which pushes the hopper right;
    # mirror-symmetric in beta
    assert res.displacement[2, 1] < 0 < res.displacement[1, 1]
    np.testing.assert_allclose(res.displacement[1], res.displacement[2] * [1, -1], atol=1e-9)
    assert set(res.status) == {"ok"}


def test_steady_gait_matches_the_exact_slip(model):
    """notes/libraries.md: 1.5 m hops at 3.5 m/s have v_z = -0.681 m/s, alpha = 71.27 deg."""
    hop = simulator_hop_fn(model, nominal_speed=3.5, nthread=1)
    st = steady_state(hop, 1.5, total_speed=3.5, tol=1e-6)
    assert st.vz == pytest.approx(-0.681, abs=0.005)
    assert np.degrees(st.alpha) == pytest.approx(71.27, abs=0.1)
    assert np.hypot(st.speed, st.vz) == pytest.approx(3.5)
