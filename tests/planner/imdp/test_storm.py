"""Cross-check robust reachability against Storm (stormpy 2.0, a dev dependency).

Storm 2.0 refuses reachability on interval models with a zero lower bound ("requires
graph-preservation"), so the models here have all lower bounds positive: random ones and a
slowly mixing chain (:func:`tests.planner.imdp.reference.sticky_imdp`). Each goes through
our DRN writer and Storm's own DRN parser (``build_model_from_drn[stormpy.Interval]``), then
``model_checking(..., uncertainty_resolution_mode=ROBUST | COOPERATIVE)`` with Storm's robust
value iteration to 1e-12 (absolute), for ``Pmax`` and ``Pmin``.
"""

import numpy as np
import pytest

from planner.imdp import IMDP, Problem, ReachAvoid, Specification, ValueIteration, solve
from planner.imdp.io import write_drn
from tests.planner.imdp.reference import random_imdp, sticky_imdp

stormpy = pytest.importorskip(
    "stormpy",
    reason="stormpy is not installed (it is a dev dependency: pip install -e '.[dev]'; its "
    "wheel exists for CPython 3.11 on x86-64 Linux)",
)


def _model(kind: str, seed: int) -> IMDP:
    if kind == "sticky":  # slowly mixing chains: mass circulates long, every lower bound > 0
        return sticky_imdp(np.random.default_rng(seed), 120)
    return _positive_lower_model(seed)


def _positive_lower_model(seed: int) -> IMDP:
    m = random_imdp(np.random.default_rng(seed), n_states=30, zero_lower=False)
    lower = np.maximum(m.lower, 1e-3)
    s, a, t, _, up = m.coo()
    return IMDP(
        m.n_states,
        s,
        a,
        t,
        lower,
        np.maximum(up, lower),
        n_actions=m.n_actions,
        labels=m.labels,
        propositions=m.propositions,
    )


@pytest.mark.parametrize(("kind", "seed"), [("random", 41), ("random", 7), ("sticky", 2)])
@pytest.mark.parametrize("strategy", ["maximize", "minimize"])
@pytest.mark.parametrize("sat", ["pessimistic", "optimistic"])
def test_values_agree_with_storm(tmp_path, sat, strategy, kind, seed):
    m = _model(kind, seed)
    path = tmp_path / "m.drn"
    write_drn(m, path)
    model = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    assert model.nr_states == m.n_states
    opt = "max" if strategy == "maximize" else "min"
    prop = stormpy.parse_properties(f'P{opt}=? [!"bad" U "goal"]')[0]
    env = stormpy.Environment()
    minmax = env.solver().min_max()
    minmax.method = stormpy.environments.MinMaxMethod.VALUE_ITERATION
    minmax.precision = stormpy.Rational(1e-12)
    minmax.relative_termination_criterion = False
    mode = (
        stormpy.UncertaintyResolutionMode.ROBUST
        if sat == "pessimistic"
        else stormpy.UncertaintyResolutionMode.COOPERATIVE
    )
    result = stormpy.model_checking(
        model,
        prop,
        only_initial_states=False,
        uncertainty_resolution_mode=mode,
        environment=env,
    )
    storm_values = np.array([result.get_value(i) for i in range(m.n_states)])
    sol = solve(
        Problem(m, Specification(ReachAvoid("goal", "bad"), sat, strategy)), ValueIteration(1e-10)
    )
    assert 0.0 < storm_values.max() and storm_values.min() < 1.0  # not a trivial model
    assert sol.values == pytest.approx(storm_values, abs=1e-8)
    # certified, and Storm (at 1e-12) within the bracket up to its own precision
    assert sol.converged
    assert np.all(sol.lower <= storm_values + 1e-9) and np.all(storm_values <= sol.upper + 1e-9)


def test_worst_case_is_below_best_case_in_storm(tmp_path):
    """Storm's two resolution modes bracket each other (the modes are not swapped)."""
    m = _positive_lower_model(41)
    path = tmp_path / "m.drn"
    write_drn(m, path)
    model = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    prop = stormpy.parse_properties('Pmax=? [!"bad" U "goal"]')[0]
    vals = {}
    for mode in ("ROBUST", "COOPERATIVE"):
        r = stormpy.model_checking(
            model,
            prop,
            only_initial_states=False,
            uncertainty_resolution_mode=getattr(stormpy.UncertaintyResolutionMode, mode),
        )
        vals[mode] = np.array([r.get_value(i) for i in range(m.n_states)])
    assert (vals["ROBUST"] <= vals["COOPERATIVE"] + 1e-9).all()
    assert (vals["ROBUST"] < vals["COOPERATIVE"] - 1e-3).any()
