"""Landing noise: truncated Gaussian, seeded."""

from __future__ import annotations

import numpy as np
import pytest

from hopper_sim.physics.noise import sample_noise


def test_noise_is_truncated_seeded_and_has_the_right_spread():
    a = sample_noise(np.random.default_rng(0), 4000)
    b = sample_noise(np.random.default_rng(0), 4000)
    assert a.shape == (4000, 2) and np.array_equal(a, b)
    assert np.abs(a).max() <= 0.2
    # std of N(0, 0.1) truncated at +/- 2 sigma: 0.1 * sqrt(1 - 2*2*phi(2)/(2*Phi(2)-1)).
    assert a.std() == pytest.approx(0.0880, abs=0.004)
    with pytest.raises(ValueError, match="sigma"):
        sample_noise(np.random.default_rng(0), 3, sigma=0.0)
