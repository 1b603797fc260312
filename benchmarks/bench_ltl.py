"""Benchmark: translate 500 random LTL formulas (depth <= 4, 3 propositions) to DRAs.

Target: <= 30 s in total, pure Python. Prints the total time, its ratio to the target, the
distribution of automaton sizes, the largest and the slowest cases, and, as a baseline
measured in the same process, the ratio against the general construction alone (tableau +
Safra/Piterman determinisation + reduction, without rewriting fast paths or compositional
products) on the first ``--baseline`` formulas.

Usage: ``python benchmarks/bench_ltl.py [--n 500] [--seed 0] [--baseline 100]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from planner.ltl import syntax as s
from planner.ltl.reduce import reduce_rabin
from planner.ltl.simplify import simplify
from planner.ltl.translate import _safra, translate

PROPS = ("a", "b", "c")
UNARY = ("!", "X", "F", "G")
BINARY = ("&", "|", "->", "<->", "xor", "U", "R", "W", "M")
TARGET_S = 30.0


def random_formula(rng: np.random.Generator, depth: int) -> s.Formula:
    """A random formula of depth <= ``depth``: at each inner node a leaf with probability
    0.15, a unary operator with 0.34, a binary one with 0.51; leaves are a proposition
    (0.8 x 3 equally likely) or a constant."""
    if depth == 0 or rng.random() < 0.15:
        if rng.random() < 0.2:
            return [s.TRUE, s.FALSE, *map(s.ap, PROPS)][rng.integers(5)]
        return s.ap(PROPS[rng.integers(3)])
    if rng.random() < 0.4:
        return s.Formula(UNARY[rng.integers(4)], (random_formula(rng, depth - 1),))
    op = BINARY[rng.integers(len(BINARY))]
    return s.Formula(op, (random_formula(rng, depth - 1), random_formula(rng, depth - 1)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--baseline", type=int, default=100, help="formulas for the baseline")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    formulas = [random_formula(rng, 4) for _ in range(args.n)]

    sizes, pairs, times = [], [], []
    t_all = time.perf_counter()
    for f in formulas:
        t0 = time.perf_counter()
        aut = translate(f, PROPS)
        times.append(time.perf_counter() - t0)
        sizes.append(aut.n_states)
        pairs.append(len(aut.pairs))
    total = time.perf_counter() - t_all
    sizes_a, times_a = np.array(sizes), np.array(times)

    print(f"{args.n} random formulas (depth <= 4, propositions {PROPS}, seed {args.seed})")
    print(
        f"total translation time: {total:.2f} s  (target {TARGET_S:.0f} s, "
        f"ratio to target {total / TARGET_S:.3f})"
    )
    print(
        f"per formula: median {np.median(times_a) * 1e3:.1f} ms, "
        f"p90 {np.quantile(times_a, 0.9) * 1e3:.1f} ms, max {times_a.max():.2f} s"
    )
    print(
        "states: "
        + ", ".join(
            f"{name} {v:g}"
            for name, v in [
                ("min", sizes_a.min()),
                ("median", np.median(sizes_a)),
                ("p90", np.quantile(sizes_a, 0.9)),
                ("p99", np.quantile(sizes_a, 0.99)),
                ("max", sizes_a.max()),
            ]
        )
    )
    edges = [1, 2, 3, 5, 10, 20, 50, 100, 1000, 10**9]
    hist = np.histogram(sizes_a, bins=edges)[0]
    print("states histogram:")
    for lo, hi, count in zip(edges[:-1], edges[1:], hist, strict=True):
        label = f"[{lo}, {hi})" if hi < 10**9 else f">= {lo}"
        print(f"  {label:>12}: {count:4d} {'#' * round(60 * count / args.n)}")
    print(
        "pairs: "
        + ", ".join(f"{k}: {v}" for k, v in zip(*np.unique(pairs, return_counts=True), strict=True))
    )
    print("largest automata:")
    for i in np.argsort(-sizes_a, kind="stable")[:5]:
        print(f"  {sizes[i]:6d} states {pairs[i]:2d} pairs {times[i]:7.3f} s  {formulas[i]}")
    print("slowest translations:")
    for i in np.argsort(-times_a, kind="stable")[:5]:
        print(f"  {times[i]:7.3f} s {sizes[i]:6d} states  {formulas[i]}")

    m = min(args.baseline, args.n)
    if m:
        t0 = time.perf_counter()
        base_sizes = []
        for f in formulas[:m]:
            g = simplify(f)
            own = tuple(p for p in PROPS if p in g.propositions())
            base_sizes.append(reduce_rabin(*_safra(g, own))[0].shape[0])
        base = time.perf_counter() - t0
        mine = float(times_a[:m].sum())
        print(
            f"baseline (general construction only) on the first {m} formulas: {base:.2f} s, "
            f"full pipeline {mine:.2f} s, speed-up {base / mine:.2f}x; "
            f"mean states {np.mean(base_sizes):.1f} vs {sizes_a[:m].mean():.1f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
