"""Decision latency of the leg-angle controller (all 8 actions in one batch) on one core,
against a baseline that solves each action separately with scipy.optimize (L-BFGS-B with
bounds, gradients by torch autograd, 3 starts per action).

    python benchmarks/bench_controller.py [--checkpoint PATH] [--decisions 200]

Prints the median latency of both, their ratio, and the mean best cost each reaches (the
batched method must not buy its speed with worse solutions).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from scipy.optimize import minimize

from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT, load_checkpoint
from hopper_sim.controller.controller import LegAngleController
from hopper_sim.controller.hop_model import heading_frame, rotate_xy

OFFSETS = np.array([[0, 1], [0, 2], [1, 0], [2, 0], [0, -1], [0, -2], [-1, 0], [-2, 0]], float)


def states(rng: np.random.Generator, n: int, speed: float) -> list[tuple[np.ndarray, ...]]:
    """Random interstitial states on the operating shell |v| = speed, random headings."""
    out = []
    for _ in range(n):
        gamma = rng.uniform(0.2, 0.9)
        psi = rng.uniform(-np.pi, np.pi)
        v = speed * np.array([np.cos(gamma) * np.cos(psi), np.cos(gamma) * np.sin(psi), 0.0])
        v[2] = -speed * np.sin(gamma)
        pos = rng.uniform(0, 1, 2) + 5
        out.append((pos, v, np.floor(pos) + 0.5 + OFFSETS))
    return out


def scipy_solve(ctl: LegAngleController, pos, vel, targets) -> tuple[np.ndarray, np.ndarray]:
    """Each action on its own: multi-start L-BFGS-B on the same cost."""
    opt = ctl.optimizer
    s, vz, psi = heading_frame(vel)
    disp = rotate_xy(targets - pos, -psi)
    unit = (targets - pos) / np.linalg.norm(targets - pos, axis=1, keepdims=True)
    vdes = np.concatenate([ctl.steady.speed * unit, np.full((8, 1), ctl.steady.vz)], axis=1)
    vdes = rotate_xy(vdes, -psi)
    lo, hi = opt.lower.numpy().astype(float), opt.upper.numpy().astype(float)
    costs, angles = np.empty(8), np.empty((8, 2))
    for k in range(8):
        t = torch.tensor(disp[k : k + 1], dtype=torch.float32)
        v = torch.tensor(vdes[k : k + 1], dtype=torch.float32)

        def f(x, t=t, v=v):
            a = torch.tensor(x[None], dtype=torch.float32, requires_grad=True)
            c = opt.cost(float(s), float(vz), a, t, v).sum()
            c.backward()
            return float(c.detach()), a.grad[0].double().numpy()

        best = None
        for b0 in (-1.0, 0.0, 1.0):
            r = minimize(
                f, [1.25, b0], jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi, strict=True))
            )
            if best is None or r.fun < best.fun:
                best = r
        costs[k], angles[k] = best.fun, best.x
    return costs, angles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default=str(DEFAULT_CHECKPOINT))
    ap.add_argument("--decisions", type=int, default=200)
    ap.add_argument("--baseline-decisions", type=int, default=10)
    args = ap.parse_args()
    torch.set_num_threads(1)
    ckpt = load_checkpoint(args.checkpoint)
    ctl = LegAngleController.from_checkpoint(ckpt)
    speed = float(ckpt.metadata["nominal_speed"])
    rng = np.random.default_rng(0)
    cases = states(rng, args.decisions, speed)
    for pos, vel, tg in cases[:5]:  # warm-up
        ctl.decide(pos, vel, range(8), tg, 0)
    lat, ours = [], []
    for pos, vel, tg in cases:
        t0 = time.perf_counter()
        d = ctl.decide(pos, vel, range(8), tg, 0)
        lat.append(time.perf_counter() - t0)
        ours.append(d.costs)
    base_lat, base = [], []
    for pos, vel, tg in cases[: args.baseline_decisions]:
        t0 = time.perf_counter()
        c, _ = scipy_solve(ctl, pos, vel, tg)
        base_lat.append(time.perf_counter() - t0)
        base.append(c)
    nb = len(base)
    ours_a, base_a = np.array(ours), np.array(base)
    m_ours, m_base = 1e3 * np.median(lat), 1e3 * np.median(base_lat)
    print("decision latency, 8 actions, torch threads = 1")
    p95 = 1e3 * np.percentile(lat, 95)
    print(f"  batched grid + Newton : median {m_ours:8.2f} ms  p95 {p95:8.2f} ms  (n={len(lat)})")
    print(f"  scipy L-BFGS-B each   : median {m_base:8.2f} ms  (n={nb})")
    print(f"  speed-up ratio (baseline / batched): {m_base / m_ours:.1f}x")
    print(
        f"  mean best cost on the same {nb} decisions: batched {ours_a[:nb].mean():.4f}, "
        f"scipy {base_a.mean():.4f}"
    )
    for tol in (1e-3, 1e-2):
        frac = np.mean(ours_a[:nb] <= base_a + tol)
        print(f"  batched cost <= scipy cost + {tol:g} in {frac:.1%} of the {base_a.size} solves")


if __name__ == "__main__":
    main()
