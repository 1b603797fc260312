"""The nouns of robust analysis (IntervalMDP.jl's): properties (:class:`ReachAvoid`,
:class:`DiscountedReward`), a :class:`Specification`, a :class:`Problem`, the algorithm
:class:`ValueIteration` and its :class:`Solution`; the analyses are
:func:`planner.imdp.solve.solve`."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from planner.errors import SpecificationError
from planner.imdp import graph
from planner.imdp.model import IMDP
from planner.modes import Adversary, Objective

StateSet = np.ndarray | str | Sequence[str] | Sequence[int]


@dataclass(frozen=True)
class ReachAvoid:
    """Reach ``target`` without first entering ``avoid``: ``(!avoid) U target``.

    ``target`` / ``avoid``: a boolean state mask, a label name, a list of label names
    (a state qualifies if it carries any of them) or a list of state indices.
    """

    target: StateSet
    avoid: StateSet | None = None


@dataclass(frozen=True)
class DiscountedReward:
    """Discounted reward ``sum_k gamma^k W(s_{k+1})`` (``W`` collected on landing)."""

    reward: np.ndarray
    discount: float


@dataclass(frozen=True)
class Specification:
    """A property with the adversary's and the strategy's goal.

    Args:
        property: :class:`ReachAvoid` or :class:`DiscountedReward`.
        satisfaction: the adversary, :class:`~planner.modes.Adversary`: ``"pessimistic"``
            (it opposes) or ``"optimistic"``.
        strategy: :class:`~planner.modes.Objective`: ``"maximize"`` or ``"minimize"``.
    """

    property: ReachAvoid | DiscountedReward
    satisfaction: Adversary = Adversary.PESSIMISTIC
    strategy: Objective = Objective.MAXIMIZE

    def __post_init__(self) -> None:
        if self.satisfaction not in tuple(Adversary):
            raise SpecificationError(
                f"satisfaction must be 'pessimistic' or 'optimistic', got {self.satisfaction!r}"
            )
        if self.strategy not in tuple(Objective):
            raise SpecificationError(
                f"strategy must be 'maximize' or 'minimize', got {self.strategy!r}"
            )
        if not isinstance(self.property, ReachAvoid | DiscountedReward):
            raise SpecificationError(
                f"property must be ReachAvoid or DiscountedReward, got {type(self.property)}"
            )
        if isinstance(self.property, DiscountedReward) and not 0 <= self.property.discount < 1:
            raise SpecificationError(f"discount must be in [0, 1), got {self.property.discount}")


@dataclass(frozen=True)
class Problem:
    """A model, a specification and (optionally) the actions the strategy may use.

    Args:
        model: the interval MDP.
        specification: what to compute.
        allowed: ``(n_states, n_actions)`` mask of allowed actions (a sub-model); states
            without an allowed action get value 0 and strategy -1.

    Raises:
        SpecificationError: on masks of the wrong shape, unknown labels or state indices.
    """

    model: IMDP
    specification: Specification
    allowed: np.ndarray | None = None

    def __post_init__(self) -> None:
        m = self.model
        if self.allowed is not None:
            a = np.asarray(self.allowed)
            if a.shape != (m.n_states, m.n_actions) or a.dtype != bool:
                raise SpecificationError(
                    f"allowed must be a boolean ({m.n_states}, {m.n_actions}) mask, got "
                    f"{a.dtype} {a.shape}"
                )
        prop = self.specification.property
        if isinstance(prop, ReachAvoid):
            resolve_states(m, prop.target, "target")
            if prop.avoid is not None:
                resolve_states(m, prop.avoid, "avoid")
        else:
            w = np.asarray(prop.reward, dtype=np.float64)
            if w.shape != (m.n_states,) or not np.all(np.isfinite(w)):
                raise SpecificationError(
                    f"reward must be a finite array of shape ({m.n_states},), got {w.shape}"
                )

    def row_mask(self) -> np.ndarray:
        if self.allowed is None:
            return np.ones(self.model.n_rows, dtype=bool)
        return graph.rows_from_actions(self.model, self.allowed)


def resolve_states(model: IMDP, states: StateSet, what: str) -> np.ndarray:
    """A boolean state mask from a mask, a label, label names or state indices."""
    if isinstance(states, str):
        states = [states]
    arr = np.asarray(states)
    if arr.dtype == bool:
        if arr.shape != (model.n_states,):
            raise SpecificationError(
                f"{what} mask must have shape ({model.n_states},), got {arr.shape}"
            )
        return arr.copy()
    if arr.size == 0:
        return np.zeros(model.n_states, dtype=bool)
    if arr.dtype.kind in "US":
        mask = np.zeros(model.n_states, dtype=bool)
        for name in arr.tolist():
            if name not in model.propositions:
                raise SpecificationError(
                    f"{what} label {name!r} is not among the model's propositions "
                    f"{model.propositions}"
                )
            mask |= model.label_matrix[:, model.propositions.index(name)]
        return mask
    if arr.dtype.kind in "iu":
        bad = arr[(arr < 0) | (arr >= model.n_states)]
        if bad.size:
            raise SpecificationError(f"{what} state {bad[0]} is not in [0, {model.n_states})")
        mask = np.zeros(model.n_states, dtype=bool)
        mask[arr] = True
        return mask
    raise SpecificationError(f"cannot read {what} states from {states!r}")


@dataclass(frozen=True)
class ValueIteration:
    """Robust value iteration with the state-ordering adversary.

    Args:
        tolerance: the width of the certified bracket ``upper - lower`` at which to stop
            (default 1e-8); with ``certified=False``, the residual ``max |V_k - V_{k-1}|``
            at which to stop.
        max_iterations: give up after this many sweeps (the solution then reports
            ``converged=False`` and the bracket reached so far).
        callback: called as ``callback(iteration, residual)`` after every sweep.
        precompute: settle the states of reachability probability 0 and (worst case, or
            a minimising strategy) 1 by graph analysis before iterating (default). Without
            it the values from below approach the same least fixed point, more slowly, and
            a minimising strategy's bound from above can stay at 1 where it could keep a
            run away from the target for ever.
        strategy_iteration: for maximal reachability, switch to robust strategy
            iteration (exact sparse evaluation of a strategy against the adversary's best
            response, then strict improvements) when the sweeps creep towards the
            tolerance (default). Without it plain sweeps can take millions of sweeps where
            mass leaks slowly out of near-end-components.
        certified: bracket every value from below and above and stop when the bracket is
            narrower than ``tolerance`` (default). ``certified=False`` is the fast
            *uncertified* mode: it stops on the residual alone, which does not bound the
            error (a slow leak can leave an error far above the residual); its ``upper``
            is then the trivial bound.
        initial: discounted reward only: ``(n_states,)`` values to start the sweeps from
            (a warm start; any start converges, the sweeps contract). Default 0.
    """

    tolerance: float = 1e-8
    max_iterations: int = 1_000_000
    callback: Callable[[int, float], None] | None = None
    precompute: bool = True
    strategy_iteration: bool = True
    certified: bool = True
    initial: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not self.tolerance > 0:
            raise SpecificationError(f"tolerance must be positive, got {self.tolerance}")
        if self.max_iterations < 1:
            raise SpecificationError(f"max_iterations must be >= 1, got {self.max_iterations}")


@dataclass
class Solution:
    """Result of :func:`solve`.

    Attributes:
        values: ``(n_states,)`` values. Reachability: the sound lower bound of the bracket
            (``values == lower``); every value is attained: the strategy reaches the
            target with at least this probability against every adversary (or, for a
            minimising strategy, the value is at most ``upper``). Discounted reward: the
            centre of the bracket.
        lower, upper: ``(n_states,)`` the certified bracket, ``lower <= V* <= upper`` for
            the optimal values ``V*``. For reachability the bound from above (of a
            maximal problem; of a minimal one, its dual's, which gives ``lower``) counts
            only once shown superharmonic in exact arithmetic
            (:func:`planner.imdp.certify.verify_upper`); where it was not, the solution
            is not ``converged``, a maximal problem's ``upper`` is 1 on the free states
            and a minimal problem's ``lower`` is 0 there (the trivial bounds: the
            iteration's own bound is checked in floating point only, which over long
            stays can leave it below the value). With the uncertified mode ``upper`` is
            only the trivial bound (1 for reachability; for discounted reward the
            residual bound, which is sound for that property).
        strategy: ``(n_states,)`` chosen action per state (-1: none; targets, avoided
            states, states without allowed actions and states settled by graph analysis
            where the action does not matter; a maximising strategy's value-1 states and
            a minimising one's value-0 states get the action that attains the value).
        residual: the last ``max |V_k - V_{k-1}|`` (a sweep with the exact order).
        iterations: the number of sweeps (from below; the sweeps that check or tighten
            the upper bound are counted in ``upper_sweeps``).
        evaluations: the number of exact strategy evaluations by strategy iteration
            (each: one or more sparse linear solves; 0 when the sweeps did not creep).
        converged: whether the stopping rule was met (certified: ``max(upper - lower) <
            tolerance``; uncertified: ``residual < tolerance``).
        fixed: ``(n_states,)`` mask of the states whose value was set without iteration.
        upper_sweeps: sweeps from above (verification of the upper bound).
        q_values: ``(n_rows,)`` robust value of every row under the final values
            (``nan`` for rows outside the allowed sub-model); computed on first access.
    """

    values: np.ndarray
    strategy: np.ndarray
    residual: float
    iterations: int
    converged: bool = True
    evaluations: int = 0
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upper_sweeps: int = 0
    _q: Callable[[], np.ndarray] | None = field(default=None, repr=False)
    _q_cache: np.ndarray | None = field(default=None, repr=False)

    @property
    def error(self) -> float:
        """``max(upper - lower)``: the certified error bound of ``values``."""
        if self.upper.size == 0:
            return float("inf")
        return float(np.max(self.upper - self.lower))

    @property
    def q_values(self) -> np.ndarray:
        if self._q_cache is None:
            if self._q is None:
                raise SpecificationError("this solution carries no row values")
            self._q_cache = self._q()
        return self._q_cache
