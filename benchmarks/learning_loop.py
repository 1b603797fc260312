"""Pure-planning learning loop on the case (a) layout (15 x 15), no MuJoCo.

Hops are simulated from the abstraction's own landing model: landing = target centre +
e(departure, action) + nu, with a smooth synthetic error field (amplitude about 0.12 m) plus an
undershoot along the hop (0.07 m for one cell, 0.18 m for two) as e and the truncated-Gaussian
noise nu; the landing-error prior knows the undershoot to 0.05 m (:func:`prior`). After
every batch the loop calls :func:`planner.learning.resynthesise` (GP refit, intervals,
product, synthesis) and prints the per-batch timings, their worst total against the 1 s budget
of the issue (ratio), and the run's outcome. The layout is the shipped scenario ``a``.

    python benchmarks/learning_loop.py [--seed 0] [--runs 1] [--beta B] [--batch 50] [--cap 500]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from planner.automaton import RabinAutomaton
from planner.gp import GPConfig, LandingErrorGP
from planner.imdp.grid import ACTION_OFFSETS, GridWorld
from planner.intervals import TruncatedGaussianNoise
from planner.learning import PlannerConfig, resynthesise
from planner.ltl.translate import translate
from planner.policy import SwitchingPolicy
from planner.scenario import load_scenario

BUDGET_S = 1.0


def case_a() -> tuple[GridWorld, np.ndarray, int]:
    """The shipped case (a): grid with labels, reward per grid state, start cell."""
    sc = load_scenario("a")
    return GridWorld.from_scenario(sc), sc.state_rewards, sc.start_cell


def until_automaton() -> RabinAutomaton:
    """The automaton of case (a)'s formula ``!Haz U Goal``."""
    return translate(load_scenario("a").formula)


BIAS = -0.07 * np.sign(ACTION_OFFSETS) * np.abs(ACTION_OFFSETS) ** 1.4
"""Undershoot along the hop per action (m): 0.07 for one cell, 0.18 for two, as measured."""


def field(p: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The synthetic mean landing error (m): a smooth field of the terrain's size (about
    0.12 m) plus the controller's undershoot of the action."""
    x, y = p[:, 0], p[:, 1]
    smooth = np.stack([0.3 * np.sin(x / 2) + 0.1 * np.cos(y / 3), 0.25 * np.cos(x / 3 + y / 2)], 1)
    return 0.4 * smooth + BIAS[np.asarray(a, dtype=int)]


def prior() -> GPConfig:
    """The landing-error prior the runner would use for such a robot: the controller's bias
    known to 0.05 m, a field of std 0.125 m and length scale 2 m."""
    return GPConfig(bias_mean=BIAS, bias_std=0.05, residual_std=0.05)


def run_once(seed: int, args: argparse.Namespace, gp: LandingErrorGP) -> dict:
    """One simulated run from the start cell; ``gp`` is reset (its data are per run)."""
    grid, w, start = case_a()
    rng = np.random.default_rng(seed)
    noise = TruncatedGaussianNoise()
    gp.reset()
    settings = PlannerConfig(beta=args.beta, candidates=args.candidates)
    policy = SwitchingPolicy(settings.switching)
    pos, err, acts = np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, dtype=int)
    cell = start
    xy = grid.centres()[cell]
    ps, r = None, None
    timings, phases, reward, outcome = [], {}, 0.0, "timeout"
    t_run = time.perf_counter()
    step = 0
    for step in tqdm(range(args.cap), desc=f"seed {seed}", leave=False):
        if step % args.batch == 0:
            r = resynthesise(
                gp, grid, until_automaton(), pos, err, actions=acts, reward=w, initial_cell=cell,
                current_state=ps, settings=settings, previous=r,
            )  # fmt: skip
            ps = r.product.entry_state(cell) if ps is None else ps
            policy.resynthesise(
                r.exploration, r.goal, r.satisfaction.values, r.fallback, r.rl, tour=r.tour
            )
            timings.append(r.timings | {"detail": r.synthesis_detail})
        d = policy.decide(ps, rng)
        phases[d.phase] = phases.get(d.phase, 0) + 1
        target = grid.target_centres[cell, d.action]
        land = target + field(xy[None], [d.action])[0] + noise.sample(rng, 2)
        pos, err = np.vstack([pos, xy]), np.vstack([err, land - target])
        acts = np.append(acts, d.action)
        xy, cell = land, int(grid.locate(land))
        ps = r.product.step(ps, cell)
        reward += w[cell]
        if "Haz" in grid.labels[cell]:
            outcome = "violation"
        elif "Goal" in grid.labels[cell]:
            outcome = "success"
        if outcome != "timeout":
            break
    return {
        "seed": seed,
        "outcome": outcome,
        "hops": step + 1,
        "reward": reward,
        "phases": phases,
        "switch_step": policy.switch_step,
        "switch_probability": policy.switch_probability,
        "timings": timings,
        "run_s": time.perf_counter() - t_run,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--runs", type=int, default=1, help="seeds seed .. seed + runs - 1")
    ap.add_argument("--beta", type=float, default=None, help="default: union bound, delta 0.01")
    ap.add_argument("--candidates", choices=("nonviolating", "accepting"), default="nonviolating")
    ap.add_argument("--batch", type=int, default=50)
    ap.add_argument("--cap", type=int, default=500)
    ap.add_argument("--verbose", action="store_true", help="print every batch's timings")
    args = ap.parse_args()
    torch.set_num_threads(1)
    gp = LandingErrorGP(prior())
    # one-time costs of a process (numba's compiled kernels load on the first solve) out of
    # the per-batch timings, as the old GP warm-up did for torch
    t0 = time.perf_counter()
    grid, w, start = case_a()
    z = np.zeros((0, 2))
    resynthesise(gp, grid, until_automaton(), z, z, reward=w, initial_cell=start)
    print(f"one-time warm-up (first synthesis of the process): {time.perf_counter() - t0:.2f} s")
    results = [run_once(args.seed + k, args, gp) for k in range(args.runs)]
    totals = []
    for res in results:
        tot = [t["gp_fit"] + t["abstraction"] + t["synthesis"] for t in res["timings"]]
        totals += tot
        print(
            f"seed {res['seed']}: {res['outcome']} after {res['hops']} hops, reward "
            f"{res['reward']:.1f}, phases {res['phases']}, switch at hop {res['switch_step']} "
            f"(worst-case probability {res['switch_probability']}), run {res['run_s']:.2f} s, "
            f"per-batch max {max(tot):.3f} s"
        )
        if args.verbose:
            for k, t in enumerate(res["timings"]):
                main_t = ", ".join(
                    f"{n} {t[n]:.3f} s" for n in ("gp_fit", "abstraction", "synthesis")
                )
                detail = ", ".join(f"{n} {v:.3f}" for n, v in t["detail"].items())
                print(f"  batch {k}: {main_t} ({detail})")
    outcomes = [res["outcome"] for res in results]
    switched = [res["switch_probability"] for res in results if res["switch_probability"]]
    print(
        f"outcomes: {outcomes.count('success')} success, {outcomes.count('violation')} "
        f"violation, {outcomes.count('timeout')} timeout of {len(results)}"
    )
    if switched:
        print(f"worst-case probability at the switch: min {min(switched):.3f}")
    print(f"per-batch total: median {np.median(totals):.3f} s, max {max(totals):.3f} s")
    print(f"ratio median per-batch / budget {BUDGET_S} s: {np.median(totals) / BUDGET_S:.3f}")
    print(f"ratio max per-batch / budget {BUDGET_S} s: {max(totals) / BUDGET_S:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
