"""The navigation environment: the MuJoCo hopper (physics) in a scenario's grid world (task).

dm_control's split: :class:`~hopper_sim.model.HopperModel` is the physics, the
:class:`~planner.scenario.Scenario` (world, labels, rewards) the task, and
:class:`HopperGridEnv` joins them with Gymnasium's conventions:
``reset(seed=...) -> (observation, info)`` and
``step(action, allowed=...) -> (observation, reward, terminated, truncated, info)``. The loop
that chooses the actions (planning, learning, observers) is :mod:`hopper_sim.runner`.

One step is one hop. The grid action (``N1, N2, E1, E2, S1, S2, W1, W2``: 1 or 2 cells north,
east, south or west, aiming at the target cell's centre) is turned into touchdown angles by
the learned :class:`~hopper_sim.controller.LegAngleController`; if its predicted cost is above
the controller's backup threshold, the controller executes the cheapest of the ``allowed``
actions instead (the paper's backup action). The hop is simulated in MuJoCo with the terrain
force field of the world (fixed by ``terrain_seed``: the same world in every episode), the
per-hop landing noise nu (drawn from the episode's generator) and the stance thrust that
regulates the energy to that of steady hopping.

Observation: the interstitial state, ``{"pos": (2,) m, "vel": (3,) m/s, "cell": int}``, the
cell a flat index ``i * ny + j`` (``nx * ny`` = off the map). Reward: the scenario's reward of
the cell landed in (``W``), paid as the scenario's ``collect`` says: with ``"once"`` only on the
episode's first landing in that cell, with ``"every"`` on every landing
(:attr:`HopperGridEnv.collected` marks the cells landed in so far, ``info["first_landing"]``
whether this landing was the episode's first in its cell). ``terminated`` when the hopper lands
in a hazard cell or off the map, or a hop fails (the hopper fell: ``info["hop"].status`` says
why); reaching the goal is the task's business (the automaton), not the environment's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hopper_sim.controller import LegAngleController, load_checkpoint
from hopper_sim.controller.controller import HopDecision
from hopper_sim.controller.simulator import nominal_energy
from hopper_sim.hop import HopResult, simulate_hop
from hopper_sim.model import HopperModel
from hopper_sim.noise import sample_model_noise
from hopper_sim.terrain import TerrainField
from planner.imdp.grid import ACTIONS, GridWorld
from planner.scenario import Scenario


class EpisodeError(RuntimeError):
    """The environment was used out of order (a step before reset, a step after the end)."""


@dataclass(frozen=True)
class EnvSettings:
    """Physics switches of the environment.

    Attributes:
        terrain: apply the terrain force field in stance.
        noise: apply the landing noise nu.
        thrust: regulate each hop's energy to the steady gait's with the stance thrust.
        terrain_seed: seed of the terrain field (the world; the same in every episode).
        record_paths: keep each hop's CoM path (for recordings and figures).
    """

    terrain: bool = True
    noise: bool = True
    thrust: bool = True
    terrain_seed: int = 0
    record_paths: bool = True


@dataclass(frozen=True)
class StepInfo:
    """What a step did: the controller's decision, the hop, the target of the executed action
    (world m) and the landing error ``landing - target`` (m) that the GPs learn."""

    decision: HopDecision
    hop: HopResult
    start_pos: np.ndarray
    target: np.ndarray
    error: np.ndarray | None


class HopperGridEnv:
    """The hopper in a grid world (see the module docstring).

    Args:
        scenario: the world and its labels and rewards.
        model: the hopper physics (default: the shipped MJCF).
        controller: the leg-angle controller (default: the shipped checkpoint, checked
            against ``model``'s parameter hash).
        settings: physics switches.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        model: HopperModel | None = None,
        controller: LegAngleController | None = None,
        settings: EnvSettings | None = None,
    ) -> None:
        self.scenario = scenario
        self.settings = settings or EnvSettings()
        self.model = model or HopperModel.load()
        if controller is None:
            ckpt = load_checkpoint(expected_param_hash=self.model.param_hash())
            controller = LegAngleController.from_checkpoint(ckpt)
        self.controller = controller
        w = scenario.world
        self.grid = GridWorld(w.nx, w.ny, w.cell, scenario.cell_labels, scenario.hazard)
        self.terrain = (
            TerrainField.for_model(self.model, self.settings.terrain_seed)
            if self.settings.terrain
            else None
        )
        self.reward_table = np.append(np.asarray(scenario.reward_grid, float).ravel(), 0.0)
        self.hazard_cells = self.grid.label_mask(scenario.hazard)
        self.collected = np.zeros(self.grid.n_states, dtype=bool)
        """Cells landed in during this episode (the start cell is not a landing)."""
        self._energy = nominal_energy(self.model, controller.steady.speed)
        self._data = self.model.make_data()
        self._rng: np.random.Generator | None = None
        self._done = True
        self.pos = np.zeros(2)
        self.vel = np.zeros(3)

    @property
    def cell(self) -> int:
        return int(self.grid.locate(self.pos[None, :])[0])

    def observation(self) -> dict[str, Any]:
        return {"pos": self.pos.copy(), "vel": self.vel.copy(), "cell": self.cell}

    def reset(self, *, seed: int | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
        """Start an episode at the scenario's start, in the steady gait heading east.

        ``seed`` seeds the episode's generator (the landing noise); ``None`` keeps drawing
        from the previous generator (a fresh unseeded one on the first reset).
        """
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self.pos = np.asarray(self.scenario.start, dtype=float).copy()
        self.vel = self.controller.steady.velocity.copy()
        self.collected[:] = False
        self._done = False
        return self.observation(), {}

    def targets(self, cell: int, actions: np.ndarray) -> np.ndarray:
        """Target positions (world m) of ``actions`` from ``cell``, ``(len(actions), 2)``."""
        return self.grid.target_centres[cell, np.asarray(actions, dtype=int)]

    def step(
        self, action: int, allowed: np.ndarray | None = None
    ) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """One hop towards ``action``'s target; ``allowed`` (action ids) are the backup's
        choices (default: every enabled action of the current cell)."""
        if self._done or self._rng is None:
            raise EpisodeError("step() needs reset() first (and a running episode)")
        cell = self.cell
        enabled = np.flatnonzero(self.grid.enabled[cell])
        acts = enabled if allowed is None else np.asarray(allowed, dtype=int)
        if action not in acts or not self.grid.enabled[cell, action]:
            raise EpisodeError(
                f"action {ACTIONS[action] if 0 <= action < len(ACTIONS) else action} is not "
                f"enabled and allowed in cell {cell} (allowed: {[ACTIONS[a] for a in acts]})"
            )
        acts = acts[self.grid.enabled[cell, acts]]
        decision = self.controller.decide(
            self.pos, self.vel, acts, self.targets(cell, acts), int(action)
        )
        nu = sample_model_noise(self.model, self._rng, 1)[0] if self.settings.noise else None
        start = self.pos.copy()
        hop = simulate_hop(
            self.model,
            self.pos,
            self.vel,
            decision.alpha,
            decision.beta,
            terrain=self.terrain,
            noise=nu,
            thrust=self.settings.thrust,
            nominal_energy=self._energy if self.settings.thrust else None,
            record_path=self.settings.record_paths,
            data=self._data,
        )
        target = self.targets(cell, [decision.executed])[0]
        if not hop.ok:
            self._done = True
            info = StepInfo(decision, hop, start, target, None)
            return self.observation(), 0.0, True, False, {"step": info, "outcome": "fell"}
        self.pos = np.asarray(hop.next_pos, dtype=float).copy()
        self.vel = np.asarray(hop.next_vel, dtype=float).copy()
        landed = self.cell
        first = not self.collected[landed]
        self.collected[landed] = True
        paid = first or self.scenario.collect == "every"
        reward = float(self.reward_table[landed]) if paid else 0.0
        hazard = bool(self.hazard_cells[landed])
        self._done = hazard
        info = StepInfo(decision, hop, start, target, self.pos - target)
        return (
            self.observation(),
            reward,
            hazard,
            False,
            {"step": info, "outcome": "hazard" if hazard else None, "first_landing": first},
        )
