"""The planner's sections of a navigation run's configuration tree.

:class:`RunConfig` (the run's schedule) and :class:`PlannerConfig` (the abstraction and
synthesis, holding the :class:`planner.policy.SwitchingConfig` and
:class:`planner.qlearning.QLearningConfig`); the tree itself
(:class:`hopper_sim.navigation.config.NavigationConfig`) composes them with the simulation's. Each
default
is defined once, in the dataclass field that holds it. A
scenario's TOML ``[runner]`` table (:class:`planner.scenario.RunnerTableConfig`) takes its defaults
from these fields and maps onto the tree (:data:`RUNNER_KEYS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

from planner.errors import IntervalError, PlannerError, PolicyError
from planner.intervals import TruncatedGaussianNoise
from planner.modes import Candidates
from planner.policy import SwitchingConfig
from planner.qlearning import QLearningConfig
from planner.tour import TOUR_MODES


class ConfigValueError(PlannerError):
    """A setting of the run's schedule out of its range (the message names the field)."""


@dataclass(frozen=True)
class RunConfig:
    """When a run re-synthesises and when it stops.

    Attributes:
        batch_size: hops between two GP refits and re-syntheses.
        max_steps: hop cap of one run; reaching it ends the run as a timeout.
        runs: number of consecutive runs (Q-values and learned rewards carried over).
        seed: seed of the first run (run ``k`` uses ``seed + k``).
        window: hops of the last window by which a run still undecided at ``max_steps`` is
            judged (recurrence, persistence, safety formulas; 0: the last half of the run;
            :class:`planner.verdict.MissionMonitor`).
    """

    batch_size: int = 50
    max_steps: int = 500
    runs: int = 1
    seed: int = 0
    window: int = 0

    def __post_init__(self) -> None:
        least = {"batch_size": 1, "max_steps": 1, "runs": 1, "seed": 0, "window": 0}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigValueError(f"{f.name} must be a whole number, got {value!r}")
            if value < least[f.name]:
                raise ConfigValueError(f"{f.name} must be >= {least[f.name]}, got {value}")


CANDIDATES: tuple[str, ...] = tuple(m.value for m in Candidates)
"""The exploration targets of :class:`PlannerConfig` (``candidates``)."""


@dataclass(frozen=True)
class PlannerConfig:
    """Settings of :func:`resynthesise` and of the plans it makes (the planner's part of the
    run's configuration tree, :class:`hopper_sim.navigation.config.NavigationConfig`).

    ``samples_per_axis``: sample points per cell and axis for the per-(cell, action) error
    bounds; ``delta``, ``horizon`` and ``beta``: see :mod:`planner.intervals` (``beta=None``
    takes the union-bound multiplier for ``delta`` over ``horizon`` hops; a ``beta`` is an
    override for studies of the guarantee, not a calibrated value); ``noise`` is the known
    landing noise nu, which must be the one of the GP's prior; ``q_tolerance``: the
    convergence tolerance of the robust Q-iteration.

    ``candidates``: the end components the exploration steers to: ``"nonviolating"``
    (default: the pessimistic MECs of the nonviolating sub-model, as the paper defines
    exploration) or ``"accepting"`` (the goal-directed variant: the robustly accepting ones,
    falling back to the nonviolating MECs if there are none). ``tour``: the in-component
    tour's mode (:data:`planner.tour.TOUR_MODES`): ``"reward"`` (default) heads for the
    component's cells of highest reward still to be collected, then tours the rest;
    ``"coverage"`` only tours (least recently visited, least known cells first), leaving the
    reward to the RL action.

    ``switching``: the settings of the :class:`~planner.policy.SwitchingPolicy` that acts on
    these plans; its ``p_sat`` is also the threshold of the satisfying sub-model
    (:attr:`p_sat`), so build the policy with ``SwitchingPolicy(settings.switching)``.
    ``q_learning``: the reward's Q-learning settings; its ``discount`` is also that of the
    known reward's robust Q-iteration (:attr:`discount`), so build a learner with
    ``RobustQLearner(..., settings=settings.q_learning)``.
    """

    samples_per_axis: int = 5
    delta: float = 0.01
    horizon: int = 100
    beta: float | None = None
    noise: TruncatedGaussianNoise = field(default_factory=TruncatedGaussianNoise)
    q_tolerance: float = 1e-6
    candidates: str = "nonviolating"
    tour: str = "reward"
    switching: SwitchingConfig = field(default_factory=SwitchingConfig)
    q_learning: QLearningConfig = field(default_factory=QLearningConfig)

    def __post_init__(self) -> None:
        if self.candidates not in CANDIDATES:
            raise PolicyError(
                f"candidates must be 'nonviolating' or 'accepting', got {self.candidates!r}"
            )
        if self.tour not in TOUR_MODES:
            raise PolicyError(f"tour must be one of {TOUR_MODES}, got {self.tour!r}")
        for name in ("samples_per_axis", "horizon"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise IntervalError(f"{name} must be a whole number >= 1, got {value!r}")
        if not 0.0 < self.delta < 1.0:
            raise IntervalError(f"delta must lie in (0, 1), got {self.delta}")
        if self.beta is not None and not (math.isfinite(self.beta) and self.beta >= 0.0):
            raise IntervalError(f"beta must be finite and >= 0, got {self.beta}")
        if not (math.isfinite(self.q_tolerance) and self.q_tolerance > 0.0):
            raise PolicyError(f"q_tolerance must be finite and > 0, got {self.q_tolerance}")

    @property
    def p_sat(self) -> float:
        """``P_sat`` (of :attr:`switching`): the satisfying sub-model keeps the states and
        actions whose worst-case satisfaction probability exceeds it."""
        return self.switching.p_sat

    @property
    def discount(self) -> float:
        """``gamma`` (of :attr:`q_learning`) of the reward's robust Q-iteration."""
        return self.q_learning.discount

    def interval_options(self) -> dict[str, Any]:
        """The keyword arguments of :func:`~planner.intervals.cell_error_bounds`."""
        return {
            "samples_per_axis": self.samples_per_axis,
            "delta": self.delta,
            "horizon": self.horizon,
            "beta": self.beta,
        }


RUNNER_KEYS: dict[str, str] = {
    "batch_size": "run.batch_size",
    "max_steps": "run.max_steps",
    "runs": "run.runs",
    "seed": "run.seed",
    "window": "run.window",
    "p_rl_ee": "planner.switching.p_rl_explore",
    "c": "planner.switching.c",
    "eps": "planner.switching.eps",
    "discount": "planner.q_learning.discount",
}
"""A scenario's ``[runner]`` key -> the configuration tree's key it sets (the scenario's
top-level ``p_sat`` sets :data:`P_SAT_KEY`)."""

P_SAT_KEY = "planner.switching.p_sat"
"""The tree's key of the scenario's top-level ``p_sat``."""
