"""The first synthesis of every shipped scenario (the prior landing-error model, no data)
is certified: the worst-case bracket closes at the default settings, for the runner's
product-interval abstraction and for the decoupled one built from the same bounds.

On scenarios b and d the prior's intervals have zero lower bounds almost everywhere and tiny
forced ones (1e-11 .. 1e-7), so the values from below are ~1e-38 and move by ~1e-11 per
sweep while the bound from above sits at 1 on 190 of the 225 free states (an end component
whose exits read its own upper bound); interval iteration stalls with every state wide.
"""

import numpy as np
import pytest

from hopper_sim.navigation.runner import NavigationRunner
from planner.gp.landing import LandingErrorGP
from planner.imdp.analysis import satisfaction
from planner.imdp.decoupled import DecoupledProduct, grid_decoupled_model
from planner.imdp.product import ProductIMDP
from planner.intervals import cell_error_bounds, transition_intervals
from planner.ltl.translate import translate
from planner.scenario import load_scenario


@pytest.mark.parametrize("name", ["a", "b", "c", "d"])
def test_prior_abstraction_is_certified(name):
    sc = load_scenario(name)
    runner = NavigationRunner(sc)
    gp = LandingErrorGP(runner.gp_settings)
    gp.fit(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, dtype=np.int64))
    grid, settings = runner.grid, runner.synthesis_settings
    bounds = cell_error_bounds(gp, grid, **settings.interval_options())
    ti = transition_intervals(bounds, grid, settings.noise)
    product = ProductIMDP(grid.imdp_from_intervals(*ti.coo()), translate(sc.formula))
    decoupled = DecoupledProduct(
        grid_decoupled_model(grid, bounds, settings.noise), translate(sc.formula)
    )
    for sol, initial in (
        (satisfaction(product), product.initial),
        (decoupled.satisfaction(), decoupled.initial),
    ):
        assert sol.converged
        assert sol.error < 1e-8
        assert np.all(sol.lower <= sol.upper)
        # no data: nothing is guaranteed at the start
        assert sol.upper[initial] < 1e-8
