"""One MuJoCo hop of the SLIP hopper, then the learned controller aiming at a cell.

Loads the hopper (physical values read back by name from the shipped MJCF), simulates one hop
of the steady gait without perturbations, then one with the terrain force field, landing
noise and the stance thrust; finally asks the learned leg-angle controller for the touchdown
angles that land 2 m east and 1 m north, and checks where the hop lands.

    python examples/01_one_hop.py
"""

import numpy as np

from hopper_sim import (
    HopperModel,
    LegAngleController,
    TerrainField,
    load_checkpoint,
    sample_model_noise,
    simulate_hop,
)


def main() -> None:
    model = HopperModel.load()
    p = model.params
    print(f"hopper: m = {p.mass} kg, l0 = {p.rest_length} m, k = {p.stiffness} N/m")

    ckpt = load_checkpoint(expected_param_hash=model.param_hash())
    controller = LegAngleController.from_checkpoint(ckpt)
    steady = controller.steady  # the interstitial state of steady hopping (v_des)
    vel = steady.velocity
    pure = simulate_hop(model, np.zeros(2), vel, steady.alpha, 0.0).raise_for_status()
    print(
        f"steady hop: lands at {pure.next_pos.round(4)} m, next velocity {pure.next_vel.round(4)}"
    )

    terrain = TerrainField.for_model(model, seed=3)
    nu = sample_model_noise(model, np.random.default_rng(0), 1)[0]
    bumped = simulate_hop(
        model, np.zeros(2), vel, steady.alpha, 0.0, terrain=terrain, noise=nu, thrust=True
    ).raise_for_status()
    shift = bumped.next_pos - pure.next_pos
    print(f"with terrain, noise {nu.round(3)} m and thrust: landing moved by {shift.round(3)} m")

    target = np.array([2.0, 1.0])
    decision = controller.decide(np.zeros(2), vel, [0], target[None, :], 0)
    hop = simulate_hop(model, np.zeros(2), vel, decision.alpha, decision.beta).raise_for_status()
    miss = np.linalg.norm(hop.next_pos - target)
    print(
        f"controller: alpha = {decision.alpha:.3f} rad, beta = {decision.beta:.3f} rad; "
        f"lands {miss:.3f} m from the target {target} m"
    )
    assert miss < 0.3, miss


if __name__ == "__main__":
    main()
