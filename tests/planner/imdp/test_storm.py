"""Cross-check against Storm (skipped when stormpy is not installed).

Storm 2.0 refuses reachability on interval models with a zero lower bound, so the model
here has all lower bounds positive. Written against stormpy 2.0's documented interface
(``build_interval_model_from_drn``, ``model_checking(..., uncertainty_resolution_mode=)``);
it has not been run on this machine, where stormpy is not installed.
"""

import numpy as np
import pytest

from planner.imdp import IMDP, Problem, ReachAvoid, Specification, ValueIteration, solve
from planner.imdp.io import write_drn
from tests.planner.imdp.reference import random_imdp

stormpy = pytest.importorskip("stormpy")


@pytest.mark.parametrize("sat", ["pessimistic", "optimistic"])
def test_values_agree_with_storm(tmp_path, sat):
    m = random_imdp(np.random.default_rng(41), n_states=30, zero_lower=False)
    lower = np.maximum(m.lower, 1e-3)  # all lower bounds positive
    s, a, t, _, up = m.coo()
    m = IMDP(
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
    path = tmp_path / "m.drn"
    write_drn(m, path)
    model = stormpy.build_interval_model_from_drn(str(path))
    prop = stormpy.parse_properties('Pmax=? [!"bad" U "goal"]')[0]
    env = stormpy.Environment()
    env.solver_environment.minmax_solver_environment.precision = stormpy.Rational(1e-10)
    mode = (
        stormpy.UncertaintyResolutionMode.ROBUST
        if sat == "pessimistic"
        else stormpy.UncertaintyResolutionMode.COOPERATIVE
    )
    task = stormpy.CheckTask(prop.raw_formula, only_initial_states=False)
    task.set_uncertainty_resolution_mode(mode)
    result = stormpy.check_interval_mdp(model, task, env)
    storm_values = np.array([result.at(i) for i in range(m.n_states)])
    ours = solve(
        Problem(m, Specification(ReachAvoid("goal", "bad"), sat)), ValueIteration(1e-12)
    ).values
    assert ours == pytest.approx(storm_values, abs=1e-8)
