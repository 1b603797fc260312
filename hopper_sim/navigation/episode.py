"""One navigation run's state between the runner's hooks, its clock, and the outcome rule.

:class:`~hopper_sim.navigation.runner.NavigationRunner` keeps an :class:`Episode` per run (data for
the
landing-error model, the synthesis in use, the policy, the automaton monitor, counters);
:class:`RunClock` times its stages; :func:`hop_outcome` decides, from the product state a hop
entered, whether the run ends there (:mod:`planner.verdict`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from planner.modes import Outcome
from planner.verdict import ACCEPTED, REJECTED, AutomatonVerdicts, MissionMonitor

if TYPE_CHECKING:
    from hopper_sim.navigation.events import ResynthesisRecord
    from planner.gp.landing import LandingErrorGP
    from planner.imdp.product import ProductIMDP
    from planner.learning import Resynthesis
    from planner.policy import SwitchingPolicy


def hop_outcome(
    product: ProductIMDP,
    verdicts: AutomatonVerdicts,
    state: int,
    *,
    terminated: bool = False,
    out: int = -1,
    start: bool = False,
) -> tuple[Outcome, str] | None:
    """The outcome rule: how a run ends on entering product state ``state`` (``None``: it
    goes on). ``terminated``: the environment ended the episode there (a hazard cell, or
    ``out``, the model state off the map); else the automaton decides (:mod:`planner.verdict`):
    violation as soon as no hazard-free continuation satisfies the formula, success as soon
    as every one does. ``start``: the run's first state (the reasons say so)."""
    if terminated:
        off_map = product.base_state_of(state) == out
        return Outcome.VIOLATION, "left the map" if off_map else "hazard"
    verdict = verdicts.verdict(product.automaton_state_of(state))
    if verdict == REJECTED:
        return Outcome.VIOLATION, "rejected at the start" if start else "specification violated"
    if verdict == ACCEPTED:
        return Outcome.SUCCESS, "accepted at the start" if start else "specification satisfied"
    return None


class RunClock:
    """A run's wall-clock seconds: since its start, per stage (``gp_fit``, ``abstraction``,
    ``synthesis`` summed over its syntheses; ``hops``; ``replan``) and the longest single
    synthesis (``batch_max``)."""

    def __init__(self, clock: Callable[[], float]) -> None:
        self.clock, self.start = clock, clock()
        self.seconds = dict.fromkeys(("gp_fit", "abstraction", "synthesis", "hops", "replan"), 0.0)
        self.batch_max = 0.0

    @contextmanager
    def timed(self, stage: str) -> Iterator[None]:
        t0 = self.clock()
        yield
        self.seconds[stage] += self.clock() - t0

    def add_synthesis(self, timings: dict[str, float]) -> None:
        for k, v in timings.items():
            self.seconds[k] = self.seconds.get(k, 0.0) + v
        self.batch_max = max(self.batch_max, sum(timings.values()))

    def elapsed(self) -> float:
        return self.clock() - self.start

    def report(self) -> dict[str, float]:
        return {**self.seconds, "batch_max": self.batch_max}


@dataclass
class Episode:
    """One run's state between the hooks of :class:`~hopper_sim.navigation.runner.NavigationRunner`
    (``pstate``: the current product state; ``outcome``: how the run ended, ``None`` while
    it goes on)."""

    run_index: int
    rng: np.random.Generator
    gp: LandingErrorGP
    clock: RunClock
    res: Resynthesis
    policy: SwitchingPolicy
    pstate: int
    monitor: MissionMonitor
    outcome: tuple[Outcome, str] | None = None
    positions: list[np.ndarray] = field(default_factory=list)
    errors: list[np.ndarray] = field(default_factory=list)
    actions: list[int] = field(default_factory=list)
    records: list[ResynthesisRecord] = field(default_factory=list)
    steps: int = 0
    backups: int = 0
    collections: int = 0
    total: float = 0.0
