"""The MuJoCo hop map (:func:`hopper_sim.physics.batch.simulate_hops`) as a :class:`BatchHopFn`.

Thrust: the navigation hops with the stance thrust on, regulated to the nominal energy
``E_nom = m V_nom^2 / 2 + m g l0`` (interstitial speed ``V_nom`` at height ``l0``), so the
training data is simulated the same way: every hop of the data ends at the nominal energy
when the thrust can reach it (with perturbations off and a start at ``V_nom`` the thrust is
idle and the hop is the ideal SLIP's).
"""

from __future__ import annotations

import numpy as np

from hopper_sim.controller.dataset import BatchHopFn, HopSamples
from hopper_sim.physics.batch import simulate_hops
from hopper_sim.physics.model import HopperModel


def nominal_energy(model: HopperModel, speed: float) -> float:
    """Energy [J] of the interstitial state (height ``l0``) with speed ``speed`` [m/s]."""
    return float(model.energy(model.params.rest_length, np.array([[speed, 0.0, 0.0]]))[0])


def simulator_hop_fn(
    model: HopperModel, *, nominal_speed: float | None, nthread: int | None = None
) -> BatchHopFn:
    """Batched MuJoCo hops from the origin; thrust regulated to ``nominal_speed`` [m/s] if
    given, else no thrust. Perturbations are off (training data of the nominal hopper)."""
    e_nom = None if nominal_speed is None else nominal_energy(model, nominal_speed)

    def hop(velocity: np.ndarray, alpha: np.ndarray, beta: np.ndarray) -> HopSamples:
        r = simulate_hops(
            model,
            velocity,
            alpha,
            beta,
            thrust=e_nom is not None,
            nominal_energy=e_nom,
            nthread=nthread,
        )
        return HopSamples(r.ok, r.next_pos, r.next_vel, np.asarray(r.status_names)[r.status])

    return hop
