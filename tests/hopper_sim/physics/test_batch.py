"""Batched hops: same results as the single-hop path, failures, progress, inputs."""

from __future__ import annotations

import numpy as np
import pytest

from hopper_sim.physics.batch import simulate_hops
from hopper_sim.physics.hop import STATUS_NAMES, HopInputError, simulate_hop
from hopper_sim.physics.model import HopperModel
from hopper_sim.physics.noise import sample_model_noise
from hopper_sim.physics.terrain import TerrainField


@pytest.fixture(scope="module")
def model():
    return HopperModel.load()


def mixed_hops(n, seed=3):
    rng = np.random.default_rng(seed)
    speed = rng.uniform(2.5, 3.5, n)
    heading = rng.uniform(0, 2 * np.pi, n)
    vel = np.column_stack(
        [speed * np.cos(heading), speed * np.sin(heading), rng.uniform(-2.4, -1.2, n)]
    )
    alpha = rng.uniform(1.25, 1.35, n)
    beta = rng.uniform(-0.3, 0.3, n)
    pos = rng.uniform(0.0, 10.0, (n, 2))
    # Rows that fail: a slow, shallow hop (no next interstitial state) and a hard landing.
    vel[0], alpha[0], beta[0] = [1.0, 0.0, -0.2], 0.8, 0.0
    vel[1], alpha[1], beta[1] = [0.0, 0.0, -16.0], np.pi / 2, 0.0
    return pos, vel, alpha, beta


def test_batch_equals_single_hops(model):
    pos, vel, alpha, beta = mixed_hops(12)
    terrain = TerrainField.for_model(model, 2)
    noise = sample_model_noise(model, np.random.default_rng(4), 12)
    ticks = []
    res = simulate_hops(
        model,
        vel,
        alpha,
        beta,
        pos=pos,
        terrain=terrain,
        noise=noise,
        nthread=2,
        progress=ticks.append,
    )
    assert sum(ticks) == 12
    assert res.status_name(0) == "no_touchdown" and res.status_name(1) == "ground"
    assert res.ok[2:].sum() >= 6
    for i in range(12):
        one = simulate_hop(
            model,
            pos[i],
            vel[i],
            alpha[i],
            beta[i],
            terrain=terrain,
            noise=noise[i],
            record_path=False,
        )
        assert res.status_name(i) == one.status
        assert res.touchdown_time[i] == pytest.approx(one.touchdown_time, abs=1e-12)
        if one.ok:
            assert np.abs(res.next_pos[i] - one.next_pos).max() <= 1e-9
            assert np.abs(res.next_vel[i] - one.next_vel).max() <= 1e-9
            assert res.liftoff_time[i] == pytest.approx(one.liftoff_time, abs=1e-12)
            assert res.energy_after[i] == pytest.approx(one.energy_after, rel=1e-12)
        else:
            assert np.isnan(res.next_pos[i]).all() and np.isnan(res.energy_after[i])
    assert set(res.status_names) == set(STATUS_NAMES)


def test_batch_thrust_regulates_energy(model):
    n = 6
    vel = np.tile([2.5, 0.0, -2.4], (n, 1))
    alpha = np.full(n, np.deg2rad(75.86))
    beta = np.linspace(-0.2, 0.2, n)
    pos = np.column_stack([np.linspace(0.0, 5.0, n), np.zeros(n)])
    terrain = TerrainField.for_model(model, 9)
    noise = sample_model_noise(model, np.random.default_rng(1), n)
    res = simulate_hops(
        model, vel, alpha, beta, pos=pos, terrain=terrain, noise=noise, thrust=True, nthread=1
    )
    assert res.ok.all()
    assert np.abs(res.energy_after / res.energy_before - 1.0).max() <= 1e-6
    assert np.any(res.thrust_command != 0.0)
    one = simulate_hop(
        model, pos[2], vel[2], alpha[2], beta[2], terrain=terrain, noise=noise[2], thrust=True
    )
    assert one.thrust_command == pytest.approx(res.thrust_command[2], rel=1e-6)


def test_batch_is_deterministic(model):
    pos, vel, alpha, beta = mixed_hops(8, seed=5)
    a = simulate_hops(model, vel, alpha, beta, pos=pos, nthread=2)
    b = simulate_hops(model, vel, alpha, beta, pos=pos, nthread=1, hops_per_sim=3)
    c = simulate_hops(model, vel, alpha, beta, pos=pos, nthread=2, hops_per_sim=1)
    for other in (b, c):
        assert np.array_equal(a.status, other.status)
        assert np.array_equal(a.next_pos, other.next_pos, equal_nan=True)
        assert np.array_equal(a.next_vel, other.next_vel, equal_nan=True)


def test_batch_rejects_bad_rows(model):
    vel = np.tile([3.0, 0.0, -0.5], (3, 1))
    vel[2, 2] = 0.3
    with pytest.raises(HopInputError, match="row 2"):
        simulate_hops(model, vel, np.full(3, 1.2), np.zeros(3))
    with pytest.raises(HopInputError, match="noise"):
        simulate_hops(model, vel[:2], np.full(2, 1.2), np.zeros(2), noise=np.zeros((3, 2)))
