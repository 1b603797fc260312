"""Interval MDPs: models, the grid abstraction, the product with a Rabin automaton,
graph analyses and robust value iteration."""

from planner.imdp.model import BOUND_TOLERANCE, IMDP
from planner.imdp.ordering import (
    OrderingAdversary,
    best_case_expectation,
    worst_case_expectation,
)
from planner.imdp.solve import (
    DiscountedReward,
    Problem,
    ReachAvoid,
    Solution,
    Specification,
    ValueIteration,
    solve,
)

__all__ = [
    "BOUND_TOLERANCE",
    "IMDP",
    "DiscountedReward",
    "OrderingAdversary",
    "Problem",
    "ReachAvoid",
    "Solution",
    "Specification",
    "ValueIteration",
    "best_case_expectation",
    "solve",
    "worst_case_expectation",
]
