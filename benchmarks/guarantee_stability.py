"""Stability of the guarantee: does the worst-case probability at the start grow with data, or
does it jump about?

Usage: python benchmarks/guarantee_stability.py [--scenario a] [--runs 50] [--workers 2]
       [--seed 0] [--drop 0.3]

Runs ``--runs`` navigation runs (seeds ``seed ..``, default settings) and records the
worst-case satisfaction probability of the start state (P̌ at the start) after every
re-synthesis of each run. Prints, per run, that sequence; then the fraction of consecutive
re-syntheses (pairs within a run) that lower P̌ at the start by more than ``--drop`` (the
fidelity issue's target: below 5 %), and the fraction of runs that switch to goal reaching
(target: at least 90 %).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))

from traced_runs import run_traced

from planner.scenario import load_scenario


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="a")
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--drop", type=float, default=0.3)
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    seeds = [args.seed + k for k in range(args.runs)]
    t0 = time.perf_counter()
    traces = sorted(
        tqdm(run_traced(sc, seeds, args.workers), total=len(seeds), unit="run"),
        key=lambda t: t.seed,
    )
    wall = time.perf_counter() - t0
    pairs = drops = 0
    for t in traces:
        p = np.array(t.p_start)
        d = np.diff(p)
        pairs += d.size
        drops += int((d < -args.drop).sum())
        seq = " ".join(f"{v:.2f}" for v in p)
        print(
            f"seed {t.seed:4d}: {t.end.outcome:9s} switch {t.end.switch_step} P_start per "
            f"re-synthesis: {seq}"
        )
    switched = sum(t.end.switch_step is not None for t in traces)
    n = len(traces)
    print(f"\n{n} runs of scenario {args.scenario} in {wall:.0f} s wall")
    frac = drops / pairs if pairs else 0.0
    print(
        f"consecutive re-syntheses lowering P_start by more than {args.drop}: {drops} of "
        f"{pairs} = {frac:.4f} (target < 0.05)"
    )
    print(
        f"runs that switch to goal reaching: {switched} of {n} = {switched / n:.3f} (target >= 0.9)"
    )
    first = np.array([t.p_start[0] for t in traces if t.p_start])
    print(f"P_start at the first synthesis (prior): min {first.min():.3f}, max {first.max():.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
