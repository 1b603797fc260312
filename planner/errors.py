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


class ModelError(PlannerError):
    """An interval MDP is malformed (see the subclasses for what exactly)."""


class IndexOutOfRangeError(ModelError):
    """A state, action or successor index lies outside the model."""


class IntervalBoundsError(ModelError):
    """A transition interval has ``lower > upper`` or a bound outside ``[0, 1]``."""


class RowSumError(ModelError):
    """A (state, action) row whose bounds do not bracket 1 (``sum l <= 1 <= sum u``)."""


class DuplicateSuccessorError(ModelError):
    """A (state, action) row names the same successor twice."""


class MissingRowError(ModelError):
    """A state has no enabled action, or an enabled action has no transitions."""


class UnknownLabelError(ModelError):
    """A state label is not one of the model's declared propositions."""


class ProductError(PlannerError):
    """A product of a model with an automaton (or a reward) cannot be formed."""


class SpecificationError(PlannerError):
    """A specification, problem or algorithm setting is malformed."""


class ModelFormatError(PlannerError):
    """A model file cannot be read; the message names the file and the line."""


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
