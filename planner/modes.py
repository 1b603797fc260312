"""The modes of planning and of a run, as string enums defined once.

Each member *is* its string (:class:`enum.StrEnum`): ``Phase.EXPLORATION == "exploration"``,
it formats, hashes and serialises (JSON, TOML, rerun) as that string, so files and printed
output carry the plain words and a plain string is accepted wherever a mode is
(``Phase("exploration")`` turns one into its member; an unknown string raises ``ValueError``).
"""

from __future__ import annotations

import sys
from enum import Enum

if sys.version_info >= (3, 11):
    from enum import StrEnum
else:  # pragma: no cover - Python 3.10

    class StrEnum(str, Enum):
        """:class:`enum.StrEnum` of Python 3.11: members are (and print as) their strings."""

        def __str__(self) -> str:
            return str(self.value)

        def __format__(self, spec: str) -> str:
            return format(str(self.value), spec)


class Phase(StrEnum):
    """Phase of the switching policy (:mod:`planner.policy`)."""

    EXPLORATION = "exploration"
    """Before the switch: nonviolating sub-model, towards (and through) the chosen MEC."""
    GOAL_REACHING = "goal_reaching"
    """After the switch: satisfying sub-model, the goal-reaching strategy."""
    FALLBACK = "fallback"
    """No nonviolating action in the current state: the fallback plan's action."""


class Source(StrEnum):
    """Which policy chose an action."""

    LTL = "LTL"
    RL = "RL"


class Outcome(StrEnum):
    """How a run ended (:mod:`planner.verdict`)."""

    SUCCESS = "success"
    """Every hazard-free continuation satisfies the formula (e.g. the goal reached)."""
    VIOLATION = "violation"
    """Hazard, out of the map, a fall, or no continuation satisfies the formula."""
    TIMEOUT = "timeout"
    """The step cap, with the formula still open and its last window not satisfying."""
    SATISFYING = "satisfying"
    """The step cap, with the last window repeated forever satisfying the formula."""


class Adversary(StrEnum):
    """How the interval adversary resolves the transition probabilities."""

    PESSIMISTIC = "pessimistic"
    """It opposes the strategy (the worst case, ``P_check``)."""
    OPTIMISTIC = "optimistic"
    """It cooperates with the strategy (the best case, ``P_hat``)."""


class Objective(StrEnum):
    """What the strategy does with the value."""

    MAXIMIZE = "maximize"
    MINIMIZE = "minimize"


class Candidates(StrEnum):
    """The end components exploration steers to (:class:`planner.learning.PlannerConfig`)."""

    NONVIOLATING = "nonviolating"
    """The pessimistic MECs of the nonviolating sub-model (the paper's exploration)."""
    ACCEPTING = "accepting"
    """The robustly accepting end components (goal-directed; nonviolating MECs if none)."""


class TourMode(StrEnum):
    """The in-component tour's targets (:mod:`planner.tour`)."""

    REWARD = "reward"
    """Rewarding cells first, then as ``COVERAGE``."""
    COVERAGE = "coverage"
    """Least recently visited (then least known) cells first."""
