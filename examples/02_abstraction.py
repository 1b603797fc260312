"""The interval-MDP abstraction of case study (a), before and after learning (no MuJoCo).

Builds the grid world of scenario ``a``, the transition intervals that the landing-error GP
prior alone allows (wide: the robot knows nothing yet), the product with the automaton of
``!Haz U Goal`` and its worst-case satisfaction probability from the start; then feeds the GP
landing errors of a made-up smooth terrain (as if the robot had hopped everywhere) and shows
how the intervals shrink and the guarantee grows.

    python examples/02_abstraction.py
"""

import numpy as np

from planner import (
    GridWorld,
    LandingErrorGP,
    ProductIMDP,
    TruncatedGaussianNoise,
    cell_error_bounds,
    load_scenario,
    transition_intervals,
    translate,
)


def product_of(scenario, grid, gp, noise):
    bounds = cell_error_bounds(gp, grid)
    intervals = transition_intervals(bounds, grid, noise)
    model = grid.imdp_from_intervals(*intervals.coo(), initial=[scenario.start_cell])
    reward = np.append(np.asarray(scenario.reward_grid, float).ravel(), 0.0)
    return ProductIMDP(model, translate(scenario.formula), reward), intervals


def main() -> None:
    sc = load_scenario("a")
    w = sc.world
    grid = GridWorld(w.nx, w.ny, w.cell, sc.cell_labels, sc.hazard)
    noise = TruncatedGaussianNoise(0.1, 0.2)  # sigma, bound [m] (the MJCF's defaults)

    prior, wide = product_of(sc, grid, LandingErrorGP(), noise)
    p0 = prior.satisfaction().values[prior.initial]
    w0 = float(np.mean(wide.upper - wide.lower))
    print(f"{sc.name}: {sc.formula}, {grid.n_states} grid states, {prior.model.n_states} product")
    print(f"GP prior only: mean interval width {w0:.3f}, P_worst(start) {p0:.3f}")

    rng = np.random.default_rng(0)
    x = rng.uniform(0.0, w.width, size=(400, 2))
    error = 0.35 * np.stack([np.sin(x[:, 1] / 3.0), np.cos(x[:, 0] / 4.0)], axis=1)
    gp = LandingErrorGP(seed=0)
    gp.fit(x, error + rng.normal(0.0, 0.02, size=error.shape))
    learnt, narrow = product_of(sc, grid, gp, noise)
    p1 = learnt.satisfaction().values[learnt.initial]
    w1 = float(np.mean(narrow.upper - narrow.lower))
    print(f"after 400 landings: mean interval width {w1:.3f}, P_worst(start) {p1:.3f}")
    assert w1 < w0 and p1 >= p0


if __name__ == "__main__":
    main()
