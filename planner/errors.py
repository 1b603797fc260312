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
