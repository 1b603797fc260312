"""Steady gaits reproduce the exact-SLIP facts measured independently (notes/libraries.md):
1.5 m per hop at 3.5 m/s with vz -0.681 m/s and alpha 71.27 deg (apex 1.024 m); 1 m per hop
at 2.5 m/s with alpha 75.05 deg."""

from __future__ import annotations

import numpy as np
import pytest

from hopper_sim.physics.gait import GaitError, gait_for_hop_length, steady_gait
from hopper_sim.physics.hop import simulate_hop
from hopper_sim.physics.model import HopperModel


@pytest.fixture(scope="module")
def model():
    return HopperModel.load()


def test_steady_gait_matches_known_fixed_point(model):
    g = steady_gait(model, float(np.sqrt(3.5**2 - 0.681**2)), -0.681)
    assert np.rad2deg(g.alpha) == pytest.approx(71.27, abs=0.01)
    assert g.hop_length == pytest.approx(1.5, abs=2e-3)
    assert g.apex == pytest.approx(1.024, abs=1e-3)
    hop = simulate_hop(model, [0, 0], [g.speed_h, 0, g.vz], g.alpha, 0.0)
    assert hop.next_vel == pytest.approx([g.speed_h, 0.0, g.vz], abs=1e-8)


def test_gait_for_hop_length(model):
    g = gait_for_hop_length(model, 1.0, 2.5, shares=9)
    assert g.hop_length == pytest.approx(1.0, abs=1e-8)
    assert np.hypot(g.speed_h, g.vz) == pytest.approx(2.5)
    assert np.rad2deg(g.alpha) == pytest.approx(75.05, abs=0.01)


def test_unreachable_gaits_raise(model):
    with pytest.raises(GaitError, match="no steady gait"):
        steady_gait(model, 8.0, -0.05)
    with pytest.raises(GaitError, match="out of reach"):
        gait_for_hop_length(model, 3.0, 1.0, shares=5)
