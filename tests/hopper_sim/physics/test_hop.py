"""One hop: agreement with the exact reference, noise shift, determinism, failures."""

from __future__ import annotations

import numpy as np
import pytest

from hopper_sim.physics.hop import HopFailure, HopInputError, simulate_hop
from hopper_sim.physics.model import HopperModel
from hopper_sim.physics.noise import sample_model_noise
from hopper_sim.physics.reference import reference_hop
from hopper_sim.physics.terrain import TerrainField

GAIT = dict(pos=[0.3, 0.4], vel=[3.5, 0.0, -0.681], alpha=np.deg2rad(71.27), beta=0.0)
# A steady gait with a high apex (1.29 m): 1.77 m hops at 2.5 m/s, vz -2.4 m/s.
HIGH_GAIT = dict(pos=[0.3, 0.4], vel=[2.5, 0.0, -2.4], alpha=np.deg2rad(75.86), beta=0.0)


@pytest.fixture(scope="module")
def model():
    return HopperModel.load()


def random_hops(rng, n):
    speed = rng.uniform(2.0, 7.0, n)
    heading = rng.uniform(0, 2 * np.pi, n)
    vel = np.column_stack(
        [speed * np.cos(heading), speed * np.sin(heading), rng.uniform(-3.0, -0.2, n)]
    )
    return vel, rng.uniform(np.pi / 4, np.pi / 2, n), rng.uniform(-np.pi / 2, np.pi / 2, n)


def test_pure_hop_matches_exact_reference(model):
    vel, alpha, beta = random_hops(np.random.default_rng(7), 60)
    compared = 0
    for i in range(vel.shape[0]):
        ref = reference_hop(model.params, np.zeros(2), vel[i], alpha[i], beta[i])
        hop = simulate_hop(model, np.zeros(2), vel[i], alpha[i], beta[i], record_path=False)
        assert hop.status == ref.status
        if not ref.ok:
            continue
        compared += 1
        assert np.abs(hop.next_pos - ref.next_pos).max() <= 1e-4
        assert np.abs(hop.next_vel - ref.next_vel).max() <= 1e-4
        assert abs(hop.liftoff_time - ref.liftoff_time) <= 1e-6
        assert abs(hop.energy_after / hop.energy_before - 1.0) <= 1e-5
    assert compared >= 8


def test_nominal_gait_is_near_steady(model):
    hop = simulate_hop(model, **GAIT).raise_for_status()
    # Exact SLIP facts: 1.5 m per hop at 3.5 m/s, alpha 71.27 deg, vz -0.681 (steady gait).
    assert np.linalg.norm(hop.next_pos - GAIT["pos"]) == pytest.approx(1.5, abs=0.03)
    assert np.linalg.norm(hop.next_vel) == pytest.approx(np.linalg.norm(GAIT["vel"]), rel=1e-6)
    assert hop.touchdown_time < hop.liftoff_time < hop.touchdown_time + 0.3
    assert hop.com_path.shape[1] == 3 and hop.com_path.shape[0] == hop.com_path_time.shape[0]
    assert np.all(np.diff(hop.com_path_time) >= 0)
    assert hop.com_path[:, 2].min() > 0.8


def test_noise_moves_next_position_by_exactly_nu(model):
    nu = np.array([0.137, -0.191])
    base = simulate_hop(model, **GAIT)
    noisy = simulate_hop(model, **GAIT, noise=nu)
    assert np.abs((noisy.next_pos - base.next_pos) - nu).max() <= 1e-6
    assert noisy.flight_time == base.flight_time
    assert noisy.next_vel[2] == base.next_vel[2]


def test_beta_is_relative_to_heading(model):
    """Rotating the velocity about z rotates the hop: the hop map is rotation invariant."""
    a = simulate_hop(model, [0.0, 0.0], [3.0, 0.0, -0.5], 1.2, 0.3)
    th = 2.0
    rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    vel = np.append(rot @ [3.0, 0.0], -0.5)
    b = simulate_hop(model, [0.0, 0.0], vel, 1.2, 0.3)
    assert np.abs(rot @ a.next_pos - b.next_pos).max() <= 1e-6
    assert np.abs(rot @ a.next_vel[:2] - b.next_vel[:2]).max() <= 1e-5


