"""Worst-case satisfaction at the start: product-interval IMDP vs orthogonally decoupled IMDP.

The case-study abstraction of scenario ``a`` (``!Haz U Goal``) is built twice from the same
landing-error GP, fitted on the hops of real runs of the navigation runner (MuJoCo, the
runner's own loop; an observer collects every hop's departure position, landing error
``landing - target`` and executed action):

* the **product-interval** IMDP of the runner (:func:`planner.intervals.transition_intervals`:
  per-successor bounds that are products of the per-axis bounds; the adversary may pick
  any joint distribution inside them);
* the **decoupled** IMDP (:func:`planner.imdp.decoupled.grid_decoupled_model`: the same
  per-axis bounds, the adversary picks one distribution per axis, the transition is their
  product).

For 0 (the prior), 50, 100 and 150 hops of data it prints ``P_check`` at the initial
product state of both (certified; the decoupled one is exact for its adversary) and checks
that the decoupled value is never below the product-interval one and strictly above it for
at least one data size. The landing-error model (its prior from the scene), the bounds
(``delta``, samples per axis) and the noise are the runner's. The decoupled model takes the
known noise nu only, not the model's per-action residual that the product-interval
intervals add to it, so its values are not yet a guarantee under that model (the runner
does not use it).

Run from the repository root:
``PYTHONPATH=. python benchmarks/bench_odimdp.py [--seeds 0 1 2] [--hops 50 100 150]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from hopper_sim.navigation.events import Observer
from hopper_sim.navigation.runner import NavigationRunner
from planner.gp.landing import LandingErrorGP
from planner.imdp.analysis import satisfaction
from planner.imdp.decoupled import DecoupledProduct, grid_decoupled_model
from planner.imdp.grid import ACTIONS
from planner.imdp.product import ProductIMDP
from planner.intervals import cell_error_bounds, transition_intervals
from planner.ltl.translate import translate
from planner.scenario import load_scenario


class HopCollector(Observer):
    """Collects the departure position and landing error of every hop."""

    def __init__(self) -> None:
        self.positions: list[np.ndarray] = []
        self.errors: list[np.ndarray] = []
        self.actions: list[int] = []

    def on_hop(self, event) -> None:
        self.positions.append(np.asarray(event.start_pos, dtype=float))
        self.errors.append(np.asarray(event.landing, float) - np.asarray(event.target, float))
        self.actions.append(ACTIONS.index(event.executed_action))


def collect(
    scenario, n_hops: int, seeds: list[int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    obs = HopCollector()
    runner = NavigationRunner(scenario, observer=obs)
    t0 = time.perf_counter()
    for seed in seeds:
        if len(obs.positions) >= n_hops:
            break
        runner.run(seed=seed)
    if len(obs.positions) < n_hops:
        raise SystemExit(f"only {len(obs.positions)} hops from seeds {seeds}; give more --seeds")
    data = np.array(obs.positions), np.array(obs.errors), np.array(obs.actions, dtype=np.int64)
    return (*data, time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="a")
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    ap.add_argument("--hops", type=int, nargs="+", default=[50, 100, 150])
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    positions, errors, actions, t_runs = collect(sc, max(args.hops), args.seeds)
    print(f"scenario {args.scenario}: {len(positions)} hops from real runs ({t_runs:.1f} s)")
    runner = NavigationRunner(sc)  # the runner's grid, settings and noise
    grid, settings = runner.grid, runner.synthesis_settings
    gp_settings = runner.gp_settings
    automaton = translate(sc.formula)
    enabled_s, enabled_a = np.nonzero(grid.enabled[: grid.n_cells])
    rows = []
    for n in [0, *args.hops]:
        gp = LandingErrorGP(gp_settings)
        gp.fit(positions[:n].reshape(-1, 2), errors[:n].reshape(-1, 2), actions[:n])
        bounds = cell_error_bounds(gp, grid, **settings.interval_options())
        t0 = time.perf_counter()
        ti = transition_intervals(bounds, grid, settings.noise)
        model = grid.imdp_from_intervals(*ti.coo(), initial=[sc.start_cell])
        pint = ProductIMDP(model, automaton)
        p_sol = satisfaction(pint)
        t1 = time.perf_counter()
        dm = grid_decoupled_model(
            grid,
            enabled_s,
            enabled_a,
            bounds.lower[enabled_s, enabled_a],
            bounds.upper[enabled_s, enabled_a],
            settings.noise,
            initial=[sc.start_cell],
        )
        dp = DecoupledProduct(dm, automaton)
        d_sol = dp.satisfaction()
        t2 = time.perf_counter()
        rows.append(
            (
                n,
                p_sol.values[pint.initial],
                d_sol.values[dp.initial],
                p_sol,
                d_sol,
                t1 - t0,
                t2 - t1,
            )
        )
        print(
            f"  {n:3d} hops: P_check at the start  product-interval {rows[-1][1]:.6f} "
            f"[{p_sol.lower[pint.initial]:.6f}, {p_sol.upper[pint.initial]:.6f}]  "
            f"decoupled {rows[-1][2]:.6f} "
            f"[{d_sol.lower[dp.initial]:.6f}, {d_sol.upper[dp.initial]:.6f}]  "
            f"gain {rows[-1][2] - rows[-1][1]:+.6f}  ({t1 - t0:.2f} s / {t2 - t1:.2f} s)"
        )
    data = [r for r in rows if r[0] > 0]
    never_lower = all(r[2] >= r[1] - 1e-8 for r in rows)
    higher = [r[0] for r in data if r[2] > r[1] + 1e-8]
    print(
        f"decoupled never below product-interval: {never_lower}; strictly higher at "
        f"{higher or 'no'} hops"
    )


if __name__ == "__main__":
    main()
