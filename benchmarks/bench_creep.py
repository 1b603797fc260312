"""Worst-case satisfaction on the learning loop's first model: plain sweeps against sweeps
with robust strategy iteration, in the same process.

The model is case (a)'s product (15 x 15 world, ``!Haz U Goal``) built exactly as the second
re-synthesis (after 50 hops) of ``benchmarks/learning_loop.py --seed 7`` builds it, and
the problems are the two worst-case satisfaction solves of a re-synthesis (all actions, and
the goal strategy's ``satisfying`` sub-model). The baseline is the same solver with
``ValueIteration(strategy_iteration=False)`` capped at ``--cap`` sweeps; it prints its
time, residual and how far its values still are from the new solver's.

    python benchmarks/bench_creep.py [--seed 7] [--cap 20000]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import learning_loop

from planner.gp import LandingErrorGP
from planner.imdp import Problem, ReachAvoid, Specification, ValueIteration, solve
from planner.imdp.analysis import accepting_states

learning_loop_resynthesise = learning_loop.resynthesise


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--cap", type=int, default=20_000, help="sweeps for the baseline")
    args = ap.parse_args()
    torch.set_num_threads(1)
    seen = []

    def recording(*a, **k):
        seen.append(learning_loop_resynthesise(*a, **k))
        return seen[-1]

    learning_loop.resynthesise = recording
    loop_args = argparse.Namespace(beta=None, candidates="accepting", batch=50, cap=51)
    learning_loop.run_once(args.seed, loop_args, LandingErrorGP(learning_loop.prior()))
    r = seen[1]
    product = r.product
    spec = Specification(ReachAvoid(accepting_states(product)))
    for name, allowed in (("all actions", None), ("satisfying", r.satisfying.actions)):
        problem = Problem(product.model, spec, allowed)
        t0 = time.perf_counter()
        new = solve(problem, ValueIteration(1e-8))
        t_new = time.perf_counter() - t0
        t0 = time.perf_counter()
        old = solve(
            problem, ValueIteration(1e-8, max_iterations=args.cap, strategy_iteration=False)
        )
        t_old = time.perf_counter() - t0
        gap = float(np.max(np.abs(new.values - old.values)))
        print(
            f"{name}: {product.model.n_states} states; strategy iteration {t_new:.3f} s, "
            f"{new.iterations} sweeps, residual {new.residual:.1e}; plain sweeps {t_old:.3f} s, "
            f"{old.iterations} sweeps, residual {old.residual:.1e}, converged {old.converged}, "
            f"max |value difference| {gap:.3g}; ratio plain/new time = {t_old / t_new:.1f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
