"""Interval soundness audit (issue "soundness"): learned intervals vs. MuJoCo frequencies.

Usage: python benchmarks/audit_intervals.py [--scenario a] [--seed 0] [--samples 200]
       [--velocity-runs 4] [--train-runs 1] [--min-pairs 150] [--attempts 4]

Runs the scenario with seed ``S`` (the training run) and ``--velocity-runs`` more runs
(seeds ``S+1 ..``); fits the landing-error model on the training run's hops (with
``--train-runs K``, on the hops of the first ``K`` runs, as a longer run would have them:
more data, narrower intervals, a harder test); then samples
hops as the navigation loop makes them (:mod:`hopper_sim.experiments.audit`: a departure uniform in
the
cell, a velocity drawn from all runs' departures, the audited action requested, the
controller's backup switch among the loop's allowed actions, each hop counted for the action
it executed) until every audited (cell, action) pair has ``--samples`` executed hops or its
requests reach ``--attempts`` x ``--samples``. The audited pairs are every enabled action of
the cells the training run departed from, then of the cells the other runs departed from
(most visited first) until there are ``--min-pairs``. Prints the fraction of
(cell, action, successor) triples of the full pairs whose empirical frequency lies within
[lower - m, upper + m] (m: the 99 % binomial margin; target >= 0.995), every triple whose
upper bound is 0 that received landings (target: none with more than 2 of 200), and the
worst offenders.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np
from tqdm import tqdm

from hopper_sim.experiments.audit import audit_intervals, collect_run_data, excluded_landings
from hopper_sim.navigation.runner import NavigationRunner
from planner.imdp.grid import ACTIONS
from planner.scenario import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="a")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--velocity-runs", type=int, default=4)
    ap.add_argument("--train-runs", type=int, default=1)
    ap.add_argument("--min-pairs", type=int, default=150)
    ap.add_argument("--attempts", type=int, default=4)
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    runner = NavigationRunner(sc)
    t0 = time.perf_counter()
    runs = [collect_run_data(runner, args.seed + k) for k in range(1 + args.velocity_runs)]
    train = runs[: max(1, args.train_runs)]
    data = replace(
        runs[0],
        positions=np.vstack([r.positions for r in train]),
        errors=np.vstack([r.errors for r in train]),
        actions=np.concatenate([r.actions for r in train]),
        velocities=np.vstack([r.velocities for r in runs]),
    )
    print(
        f"training data (seeds {args.seed}..{args.seed + len(train) - 1}): "
        f"{len(data.positions)} hops; departure velocities from {len(runs)} runs: "
        f"{len(data.velocities)} ({time.perf_counter() - t0:.1f} s)"
    )
    grid = runner.grid
    order = list(np.unique(grid.locate(data.positions)))
    rest = runs[len(train) :]
    others = np.concatenate([grid.locate(r.positions) for r in rest] or [np.zeros(0, int)])
    counts = np.bincount(others, minlength=grid.n_states)[: grid.n_cells]
    for c in np.argsort(-counts, kind="stable"):
        if int(grid.enabled[order].sum()) >= args.min_pairs or counts[c] == 0:
            break
        if c not in order:
            order.append(int(c))
    cells = np.array(sorted(order), dtype=np.int64)
    c_idx, a_idx = np.nonzero(grid.enabled[cells])
    every = np.stack([cells[c_idx], a_idx], axis=1)
    rng = np.random.default_rng(args.seed)
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
        for c, a, succ, k, n in ex[:10]:
            i, j = grid.cell_ij(c)
            where = "out" if succ == grid.out else str(tuple(int(v) for v in grid.cell_ij(succ)))
            print(f"  ({int(i)},{int(j)}) {ACTIONS[a]} -> {where}: {k}/{n}")
    else:
        print("landings in successors the intervals exclude (upper 0): none")
    over = int((ex[:, 3] > 0.01 * ex[:, 4]).sum()) if len(ex) else 0
    print(
        f"excluded triples with more than 1 % of their pair's landings (more than 2 of 200): "
        f"{over} (target 0)"
    )
    r = res.result
    if r is None:
        print("no pair filled up: nothing to audit")
        return
    print(
        f"triples within [lower - m, upper + m]: {r.fraction:.4f} of {r.num_triples} "
        f"(m = {r.margin.max():.3f} at 99 %; target >= 0.995)"
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
