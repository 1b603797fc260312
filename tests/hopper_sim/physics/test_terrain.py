"""Terrain force field: seeded, RBF-like statistics, input checks."""

from __future__ import annotations

import numpy as np
import pytest

from hopper_sim.physics.terrain import TerrainError, TerrainField


def test_same_seed_same_field_other_seed_other_field():
    pts = np.random.default_rng(0).uniform(0, 15, (50, 2))
    a = TerrainField.from_seed(3, 150.0, 2.0).force(pts)
    b = TerrainField.from_seed(3, 150.0, 2.0).force(pts)
    c = TerrainField.from_seed(4, 150.0, 2.0).force(pts)
    assert a.shape == (50, 2)
    assert np.array_equal(a, b) and not np.allclose(a, c)


def test_prior_statistics_match_the_rbf_kernel():
    """Across seeds: per-axis std = amplitude, correlation exp(-d^2 / (2 ell^2))."""
    amp, ell = 100.0, 2.0
    pts = np.array([[1.0, 1.0], [1.0 + ell, 1.0]])
    f = np.array([TerrainField.from_seed(s, amp, ell).force(pts) for s in range(400)])
    assert f[:, 0, :].std(axis=0) == pytest.approx([amp, amp], rel=0.12)
    corr = np.corrcoef(f[:, 0, 0], f[:, 1, 0])[0, 1]
    assert corr == pytest.approx(np.exp(-0.5), abs=0.12)
    assert abs(np.corrcoef(f[:, 0, 0], f[:, 0, 1])[0, 1]) < 0.15  # axes independent


def test_single_point_and_bad_inputs():
    t = TerrainField.from_seed(1, 50.0, 1.0, features=16)
    assert t.force(np.array([0.5, 0.5])).shape == (2,)
    with pytest.raises(TerrainError, match="shape"):
        t.force(np.zeros((3, 3)))
    with pytest.raises(TerrainError, match="seed"):
        TerrainField.from_seed(-1, 50.0, 1.0)
    with pytest.raises(TerrainError, match="length scale"):
        TerrainField.from_seed(1, 50.0, 0.0)
