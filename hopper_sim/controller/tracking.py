"""Chained-hop tracking of random grid actions in MuJoCo (acceptance check of the controller).

Each hop starts where the previous one ended (position and velocity of the interstitial
state). Per hop a random action among the 8 of docs/design.md (N1, N2, E1, E2, S1, S2, W1, W2) is
requested; the targets are the centres of the cells 1 or 2 cells away from the cell the
hopper is in, on an unbounded 1 m grid (no world edge); all 8 actions are allowed, so the
backup switch may execute another one. The landing error is
``|next interstitial position - centre of the executed action's target cell|``.
A failed hop is counted and the chain restarts from the steady gait at the same position.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hopper_sim.controller.controller import LegAngleController
from hopper_sim.controller.simulator import nominal_energy
from hopper_sim.physics.hop import simulate_hop
from hopper_sim.physics.model import HopperModel
from hopper_sim.physics.noise import sample_model_noise
from hopper_sim.physics.terrain import ForceField
from planner.imdp.grid import ACTION_OFFSETS, ACTIONS


@dataclass
class ChainResult:
    """Per hop (length N): requested and executed action ids, backup used, hop succeeded,
    landing error [m] (NaN for failed hops), predicted landing error of the model [m], and
    the decision latency [s]; ``in_range``: the state lay in the network's training box."""

    requested: np.ndarray
    executed: np.ndarray
    backup: np.ndarray
    ok: np.ndarray
    error: np.ndarray
    model_error: np.ndarray
    latency: np.ndarray
    in_range: np.ndarray


def track_random_actions(
    controller: LegAngleController,
    model: HopperModel,
    n_hops: int,
    *,
    rng: np.random.Generator,
    nominal_speed: float,
    cell: float = 1.0,
    terrain: ForceField | None = None,
    noise: bool = False,
    progress: Callable[[int], None] | None = None,
) -> ChainResult:
    """Run ``n_hops`` chained hops with the stance thrust regulated to ``nominal_speed``;
    ``rng`` draws the actions (and the noise nu when ``noise``)."""
    import time

    e_nom = nominal_energy(model, nominal_speed)
    data = model.make_data()
    pos = np.array([0.5, 0.5]) * cell
    vel = controller.steady.velocity.copy()
    out = {k: np.zeros(n_hops) for k in ("error", "model_error", "latency")}
    req = np.zeros(n_hops, dtype=int)
    exe = np.zeros(n_hops, dtype=int)
    backup = np.zeros(n_hops, dtype=bool)
    ok = np.zeros(n_hops, dtype=bool)
    in_range = np.zeros(n_hops, dtype=bool)
    for k in range(n_hops):
        req[k] = int(rng.integers(len(ACTIONS)))
        targets = (np.floor(pos / cell) + 0.5 + ACTION_OFFSETS) * cell
        t0 = time.perf_counter()
        d = controller.decide(pos, vel, range(len(ACTIONS)), targets, int(req[k]))
        out["latency"][k] = time.perf_counter() - t0
        nu = sample_model_noise(model, rng, 1)[0] if noise else None
        r = simulate_hop(
            model,
            pos,
            vel,
            d.alpha,
            d.beta,
            terrain=terrain,
            noise=nu,
            thrust=True,
            nominal_energy=e_nom,
            record_path=False,
            data=data,
        )
        exe[k], backup[k], ok[k], in_range[k] = d.executed, d.backup_used, r.ok, d.in_range
        if r.ok:
            out["error"][k] = np.linalg.norm(r.next_pos - targets[d.executed])
            out["model_error"][k] = np.linalg.norm(r.next_pos - d.predicted_landing)
            pos, vel = np.asarray(r.next_pos, float), np.asarray(r.next_vel, float)
        else:
            out["error"][k] = out["model_error"][k] = np.nan
            vel = controller.steady.velocity.copy()
        if progress is not None:
            progress(1)
    return ChainResult(
        req, exe, backup, ok, out["error"], out["model_error"], out["latency"], in_range
    )
