"""Interval soundness audit (issue "learning"): learned intervals vs. MuJoCo frequencies.

Usage: python benchmarks/audit_intervals.py [--scenario a] [--seed 0] [--samples 200]
       [--pairs 120 | --pairs all] [--attempts 4]

Trains the GPs on one navigation run's data, then samples hops as the navigation loop makes
them (:mod:`hopper_sim.audit`: the audited action requested, the controller's backup switch
among the loop's allowed actions, each hop counted for the action it executed) until every
audited (cell, action) pair has ``--samples`` executed hops or its requests reach
``--attempts`` x ``--samples``. Prints how many pairs could not be filled, and the fraction of
(cell, action, successor) triples of the full pairs whose empirical frequency lies within
[lower - m, upper + m] (m: the 99 % binomial margin), the target being >= 0.99, and the worst
offenders. ``--pairs N`` audits N enabled pairs drawn at random (seeded), always including
every pair of the cells the run visited; ``all`` audits every one.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from tqdm import tqdm

from hopper_sim.audit import audit_intervals, collect_run_data, excluded_landings
from hopper_sim.runner import NavigationRunner
from planner.imdp.grid import ACTIONS
from planner.scenario import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="a")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--pairs", default="120")
    ap.add_argument("--attempts", type=int, default=4)
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
    print(
        f"auditing {len(every)} (cell, action) pairs: {args.samples} executed hops each, at "
        f"most {args.attempts * args.samples} requests each"
    )
    t0 = time.perf_counter()
    with tqdm(unit="decision") as bar:
        res = audit_intervals(
            runner,
            data,
            every,
            samples=args.samples,
            rng=rng,
            attempts=args.attempts,
            progress=bar.update,
        )
    print(
        f"audit: {res.decisions} controller decisions, {res.hops} hops simulated, "
        f"{res.failures} failed, {time.perf_counter() - t0:.1f} s"
    )
    rate = np.bincount(every[:, 1], weights=res.as_requested, minlength=len(ACTIONS)) / np.maximum(
        np.bincount(every[:, 1], weights=res.requests, minlength=len(ACTIONS)), 1
    )
    print(
        "requests executed as requested (not replaced by the backup), by action: "
        + ", ".join(f"{ACTIONS[a]} {rate[a]:.2f}" for a in range(len(ACTIONS)))
    )
    empty = res.executed == 0
    short = ~res.full & ~empty
    print(
        f"pairs filled: {int(res.full.sum())} of {len(every)}; never executed: "
        f"{int(empty.sum())}; partly filled: {int(short.sum())} (the controller's backup "
        "switch chose another allowed action from the other sampled states)"
    )
    for name, mask in (("never executed", empty), ("partly filled", short)):
        by_action = np.bincount(every[mask, 1], minlength=len(ACTIONS))
        listed = ", ".join(f"{ACTIONS[a]} {n}" for a, n in enumerate(by_action) if n)
        print(f"  {name} by action: {listed or '-'}")
    if short.any():
        fill = res.executed[short]
        print(
            f"  partly filled pairs' executed hops: min {fill.min()}, median {np.median(fill):.0f}"
        )
    if res.partial is not None:
        p = res.partial
        print(
            f"partly filled pairs (own margins): {p.fraction:.4f} of {p.num_triples} triples "
            f"within [lower - m, upper + m]"
        )
    ex = excluded_landings(res, every)
    if len(ex):
        freq = ex[:, 3] / np.maximum(ex[:, 4], 1)
        print(
            f"landings in successors the intervals exclude (upper 0): {int(ex[:, 3].sum())} "
            f"hops in {len(ex)} triples, max frequency {freq.max():.3f}, by action: "
            + ", ".join(
                f"{ACTIONS[a]} {int(ex[ex[:, 1] == a, 3].sum())}" for a in np.unique(ex[:, 1])
            )
        )
        for c, a, succ, k, n in ex[:5]:
            i, j = grid.cell_ij(c)
            where = "out" if succ == grid.out else str(tuple(int(v) for v in grid.cell_ij(succ)))
            print(f"  ({int(i)},{int(j)}) {ACTIONS[a]} -> {where}: {k}/{n}")
    else:
        print("landings in successors the intervals exclude (upper 0): none")
    r = res.result
    if r is None:
        print("no pair filled up: nothing to audit")
        return
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
