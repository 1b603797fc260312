"""Interval MDPs: models, the grid abstraction, the product with a Rabin automaton,
graph analyses and robust value iteration."""

from planner.imdp.analysis import MecChoice
from planner.imdp.graph import EndComponent, SubModel
from planner.imdp.grid import ACTIONS, GridWorld
from planner.imdp.model import BOUND_TOLERANCE, IMDP
from planner.imdp.ordering import (
    OrderingAdversary,
    best_case_expectation,
    worst_case_expectation,
)
from planner.imdp.product import ProductIMDP
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
    "ACTIONS",
    "BOUND_TOLERANCE",
    "IMDP",
    "DiscountedReward",
    "EndComponent",
    "GridWorld",
    "MecChoice",
    "OrderingAdversary",
    "Problem",
    "ProductIMDP",
    "ReachAvoid",
    "Solution",
    "Specification",
    "SubModel",
    "ValueIteration",
    "best_case_expectation",
    "solve",
    "worst_case_expectation",
]
