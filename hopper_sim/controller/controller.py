"""World-frame leg-angle controller with the backup action switch.

The caller gives the current interstitial state (position ``(x, y)`` [m], velocity
``(v_x, v_y, v_z)`` [m/s], world frame), the allowed actions with their target positions
(world frame, typically cell centres) and the requested action. The controller

1. rotates every target displacement ``target - position`` and every desired velocity into
   the heading frame (heading ``psi = atan2(v_y, v_x)``);
2. solves the leg-angle problem for all allowed actions in one batch
   (:class:`LegAngleOptimizer`);
3. executes the requested action if its best cost is at most ``backup_threshold``;
   otherwise it executes the allowed action of least cost (the backup switch of the paper;
   that may still be the requested one if nothing is cheaper).

Desired velocity for a turning hop: the steady-hopping velocity ``v_des`` = (s*, 0, v_z*) is
defined for hopping straight ahead; for a hop towards a target in direction ``u`` (unit
horizontal vector from the position to the target) the controller asks for
``(s* u, v_z*)``, i.e. steady speed *and* a heading that points along the commanded hop.
This is the paper's ``||v - v_des||`` with ``v_des`` turned to the commanded direction: it
rewards landing ready for the next hop in that direction and penalises a change of speed.

The cost is in "metres of landing error" (``c1 = 1``); the default threshold 0.3 thus
switches when the requested action is predicted to miss by about 0.3 m, or to land far from
steady hopping (0.3 / c2 m/s), too near the region where hops fail, or without apex margin.
Measured with the shipped checkpoint (``benchmarks/bench_tracking.py``, 1,000 chained MuJoCo
hops, random requests, perturbations off, seed 0): 60 backups, all 8 actions executed,
landing error median 0.015 m, p95 0.086 m, no failed hop.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hopper_sim.controller.checkpoint import HopModelCheckpoint
from hopper_sim.controller.errors import ActionError, InputShapeError
from hopper_sim.controller.hop_model import HopNet, heading_frame, rotate_xy
from hopper_sim.controller.optimizer import (
    AngleSolution,
    CostWeights,
    LegAngleOptimizer,
    OptimizerConfig,
)
from hopper_sim.controller.steady import SteadyState

DEFAULT_BACKUP_THRESHOLD = 0.3


@dataclass(frozen=True)
class HopDecision:
    """What the controller decided for one hop.

    ``requested``/``executed``: action ids; ``alpha``, ``beta`` [rad] (beta relative to the
    heading); ``predicted_landing`` (2,) world position [m] and ``predicted_velocity`` (3,)
    world velocity [m/s] of the next interstitial state; ``cost`` of the executed action;
    ``backup_used`` whether the executed action differs from the requested one;
    ``actions``/``costs``: every evaluated action and its best cost; ``p_ok``: predicted
    success probability of the executed hop; ``in_range``: whether the interstitial state lay
    inside the network's training box (else it was clamped into it).
    """

    requested: int
    executed: int
    alpha: float
    beta: float
    predicted_landing: np.ndarray
    predicted_velocity: np.ndarray
    cost: float
    backup_used: bool
    actions: tuple[int, ...]
    costs: np.ndarray
    p_ok: float
    in_range: bool = True


class LegAngleController:
    """Targets in world coordinates -> touchdown angles, with the backup switch."""

    def __init__(
        self,
        net: HopNet,
        steady: SteadyState,
        *,
        weights: CostWeights | None = None,
        config: OptimizerConfig | None = None,
        backup_threshold: float = DEFAULT_BACKUP_THRESHOLD,
    ):
        if not backup_threshold > 0:
            raise InputShapeError(f"backup_threshold must be positive, got {backup_threshold}")
        self.optimizer = LegAngleOptimizer(
            net, weights or CostWeights(), config or OptimizerConfig()
        )
        self.steady = steady
        self.backup_threshold = float(backup_threshold)

    @classmethod
    def from_checkpoint(cls, checkpoint: HopModelCheckpoint, **kwargs) -> LegAngleController:
        """Controller for a checkpoint whose metadata holds ``"steady"`` (a
        :meth:`SteadyState.as_dict`)."""
        from hopper_sim.controller.errors import CheckpointCorruptError

        try:
            steady = SteadyState(**checkpoint.metadata["steady"])
        except (KeyError, TypeError) as exc:
            raise CheckpointCorruptError(
                f"checkpoint metadata lacks a valid 'steady' entry ({exc})"
            ) from exc
        return cls(checkpoint.net, steady, **kwargs)

    def solve_all(
        self, position: np.ndarray, velocity: np.ndarray, targets: np.ndarray
    ) -> tuple[AngleSolution, float, bool]:
        """Best angles for each of ``targets`` (K, 2) [world m]; also returns the heading
        ``psi`` [rad] of ``velocity`` and whether the state lay in the training box (a state
        outside it is clamped into it for the network)."""
        pos = np.asarray(position, dtype=np.float64)
        vel = np.asarray(velocity, dtype=np.float64)
        tg = np.asarray(targets, dtype=np.float64)
        if pos.shape != (2,) or vel.shape != (3,):
            raise InputShapeError(
                f"position must be (2,) and velocity (3,), got {pos.shape} and {vel.shape}"
            )
        if tg.ndim != 2 or tg.shape[1] != 2 or len(tg) == 0:
            raise InputShapeError(f"targets must be (K, 2) with K >= 1, got {tg.shape}")
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(vel)) and np.all(np.isfinite(tg))):
            raise InputShapeError("position, velocity and targets must be finite")
        speed, vz, psi = heading_frame(vel)
        if speed < 1e-6:
            raise InputShapeError(
                f"horizontal speed {speed:.3g} m/s: the heading (and beta) is undefined"
            )
        disp = tg - pos
        dist = np.linalg.norm(disp, axis=1, keepdims=True)
        heading = np.array([np.cos(psi), np.sin(psi)])
        unit = np.where(dist > 1e-9, disp / np.maximum(dist, 1e-9), heading)
        v_des = np.concatenate(
            [self.steady.speed * unit, np.full((len(tg), 1), self.steady.vz)], axis=1
        )
        r = self.optimizer.net.ranges
        in_range = bool(r.speed[0] <= speed <= r.speed[1] and r.vz[0] <= vz <= r.vz[1])
        sol = self.optimizer.solve(
            float(np.clip(speed, *r.speed)),
            float(np.clip(vz, *r.vz)),
            rotate_xy(disp, -psi),
            rotate_xy(v_des, -psi),
        )
        return sol, float(psi), in_range

    def decide(
        self,
        position: np.ndarray,
        velocity: np.ndarray,
        actions: Sequence[int],
        targets: np.ndarray,
        requested: int,
    ) -> HopDecision:
        """Decide the hop for ``requested`` among ``actions`` (ids, one per row of
        ``targets``, world positions [m])."""
        acts = tuple(int(a) for a in actions)
        if len(acts) == 0:
            raise ActionError("no allowed actions given")
        if len(acts) != len(np.asarray(targets)):
            raise ActionError(f"{len(acts)} actions but {len(np.asarray(targets))} targets")
        if requested not in acts:
            raise ActionError(f"requested action {requested} is not among the allowed {acts}")
        sol, psi, in_range = self.solve_all(position, velocity, targets)
        req = acts.index(requested)
        pick = req if sol.cost[req] <= self.backup_threshold else int(np.argmin(sol.cost))
        landing = np.asarray(position, dtype=np.float64) + rotate_xy(sol.displacement[pick], psi)
        return HopDecision(
            requested=int(requested),
            executed=acts[pick],
            alpha=float(sol.alpha[pick]),
            beta=float(sol.beta[pick]),
            predicted_landing=landing,
            predicted_velocity=rotate_xy(sol.velocity[pick], psi),
            cost=float(sol.cost[pick]),
            backup_used=pick != req,
            actions=acts,
            costs=sol.cost,
            p_ok=float(sol.p_ok[pick]),
            in_range=in_range,
        )