def test_zero_horizontal_speed_uses_heading_plus_x(model):
    hop = simulate_hop(model, [0.0, 0.0], [0.0, 0.0, -1.0], 1.4, 0.0)
    assert hop.foot[0] > 0 and hop.foot[1] == 0.0


def test_same_seed_same_hop_bit_for_bit(model):
    def hop(seed):
        rng = np.random.default_rng(seed)
        terrain = TerrainField.for_model(model, seed)
        nu = sample_model_noise(model, rng, 1)[0]
        return simulate_hop(model, **GAIT, terrain=terrain, noise=nu, thrust=True)

    a, b, c = hop(11), hop(11), hop(12)
    assert a.ok
    assert np.array_equal(a.next_pos, b.next_pos) and np.array_equal(a.next_vel, b.next_vel)
    assert a.thrust_command == b.thrust_command
    assert np.array_equal(a.com_path, b.com_path)
    assert not np.array_equal(a.next_pos, c.next_pos)


def test_low_energy_hop_fails_with_named_reason(model):
    hop = simulate_hop(model, [0.0, 0.0], [1.0, 0.0, -0.2], 0.8, 0.0)
    assert not hop.ok and hop.status == "no_touchdown"
    assert hop.next_pos is None
    with pytest.raises(HopFailure) as info:
        hop.raise_for_status()
    assert info.value.reason == "no_touchdown"


def test_ground_failure(model):
    # Falling at 16 m/s onto a vertical leg: m v^2 / 2 + m g l0 > k l0^2 / 2.
    hop = simulate_hop(model, [0.0, 0.0], [0.0, 0.0, -16.0], np.pi / 2, 0.0)
    ref = reference_hop(model.params, np.zeros(2), [0.0, 0.0, -16.0], np.pi / 2, 0.0)
    assert hop.status == ref.status == "ground"


def test_no_liftoff_failure(model):
    """A vertical hop whose thrust damps the compression never gets back to l0."""
    vel, alpha = np.array([0.0, 0.0, -0.5]), np.pi / 2
    hop = simulate_hop(model, [0.0, 0.0], vel, alpha, 0.0, thrust_command=-2000.0)
    ref = reference_hop(model.params, np.zeros(2), vel, alpha, 0.0, thrust_command=-2000.0)
    assert hop.status == ref.status == "no_liftoff"
    assert "l0" in hop.message


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(vel=[3.0, 0.0, 0.5]), "descends"),
        (dict(alpha=2.0), "alpha"),
        (dict(vel=[3.0, np.nan, -0.5]), "vel is not finite"),
        (dict(pos=[1.0, 2.0, 3.0]), "pos must have shape"),
    ],
)
def test_bad_input_raises(model, kwargs, match):
    args = dict(GAIT) | kwargs
    with pytest.raises(HopInputError, match=match):
        simulate_hop(model, **args)


def test_thrust_returns_energy_to_nominal_under_perturbation(model):
    terrain = TerrainField.for_model(model, 5)
    for nominal in (None, 1300.0):
        hop = simulate_hop(
            model,
            **HIGH_GAIT,
            terrain=terrain,
            noise=[0.1, -0.05],
            thrust=True,
            nominal_energy=nominal,
        )
        target = hop.energy_before if nominal is None else nominal
        assert hop.ok and hop.thrust_command != 0.0
        assert hop.energy_after == pytest.approx(target, rel=1e-6)
        free = simulate_hop(model, **HIGH_GAIT, terrain=terrain, noise=[0.1, -0.05])
        assert abs(free.energy_after - target) > 1.0


