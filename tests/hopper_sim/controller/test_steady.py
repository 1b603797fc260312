from __future__ import annotations

import numpy as np
import pytest

from hopper_sim.controller.dataset import HopSamples
from hopper_sim.controller.errors import SteadyStateError
from hopper_sim.controller.hop_model import heading_frame
from hopper_sim.controller.steady import steady_state

from .standin import S0, standin_hop, steady_alpha, steady_vz


@pytest.mark.parametrize("length", [1.0, 1.5, 2.0])
def test_fixed_point_of_the_standin(length):
    st = steady_state(standin_hop, length)
    assert st.speed == pytest.approx(S0, abs=1e-6)
    assert st.alpha == pytest.approx(steady_alpha(length), abs=1e-6)
    assert st.vz == pytest.approx(steady_vz(st.alpha), abs=1e-6)
    assert st.residual < 1e-6
    # it really is a fixed point: one more hop reproduces the state
    res = standin_hop(st.velocity[None], np.array([st.alpha]), np.zeros(1))
    np.testing.assert_allclose(res.next_velocity[0], st.velocity, atol=1e-5)
    np.testing.assert_allclose(res.displacement[0], [length, 0.0], atol=1e-5)


def conservative_hop(velocity, alpha, beta):
    """Energy-conserving variant: the total speed is preserved, vz' = -0.3 - (alpha - 1.2)."""
    s, vz, _ = heading_frame(velocity)
    total = np.hypot(s, vz)
    vz_next = -0.3 - (alpha - 1.2)
    s_next = np.sqrt(total**2 - vz_next**2)
    disp = np.stack([0.5 * s * np.cos(alpha) / np.cos(np.pi / 4), 0 * s], axis=1)
    vel = np.stack([s_next, 0 * s, vz_next], axis=1)
    return HopSamples(np.ones(len(s), bool), disp, vel, np.full(len(s), "ok"))


def test_fixed_point_at_a_given_energy():
    st = steady_state(conservative_hop, 1.2, total_speed=3.0)
    assert np.hypot(st.speed, st.vz) == pytest.approx(3.0)
    assert st.vz == pytest.approx(-0.3 - (st.alpha - 1.2), abs=1e-6)
    assert 0.5 * st.speed * np.cos(st.alpha) / np.cos(np.pi / 4) == pytest.approx(1.2, abs=1e-6)


def test_failure_is_reported():
    def always_fails(velocity, alpha, beta):
        n = len(alpha)
        nan = np.full((n, 3), np.nan)
        return HopSamples(np.zeros(n, bool), nan[:, :2], nan, np.full(n, "no_touchdown"))

    with pytest.raises(SteadyStateError, match="failed"):
        steady_state(always_fails, 1.5)
    with pytest.raises(SteadyStateError, match="within 0 iterations"):
        steady_state(standin_hop, 1.5, max_iter=0)
