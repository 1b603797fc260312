"""Exceptions raised by the planning library.

Every error names what is wrong and where (a position in a formula, a state and action in a
model, a line in a file). All derive from :class:`PlannerError`, itself a ``ValueError``.
"""

from __future__ import annotations


class PlannerError(ValueError):
    """Base class of every error raised by :mod:`planner`."""


class AutomatonError(PlannerError):
    """An automaton is malformed (bad transition table, unknown state, bad alphabet)."""


class TranslationLimitError(AutomatonError):
    """An LTL translation exceeded a limit (letters, states or time;
    :class:`planner.ltl.budget.TranslationLimits`)."""


class ResourceLimitError(PlannerError):
    """An input asks for more than a bounded resource allows (states, actions, cells, ...);
    the message names the quantity, the value and the limit."""


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


class ScenarioError(PlannerError):
    """A scenario (a case-study description) is malformed.

    Attributes:
        key: the dotted key the problem is about (``"regions.Goal.rects[1]"``), or ``None``.
        line: the 1-based line of that key in the source file, or ``None`` when unknown
            (a scenario built in code, not loaded from a file).
        source: the file the scenario came from, or ``None``.
        problem: the bare description of the problem, without location.
    """

    def __init__(
        self,
        problem: str,
        *,
        key: str | None = None,
        line: int | None = None,
        source: str | None = None,
    ) -> None:
        self.problem = problem
        self.key = key
        self.line = line
        self.source = source
        super().__init__(self._format())

    def _format(self) -> str:
        where = []
        if self.source is not None:
            where.append(str(self.source))
        if self.line is not None:
            where.append(f"line {self.line}")
        prefix = ", ".join(where)
        key = f"key '{self.key}': " if self.key is not None else ""
        return f"{prefix}: {key}{self.problem}" if prefix else f"{key}{self.problem}"

    def located(self, line: int | None, source: str | None) -> ScenarioError:
        """A copy of this error (same class) carrying a file position."""
        err = type(self)(self.problem, key=self.key, line=line, source=source)
        err.__cause__ = self.__cause__
        return err


class ScenarioSyntaxError(ScenarioError):
    """A scenario file is not valid TOML (the line is tomllib's)."""


class MissingKeyError(ScenarioError):
    """A required scenario key is absent."""


class ScenarioTypeError(ScenarioError):
    """A scenario value has the wrong type or shape (a string where a number is needed...)."""


class ScenarioValueError(ScenarioError):
    """A scenario value has the right type but an invalid value (a negative cell size...)."""


class UndefinedLabelError(ScenarioError, UnknownPropositionError):
    """A formula, reward or setting names a label that no region defines."""


class ScenarioFormulaError(ScenarioError):
    """A scenario's LTL formula does not parse (the message gives the position)."""


class RegionOverlapError(ScenarioError):
    """Regions that must be disjoint (the goal and the hazard) share a cell."""


class RegionOutsideWorldError(ScenarioError):
    """A region, cell or position lies (partly) outside the world."""


class StartInHazardError(ScenarioError):
    """The start position lies in a hazard cell."""


class UnknownKeyError(ScenarioError):
    """A scenario file holds a key the format does not define (often a typo)."""


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


class SealError(PlannerError):
    """Sealed bytes (:mod:`planner._util.sealed`) are not of the expected kind, or their
    digest does not match; the readers of sealed files turn it into their own error type."""
