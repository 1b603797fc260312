"""Exceptions raised by the planning library.

Every error names what is wrong and where (a position in a formula, a state and action in a
model, a line in a file). All derive from :class:`PlannerError`, itself a ``ValueError``.
"""

from __future__ import annotations


class PlannerError(ValueError):
    """Base class of every error raised by :mod:`planner`."""


class AutomatonError(PlannerError):
    """An automaton is malformed (bad transition table, unknown state, bad alphabet)."""


class UnknownPropositionError(PlannerError):
    """A formula or word names a proposition that the labels do not provide."""


class LTLSyntaxError(PlannerError):
    """An LTL formula does not parse; the message names the position and what was expected.

    Attributes:
        position: 0-based character offset of the offending token in the formula.
    """

    def __init__(self, message: str, position: int) -> None:
        super().__init__(message)
        self.position = position


class HOAError(PlannerError):
    """A HOA (Hanoi Omega-Automata) text is malformed or unsupported; names the line."""


class NondeterministicAutomatonError(HOAError):
    """A HOA automaton is not deterministic (several initial states or overlapping edges)."""
