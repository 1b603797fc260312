"""End-to-end check of the guarantee: do runs that switch keep the promise ``p_switch``?

Usage: python benchmarks/guarantee.py [--scenario a] [--runs 100] [--workers 2] [--seed 0]

Runs ``--runs`` independent navigation runs (seeds ``seed .. seed + runs - 1``, default
settings, in ``--workers`` processes) and checks the promise of the switch to goal reaching:
a run that switches with worst-case satisfaction probability ``p_switch`` satisfies the task
with probability at least ``p_switch`` (:mod:`planner.intervals` states under which model
and confidence). Prints every run, then: violations (hazard or off the map; target 0), hop
failures, timeouts; for the runs that switched, the success rate with its one-sided 95 %
Clopper-Pearson upper bound against their mean ``p_switch`` (the promise holds when the bound
is at least the mean); and how often a run left the goal-reaching plan of its switch and why
(the landing that took it out, and whether the intervals of the switch allowed that landing).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
from scipy.stats import beta as beta_dist
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))

from traced_runs import run_traced

from planner.scenario import load_scenario


def upper_bound(successes: int, n: int, confidence: float = 0.95) -> float:
    """One-sided Clopper-Pearson upper confidence bound of a binomial rate."""
    if successes >= n:
        return 1.0
    return float(beta_dist.ppf(confidence, successes + 1, n - successes))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="a")
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    sc = load_scenario(args.scenario)
    seeds = [args.seed + k for k in range(args.runs)]
    t0 = time.perf_counter()
    traces = sorted(
        tqdm(run_traced(sc, seeds, args.workers), total=len(seeds), unit="run"),
        key=lambda t: t.seed,
    )
    wall = time.perf_counter() - t0
    for t in traces:
        e = t.end
        left = "" if t.left is None else f" left plan at hop {t.left['hop']} ({t.left['kind']})"
        print(
            f"seed {t.seed:4d}: {e.outcome:9s} {e.reason:26s} steps {e.steps:4d} switch "
            f"{e.switch_step} p_switch {'-' if e.p_switch is None else f'{e.p_switch:.3f}'}"
            f"{left} (longest re-synthesis {e.timings.get('batch_max', 0.0):.2f} s)"
        )
    ends = [t.end for t in traces]
    n = len(ends)
    violations = sum(e.reason in ("hazard", "left the map") for e in ends)
    fell = sum(e.reason.startswith("hop failed") for e in ends)
    timeouts = sum(e.outcome == "timeout" for e in ends)
    print(f"\n{n} runs of scenario {args.scenario} in {wall:.0f} s wall")
    print(f"violations (hazard or off the map): {violations} (target 0); hop failures: {fell}")
    print(f"timeouts: {timeouts}; successes: {sum(e.outcome == 'success' for e in ends)}")
    switched = [t for t in traces if t.end.p_switch is not None]
    print(f"runs that switched to goal reaching: {len(switched)} of {n}")
    if switched:
        p = np.array([t.end.p_switch for t in switched])
        k = sum(t.end.outcome == "success" for t in switched)
        ub = upper_bound(k, len(switched))
        print(
            f"p_switch: mean {p.mean():.4f}, min {p.min():.4f}, max {p.max():.4f}; switch hop: "
            f"median {np.median([t.end.switch_step for t in switched]):.0f}"
        )
        verdict = "holds" if ub >= p.mean() else "does NOT hold"
        print(
            f"success after the switch: {k}/{len(switched)} = {k / len(switched):.4f}, one-sided "
            f"95 % upper bound {ub:.4f} vs mean p_switch {p.mean():.4f}: the promise {verdict}"
        )
        left = [t for t in switched if t.left is not None]
        print(f"runs that left the goal-reaching plan of their switch: {len(left)}")
        kinds = Counter(t.left["kind"] for t in left)
        for kind, count in sorted(kinds.items()):
            what = (
                "landed where the intervals of the switch say impossible (upper bound 0)"
                if kind == "excluded"
                else "landed in a successor the intervals allow, outside the satisfying "
                "sub-model (the adversary's share of p_switch)"
            )
            print(f"  {count}: {what}")
        for t in left:
            lf = t.left
            print(
                f"  seed {t.seed}: hop {lf['hop']} from cell {lf['cell']} {lf['action']} -> "
                f"{lf['landed']} (upper bound {lf['upper']:.3g}); the run ended in "
                f"{t.end.outcome}"
            )
        return 0 if violations == 0 and ub >= p.mean() else 1
    return 0 if violations == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
