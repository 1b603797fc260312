"""hopnav's planning library: LTL, interval MDPs, products, synthesis, learned intervals.

Pure Python/numpy/scipy (and torch for the GP pieces); it never imports MuJoCo. The nouns of
the pipeline are importable from here (``from planner import GridWorld, solve``); each is
imported on first use, so ``import planner`` itself is cheap.

Pipeline, in the order a run uses it: a :class:`Scenario` (``load_scenario("a")``) gives the
:class:`GridWorld` and the LTL formula, which :func:`translate` turns into a
:class:`RabinAutomaton`; a :class:`LandingErrorGP` learns the landing error, whose per-cell
bounds (:func:`cell_error_bounds`) with the :class:`TruncatedGaussianNoise` give the
transition intervals (:func:`transition_intervals`) of an :class:`IMDP`; the
:class:`ProductIMDP` with the automaton is solved with ``solve(Problem(model,
Specification(ReachAvoid(...))), ValueIteration())``; :func:`resynthesise` does all of it for
the learning loop and a :class:`SwitchingPolicy` acts on its result, with a
:class:`RobustQLearner` where the reward is unknown.
"""

from __future__ import annotations

import importlib
from typing import Any

from hopnav import __version__

#: public name -> module that defines it
_EXPORTS: dict[str, str] = {
    # scenarios
    "Scenario": "planner.scenario",
    "World": "planner.world",
    "Region": "planner.world",
    "GridGeometry": "planner.geometry",
    "RunnerTableConfig": "planner.scenario",
    "load_scenario": "planner.scenario_file",
    "parse_scenario": "planner.scenario_file",
    # LTL and automata
    "RabinAutomaton": "planner.automaton",
    "RabinPair": "planner.automaton",
    "translate": "planner.ltl.translate",
    "parse_formula": "planner.ltl.parser",
    # interval MDPs
    "ACTIONS": "planner.imdp",
    "IMDP": "planner.imdp",
    "GridWorld": "planner.imdp",
    "ProductIMDP": "planner.imdp",
    "satisfaction": "planner.imdp.analysis",
    "labelled_model": "planner.imdp.analysis",
    "Problem": "planner.imdp",
    "Specification": "planner.imdp",
    "ReachAvoid": "planner.imdp",
    "DiscountedReward": "planner.imdp",
    "ValueIteration": "planner.imdp",
    "Solution": "planner.imdp",
    "solve": "planner.imdp",
    "read_model": "planner.imdp.io",
    "write_model": "planner.imdp.io",
    # learned intervals
    "LandingErrorGP": "planner.gp.landing",
    "GPConfig": "planner.gp.landing",
    "TruncatedGaussianNoise": "planner.intervals",
    "cell_error_bounds": "planner.intervals",
    "transition_intervals": "planner.intervals",
    # synthesis, policies, learning
    "resynthesise": "planner.learning",
    "Resynthesis": "planner.learning",
    "PlannerConfig": "planner.config",
    "SwitchingPolicy": "planner.policy",
    "SwitchingConfig": "planner.policy",
    "RobustQLearner": "planner.qlearning",
    "QLearningConfig": "planner.qlearning",
    "robust_q_iteration": "planner.qlearning",
    # errors
    "PlannerError": "planner.errors",
    "ScenarioError": "planner.errors",
}
_RENAMED = {"parse_formula": "parse"}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'planner' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), _RENAMED.get(name, name))
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
