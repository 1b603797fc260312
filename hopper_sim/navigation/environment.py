"""The navigation environment: the MuJoCo hopper (physics) in a scenario's grid world (task).

dm_control's split: :class:`~hopper_sim.physics.model.HopperModel` is the physics, the
:class:`~planner.scenario.Scenario` (world, labels, rewards) the task, and
:class:`HopperGridEnv` joins them as a Gymnasium environment:
``reset(seed=..., options=...) -> (observation, info)`` and
``step(action, allowed=...) -> (observation, reward, terminated, truncated, info)``, with
``action_space`` ``Discrete(8)``, a ``Dict`` ``observation_space`` and ``close()``. With
gymnasium installed (the ``gym`` extra) it is a :class:`gymnasium.Env` (registered as
``hopnav/HopperGrid-v0`` when :mod:`hopper_sim` is imported) and passes
``gymnasium.utils.env_checker.check_env``; without it, the same class works without the
spaces (``None``). The loop that chooses the actions (planning, learning, observers) is
:mod:`hopper_sim.navigation.runner`.

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
in a hazard cell or off the map, or a hop fails (the hopper fell: ``info["step"].hop.status``
says why); reaching the goal is the task's business (the automaton), not the environment's.
``truncated`` when the episode reaches ``max_steps`` hops (default: the scenario's step cap)
without terminating. ``info["action_mask"]`` (``int8``, one per action) marks the actions
whose target cell lies inside the world from the current cell (the abstraction's enabled
actions). A Gymnasium agent may still step a masked action: the hopper then aims at that
target outside the world and, landing there, leaves the map (``terminated``); the runner
passes ``allowed`` and gets an :class:`EpisodeError` for such an action instead.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass
from typing import Any

import numpy as np

from hopper_sim.controller import LegAngleController, load_checkpoint
from hopper_sim.controller.controller import HopDecision
from hopper_sim.controller.simulator import nominal_energy
from hopper_sim.errors import HopperSimError
from hopper_sim.physics.hop import HopResult, simulate_hop
from hopper_sim.physics.model import HopperModel
from hopper_sim.physics.noise import sample_model_noise
from hopper_sim.physics.terrain import TerrainField
from planner.imdp.grid import ACTIONS, GridWorld
from planner.scenario import Scenario, load_scenario

try:  # the optional `gym` extra
    import gymnasium
    from gymnasium import spaces

    _EnvBase: type = gymnasium.Env
except ImportError:  # pragma: no cover - exercised where gymnasium is absent
    gymnasium = None
    spaces = None
    _EnvBase = object


class EpisodeError(HopperSimError, RuntimeError):
    """The environment was used out of order (a step before reset, a step after the end)."""


@dataclass(frozen=True)
class EnvConfig:
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


def _same(a: Any, b: Any) -> bool:
    """Equality through dataclasses, sequences and arrays (NaN equal to NaN)."""
    if is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(
            _same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a)
        )
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        numeric = a.dtype.kind in "fc" and b.dtype.kind in "fc"
        return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=numeric))
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float) and np.isnan(a) and np.isnan(b):
        return True
    return bool(a == b)


@dataclass(frozen=True, eq=False)
class StepInfo:
    """What a step did: the controller's decision, the hop, the target of the executed action
    (world m) and the landing error ``landing - target`` (m) that the GPs learn.

    Two are equal when every field is (arrays element-wise), so that Gymnasium's
    determinism checks can compare the ``info`` of two identical steps."""

    decision: HopDecision
    hop: HopResult
    start_pos: np.ndarray
    target: np.ndarray
    error: np.ndarray | None

    def __eq__(self, other: object) -> bool:
        return isinstance(other, StepInfo) and _same(self, other)

    __hash__ = None  # type: ignore[assignment]


class HopperGridEnv(_EnvBase):
    """The hopper in a grid world (see the module docstring).

    Args:
        scenario: the world and its labels and rewards, or a shipped name / TOML path.
        model: the hopper physics (default: the shipped MJCF).
        controller: the leg-angle controller (default: the shipped checkpoint, checked
            against ``model``'s parameter hash).
        settings: physics switches.
        max_steps: hops after which an episode is truncated (default: the scenario's
            ``runner.max_steps``).

    Attributes:
        action_space: ``Discrete(8)``, the actions of :data:`planner.imdp.grid.ACTIONS`
            (``None`` without gymnasium).
        observation_space: ``Dict(pos=Box(2), vel=Box(3), cell=Discrete(nx * ny + 1))``
            (``None`` without gymnasium).
    """

    metadata = {"render_modes": []}  # noqa: RUF012 - Gymnasium's class attribute

    def __init__(
        self,
        scenario: Scenario | str,
        *,
        model: HopperModel | None = None,
        controller: LegAngleController | None = None,
        settings: EnvConfig | None = None,
        max_steps: int | None = None,
    ) -> None:
        if not isinstance(scenario, Scenario):
            scenario = load_scenario(scenario)
        self.scenario = scenario
        self.max_steps = int(scenario.runner.max_steps if max_steps is None else max_steps)
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be at least 1, got {max_steps}")
        self.settings = settings or EnvConfig()
        self.model = model or HopperModel.load()
        if controller is None:
            ckpt = load_checkpoint(expected_param_hash=self.model.param_hash())
            controller = LegAngleController.from_checkpoint(ckpt)
        self.controller = controller
        self.grid = GridWorld.from_scenario(scenario)
        self.terrain = (
            TerrainField.for_model(self.model, self.settings.terrain_seed)
            if self.settings.terrain
            else None
        )
        self.reward_table = scenario.state_rewards
        self.hazard_cells = self.grid.label_mask(scenario.hazard)
        self.collected = np.zeros(self.grid.n_states, dtype=bool)
        """Cells landed in during this episode (the start cell is not a landing)."""
        self._energy = nominal_energy(self.model, controller.steady.speed)
        self._data = self.model.make_data()
        self._rng: np.random.Generator | None = None
        self._done = True
        self._steps = 0
        self.pos = np.zeros(2)
        self.vel = np.zeros(3)
        self.action_space = None
        self.observation_space = None
        if spaces is not None:
            self.action_space = spaces.Discrete(len(ACTIONS))
            self.observation_space = spaces.Dict(
                {
                    "pos": spaces.Box(-np.inf, np.inf, shape=(2,), dtype=np.float64),
                    "vel": spaces.Box(-np.inf, np.inf, shape=(3,), dtype=np.float64),
                    "cell": spaces.Discrete(self.grid.n_cells + 1),
                }
            )

    @property
    def cell(self) -> int:
        return int(self.grid.locate(self.pos[None, :])[0])

    def observation(self) -> dict[str, Any]:
        return {"pos": self.pos.copy(), "vel": self.vel.copy(), "cell": self.cell}

    def action_mask(self, cell: int | None = None) -> np.ndarray:
        """``(8,)`` ``int8``: 1 for the actions enabled in ``cell`` (default: the current
        one; all 0 off the map)."""
        cell = self.cell if cell is None else int(cell)
        if cell >= self.grid.n_cells:
            return np.zeros(len(ACTIONS), dtype=np.int8)
        return self.grid.enabled[cell].astype(np.int8)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Start an episode at the scenario's start (or ``options["start"]``, ``(x, y)`` m in
        the world), in the steady gait heading east.

        ``seed`` seeds the episode's generator (the landing noise); ``None`` keeps drawing
        from the previous generator (a fresh unseeded one on the first reset). The generator
        is ``numpy.random.default_rng(seed)``, as Gymnasium's ``np_random``.

        Raises:
            ValueError: an unknown option, or a start outside the world.
        """
        options = dict(options or {})
        start = options.pop("start", self.scenario.start)
        if options:
            raise ValueError(f"unknown reset option(s) {sorted(options)}; known: 'start'")
        pos = np.asarray(start, dtype=float).reshape(-1)
        w = self.scenario.world
        if pos.shape != (2,) or not (0 <= pos[0] < w.width and 0 <= pos[1] < w.height):
            raise ValueError(
                f"start {start!r} must be (x, y) inside the {w.width} x {w.height} m world"
            )
        if _EnvBase is not object:
            super().reset(seed=seed)
            self._rng = self.np_random
        elif seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self.pos = pos.copy()
        self.vel = self.controller.steady.velocity.copy()
        self.collected[:] = False
        self._done = False
        self._steps = 0
        return self.observation(), {"action_mask": self.action_mask()}

    def close(self) -> None:
        """End the episode; the environment needs :meth:`reset` before the next step."""
        self._done = True

    def targets(self, cell: int, actions: np.ndarray) -> np.ndarray:
        """Target positions (world m) of ``actions`` from ``cell``, ``(len(actions), 2)``
        (also of actions whose target lies outside the world)."""
        return self.grid.hop_target_centres[cell, np.asarray(actions, dtype=int)]

    def step(
        self, action: int, allowed: np.ndarray | None = None
    ) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """One hop towards ``action``'s target; ``allowed`` (action ids) are the backup's
        choices (default: every enabled action of the current cell, and ``action`` itself
        when its target lies outside the world, see the module docstring)."""
        if self._done or self._rng is None:
            raise EpisodeError("step() needs reset() first (and a running episode)")
        cell = self.cell
        action = int(action)
        if not 0 <= action < len(ACTIONS):
            raise EpisodeError(f"action {action} is not one of 0..{len(ACTIONS) - 1}")
        enabled = np.flatnonzero(self.grid.enabled[cell])
        if allowed is None:
            acts = enabled if self.grid.enabled[cell, action] else np.append(enabled, action)
        else:
            acts = np.asarray(allowed, dtype=int)
            if action not in acts or not self.grid.enabled[cell, action]:
                raise EpisodeError(
                    f"action {ACTIONS[action]} is not enabled and allowed in cell {cell} "
                    f"(allowed: {[ACTIONS[a] for a in acts]})"
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
        self._steps += 1
        if not hop.ok:
            self._done = True
            info = StepInfo(decision, hop, start, target, None)
            mask = np.zeros(len(ACTIONS), dtype=np.int8)
            return (
                self.observation(),
                0.0,
                True,
                False,
                {"step": info, "outcome": "fell", "action_mask": mask, "first_landing": False},
            )
        self.pos = np.asarray(hop.next_pos, dtype=float).copy()
        self.vel = np.asarray(hop.next_vel, dtype=float).copy()
        landed = self.cell
        first = not self.collected[landed]
        self.collected[landed] = True
        paid = first or self.scenario.collect == "every"
        reward = float(self.reward_table[landed]) if paid else 0.0
        hazard = bool(self.hazard_cells[landed])
        truncated = not hazard and self._steps >= self.max_steps
        self._done = hazard or truncated
        info = StepInfo(decision, hop, start, target, self.pos - target)
        return (
            self.observation(),
            reward,
            hazard,
            truncated,
            {
                "step": info,
                "outcome": "hazard" if hazard else None,
                "action_mask": self.action_mask(landed),
                "first_landing": first,
            },
        )
