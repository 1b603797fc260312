"""The interval-MDP abstraction of case study (a), before and after learning (no MuJoCo).

Builds the grid world of scenario ``a``, the transition intervals that the landing-error GP
prior alone allows (wide: the robot knows nothing yet; a uniform push of 0.25 m std and a
local field of 0.06 m, about the shipped scene's), the product with the automaton of
``!Haz U Goal`` and its worst-case satisfaction probability from the start; then feeds the
model the landing errors of a made-up terrain (a uniform push plus a smooth field, 400 hops
of random actions anywhere) and shows how the intervals shrink and the guarantee grows.

    python examples/02_abstraction.py
"""

import numpy as np

from planner import (
    GPConfig,
    GridWorld,
    LandingErrorGP,
    PlannerConfig,
    ProductIMDP,
    TruncatedGaussianNoise,
    cell_error_bounds,
    load_scenario,
    satisfaction,
    transition_intervals,
    translate,
)


def product_of(scenario, grid, gp, noise):
    bounds = cell_error_bounds(gp, grid, **PlannerConfig().interval_options())
    intervals = transition_intervals(bounds, grid, noise)
    model = grid.imdp_from_intervals(*intervals.coo(), initial=[scenario.start_cell])
    return ProductIMDP(model, translate(scenario.formula), scenario.state_rewards), intervals


def main() -> None:
    sc = load_scenario("a")
    grid = GridWorld.from_scenario(sc)
    noise = TruncatedGaussianNoise(0.1, 0.2)  # sigma, bound [m] (the MJCF's defaults)

    prior_settings = GPConfig(field_std=0.06, offset_std=0.25, bias_std=0.05, noise=noise)
    prior, wide = product_of(sc, grid, LandingErrorGP(prior_settings), noise)
    p0 = satisfaction(prior).values[prior.initial]
    w0 = float(np.mean(wide.upper - wide.lower))
    print(f"{sc.name}: {sc.formula}, {grid.n_states} grid states, {prior.model.n_states} product")
    print(f"GP prior only: mean interval width {w0:.3f}, P_worst(start) {p0:.3f}")

    rng = np.random.default_rng(0)
    x = rng.uniform(0.0, sc.world.width, size=(400, 2))
    actions = rng.integers(0, 8, size=400)  # N1, N2, E1, E2, S1, S2, W1, W2
    push = np.array([0.2, -0.1])  # metres, the same everywhere
    error = push + 0.05 * np.stack([np.sin(x[:, 1] / 3.0), np.cos(x[:, 0] / 4.0)], axis=1)
    gp = LandingErrorGP(prior_settings)
    gp.fit(x, error + rng.normal(0.0, 0.1, size=error.shape), actions)
    learnt, narrow = product_of(sc, grid, gp, noise)
    p1 = satisfaction(learnt).values[learnt.initial]
    w1 = float(np.mean(narrow.upper - narrow.lower))
    print(f"after 400 landings: mean interval width {w1:.3f}, P_worst(start) {p1:.3f}")
    assert w1 < w0 and p1 >= p0


if __name__ == "__main__":
    main()
