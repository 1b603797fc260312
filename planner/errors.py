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


class GPModelError(PlannerError):
    """A Gaussian-process model is set up wrongly (unsupported kernel, bad shapes)."""


class GPDataError(PlannerError):
    """Training or query data for a Gaussian process is malformed (shape, non-finite values)."""


class IntervalError(PlannerError):
    """Inputs of the transition-interval computation are invalid (grid, noise, error bounds)."""


class QTableError(PlannerError):
    """A Q-table or reward table is inconsistent with its model, or its file is corrupt."""


class PolicyError(PlannerError):
    """A policy is asked to act where it cannot (no allowed action, bad parameters)."""
