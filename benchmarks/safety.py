"""Safety and guarantee check (issue "learning"): many runs of case (a) with a known reward.

Usage: python benchmarks/safety.py [--runs 50] [--workers 2] [--scenario a] [--seed 0]

Acceptance: no run enters a hazard or leaves the map, and the success rate is at least the
worst-case satisfaction probability reported at the switch to goal reaching (>= P_sat).
Prints per-run outcomes, the violation count, the success rate with its 95 % Wilson interval,
the mean and minimum p_switch, and the runs that left the goal-reaching plan of their switch
(the runner keeps that plan after the switch, see :mod:`hopper_sim.navigation.runner`).
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from tqdm import tqdm

from hopper_sim.navigation.runner import run_single
from planner.scenario import load_scenario


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="a")
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    seeds = [args.seed + k for k in range(args.runs)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        futures = [pool.submit(run_single, sc, s, k) for k, s in enumerate(seeds)]
        ends = [f.result() for f in tqdm(futures, unit="run")]
    wall = time.perf_counter() - t0
    for e in ends:
        print(
            f"run {e.run_index:3d}: {e.outcome:9s} {e.reason:28s} steps {e.steps:4d} "
            f"reward {e.reward:7.1f} switch {e.switch_step} p_switch "
            f"{'-' if e.p_switch is None else f'{e.p_switch:.3f}'} "
            f"{'' if e.left_plan_step is None else f'left plan at {e.left_plan_step} '}"
            f"{e.seconds:.1f} s (longest re-synthesis {e.timings.get('batch_max', 0.0):.2f} s)"
        )
    n = len(ends)
    outcomes = [e.outcome for e in ends]
    hazard = sum(e.reason in ("hazard", "left the map") for e in ends)
    fell = sum(e.reason.startswith("hop failed") for e in ends)
    succ = outcomes.count("success")
    lo, hi = wilson(succ, n)
    p_sw = np.array([e.p_switch for e in ends if e.p_switch is not None])
    secs = np.array([e.seconds for e in ends])
    batch = np.array([e.timings.get("batch_max", 0.0) for e in ends])
    print(f"\n{n} runs in {wall:.0f} s wall")
    print(
        f"run time: median {np.median(secs):.1f} s, max {secs.max():.1f} s (target <= 60 s); "
        f"longest re-synthesis: median {np.median(batch):.2f} s, max {batch.max():.2f} s "
        f"(target <= 1 s)"
    )
    print(f"hazard or off-map: {hazard}  (target 0)   hop failures: {fell}")
    print(f"success {succ}/{n} = {succ / n:.3f} (95 % Wilson [{lo:.3f}, {hi:.3f}])")
    if p_sw.size:
        switched = [e for e in ends if e.p_switch is not None]
        k = sum(e.outcome == "success" for e in switched)
        lo_s, hi_s = wilson(k, len(switched))
        print(f"p_switch: mean {p_sw.mean():.3f}, min {p_sw.min():.3f} over {p_sw.size} switches")
        print(
            f"success after a switch: {k}/{len(switched)} = {k / len(switched):.3f} "
            f"(95 % Wilson [{lo_s:.3f}, {hi_s:.3f}])"
        )
        left = [e for e in switched if e.left_plan_step is not None]
        print(
            f"runs that left the goal-reaching plan of their switch: {len(left)}"
            + (f" (runs {[e.run_index for e in left]})" if left else "")
        )
        for name, rate in (("all runs", succ / n), ("runs that switched", k / len(switched))):
            verdict = "holds" if rate >= p_sw.mean() else "does NOT hold"
            print(f"success rate of {name} >= mean p_switch ({p_sw.mean():.3f}): {verdict}")
    else:
        print("no run switched to goal reaching")


if __name__ == "__main__":
    main()
