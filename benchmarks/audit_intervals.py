"""Interval soundness audit (issue "learning"): learned intervals vs. MuJoCo frequencies.

Usage: python benchmarks/audit_intervals.py [--scenario a] [--seed 0] [--samples 200]
       [--pairs 120 | --pairs all]

Trains the GPs on one navigation run's data, then samples each audited (cell, action) pair
``--samples`` times in MuJoCo and prints the fraction of (cell, action, successor) triples
whose empirical frequency lies within [lower - m, upper + m] (m: 99 % Clopper-Pearson margin),
the target being >= 0.99, and the worst offenders. ``--pairs N`` audits N enabled pairs drawn
at random (seeded), always including the pairs the run used; ``all`` audits every one.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from tqdm import tqdm

from hopper_sim.audit import audit_intervals, collect_run_data
from hopper_sim.runner import NavigationRunner
from planner.imdp.grid import ACTIONS
from planner.scenario import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="a")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--pairs", default="120")
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    runner = NavigationRunner(sc)
    t0 = time.perf_counter()
    data = collect_run_data(runner, args.seed)
    print(f"run data: {len(data.positions)} hops ({time.perf_counter() - t0:.1f} s)")
    grid = runner.grid
    cells, acts = np.nonzero(grid.enabled[: grid.n_cells])
    every = np.stack([cells, acts], axis=1)
    rng = np.random.default_rng(args.seed)
    if args.pairs != "all":
        used = np.unique(grid.locate(data.positions))
        on_route = np.isin(every[:, 0], used)
        rest = np.flatnonzero(~on_route)
        n_more = max(0, int(args.pairs) - int(on_route.sum()))
        pick = np.concatenate([np.flatnonzero(on_route), rng.permutation(rest)[:n_more]])
        every = every[np.sort(pick)]
    print(f"auditing {len(every)} (cell, action) pairs x {args.samples} hops")
    t0 = time.perf_counter()
    with tqdm(total=len(every) * args.samples, unit="hop") as bar:
        res = audit_intervals(
            runner.env, data, every, samples=args.samples, rng=rng, progress=bar.update
        )
    r = res.result
    print(f"audit: {res.hops} hops, {res.failures} failed, {time.perf_counter() - t0:.1f} s")
    print(
        f"triples within [lower - m, upper + m]: {r.fraction:.4f} of {r.num_triples} "
        f"(m = {r.margin.max():.3f} at 99 %; target >= 0.99)"
    )
    print("worst offenders: cell (i,j) action -> successor: freq vs [lower, upper]")
    for o in r.offenders[:10]:
        i, j = grid.cell_ij(o.state)
        succ = (
            "out"
            if o.successor == grid.out
            else str(tuple(int(v) for v in grid.cell_ij(o.successor)))
        )
        print(
            f"  ({int(i)},{int(j)}) {ACTIONS[o.action]} -> {succ}: {o.frequency:.3f} vs "
            f"[{o.lower:.3f}, {o.upper:.3f}] (outside by {o.excess:.3f})"
        )


if __name__ == "__main__":
    main()