def test_thrust_settles_for_a_feasible_command_when_the_target_is_out_of_reach(model):
    """Removing 400 J would end the hop (apex below l0): the regulator backs off to a command
    whose hop works, with the least energy error it found."""
    free = simulate_hop(model, **GAIT, record_path=False)
    nominal = free.energy_before - 400.0
    hop = simulate_hop(model, **GAIT, thrust=True, nominal_energy=nominal, record_path=False)
    assert hop.ok and hop.thrust_command < 0.0
    assert nominal < hop.energy_after < free.energy_before - 50.0
    harder = simulate_hop(model, **GAIT, thrust_command=hop.thrust_command * 1.5, record_path=False)
    assert not harder.ok


@pytest.mark.parametrize("command", [-150.0, 150.0])
def test_fixed_thrust_and_terrain_force_match_reference(model, command):
    class Constant:
        def force(self, xy):
            return np.tile([40.0, -25.0], (np.atleast_2d(xy).shape[0], 1))

    hop = simulate_hop(model, **GAIT, terrain=Constant(), thrust_command=command)
    ref = reference_hop(
        model.params,
        np.array(GAIT["pos"]),
        np.array(GAIT["vel"]),
        GAIT["alpha"],
        0.0,
        force=[40.0, -25.0],
        thrust_command=command,
    )
    assert hop.ok and ref.ok
    # c > 0 switches on at the first step boundary after maximal compression (measured
    # 1.7e-5 m at 300 N s/m); c < 0 switches off there, where its force is near zero.
    assert np.abs(hop.next_pos - ref.next_pos).max() <= 5e-5
    assert np.abs(hop.next_vel - ref.next_vel).max() <= 1e-4


def test_inputs_outside_the_valid_range_are_refused(model):
    from hopper_sim.physics.hop import HopInputError, max_speed

    assert max_speed(model.params) == pytest.approx(50.0)  # l0 = 1 m, dt = 1 ms
    good = dict(pos=np.zeros(2), vel=np.array([4.0, 0.0, -1.0]), alpha=1.2, beta=0.0)
    for change, match in (
        ({"vel": np.array([1e6, 0.0, 0.0])}, "horizontal speed"),
        ({"vel": np.array([4.0, 0.0, -60.0])}, r"\|vz\|"),
        ({"beta": 100.0}, r"\|beta\|"),
        ({"pos": np.array([1e300, 0.0])}, r"\|pos\|"),
    ):
        with pytest.raises(HopInputError, match=match):
            simulate_hop(model, **{**good, **change})
    with pytest.raises(HopInputError, match=r"\|noise\|"):
        simulate_hop(model, **good, noise=np.array([1e6, 0.0]))


def test_a_hop_that_falls_after_liftoff_is_not_ok(model):
    """Fast and steep: the CoM still descends when the leg reaches l0 again, so there is no
    next interstitial state (it used to come out ok with a negative flight time)."""
    from hopper_sim.physics.slip import time_to_height

    assert np.isnan(time_to_height(np.array([0.9]), np.array([-1.0]), 1.0, 9.81))[0]
    assert time_to_height(np.array([0.9]), np.array([2.0]), 1.0, 9.81)[0] > 0
    r = simulate_hop(model, np.zeros(2), np.array([7.978377, 0.0, -3.611893]), 1.516089, 0.959644)
    assert not r.ok and r.status == "no_touchdown" and r.flight_time is None


def test_implausible_results():
    from hopper_sim.physics.hop import implausible

    def one(td, lo, fl, e0, e1, passive):
        return bool(implausible(*(np.array([x]) for x in (td, lo, fl, e0, e1, passive)))[0])

    assert not one(0.05, 0.24, 0.28, 1464.8, 1464.8000015, True)
    assert one(0.12, 0.12, -0.12, 4e13, 4e13, True)  # negative flight time
    assert one(0.2, 0.1, 0.3, 100.0, 100.0, True)  # liftoff before touchdown
    assert one(0.05, 0.24, 0.28, 1464.8, 1500.0, True)  # a passive hop gained energy
    assert not one(0.05, 0.24, 0.28, 1464.8, 1500.0, False)  # thrust may add energy
    assert one(0.05, 0.24, 0.28, 1464.8, np.inf, False)
