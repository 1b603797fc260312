"""The schedule of a navigation run: its section of the configuration tree.

The tree itself (:class:`hopper_sim.config.RunnerSettings`) composes this section with the
planner's own settings (:class:`planner.learning.ResynthesisSettings`, which holds the
:class:`planner.policy.SwitchingSettings` and :class:`planner.qlearning.QLearningSettings`)
and the simulation's; each default is defined once, in the dataclass field that holds it. A
scenario's TOML ``[runner]`` table (:class:`planner.scenario.RunnerParams`) takes its defaults
from these fields and maps onto the tree (:data:`RUNNER_KEYS`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from planner.errors import PlannerError


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
