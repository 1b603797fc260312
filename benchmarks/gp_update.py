"""Per-batch GP update on the 15 x 15 world: refit (warm) + cell error bounds + intervals.

Prints the median time of the sparse update over ``--repeats`` batches and its ratio against
two references measured in this process: an exact GP (gpytorch ``ExactGP``, same kernel,
same number of Adam steps, same prediction points) and the 0.5 s budget of the issue.

    python benchmarks/gp_update.py [--points 1000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import gpytorch
import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from planner.gp import LandingErrorGP
from planner.imdp.grid import GridWorld
from planner.intervals import (
    cell_error_bounds,
    cell_sample_points,
    transition_intervals,
)

BUDGET_S = 0.5


def field(p: np.ndarray) -> np.ndarray:
    x, y = p[:, 0], p[:, 1]
    return np.stack([0.3 * np.sin(x / 2) + 0.1 * np.cos(y / 3), 0.25 * np.cos(x / 3 + y / 2)], 1)


class ExactModel(gpytorch.models.ExactGP):
    def __init__(self, x, y, likelihood):
        super().__init__(x, y, likelihood)
        batch = torch.Size([2])
        self.mean_module = gpytorch.means.ConstantMean(batch_shape=batch)
        self.covar_module = gpytorch.kernels.ScaleKernel(
            gpytorch.kernels.RBFKernel(ard_num_dims=2, batch_shape=batch), batch_shape=batch
        )

    def forward(self, x):
        return gpytorch.distributions.MultivariateNormal(self.mean_module(x), self.covar_module(x))


def exact_update(pos: np.ndarray, err: np.ndarray, query: np.ndarray, steps: int) -> float:
    t0 = time.perf_counter()
    x = torch.as_tensor(pos).unsqueeze(0).expand(2, *pos.shape)
    y = torch.as_tensor(err.T.copy())
    lik = gpytorch.likelihoods.GaussianLikelihood(batch_shape=torch.Size([2])).double()
    model = ExactModel(x, y, lik).double()
    model.train()
    mll = gpytorch.mlls.ExactMarginalLogLikelihood(lik, model)
    opt = torch.optim.Adam(model.parameters(), lr=0.05)
    for _ in range(steps):
        opt.zero_grad()
        loss = -mll(model(x), y).sum()
        loss.backward()
        opt.step()
    model.eval()
    with torch.no_grad():
        q = torch.as_tensor(query).unsqueeze(0).expand(2, *query.shape)
        pred = lik(model(q))
        _ = pred.mean, pred.variance
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    grid = GridWorld(15, 15, 1.0)
    pos = rng.uniform(0, 15, (args.points, 2))
    err = field(pos) + rng.normal(0, 0.1, pos.shape)
    gp = LandingErrorGP(seed=0)
    t0 = time.perf_counter()
    gp.fit(pos, err)
    cold = time.perf_counter() - t0
    sparse, parts = [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        gp.fit(pos, err)
        t1 = time.perf_counter()
        bounds = cell_error_bounds(gp, grid)
        ti = transition_intervals(bounds, grid)
        t2 = time.perf_counter()
        sparse.append(t2 - t0)
        parts.append((t1 - t0, t2 - t1))
    steps = gp.settings.steps
    query = cell_sample_points(grid, 5).reshape(-1, 2)
    exact = [exact_update(pos, err, query, steps)]  # slow: measured once
    s, e = statistics.median(sparse), statistics.median(exact)
    fit_t = statistics.median(p[0] for p in parts)
    int_t = statistics.median(p[1] for p in parts)
    print(f"data points: {args.points}, inducing: {gp.settings.num_inducing}, steps: {steps}")
    print(f"cold first fit ({gp.settings.cold_steps} steps): {cold:.3f} s")
    print(f"sparse update (warm refit + bounds + intervals): {s:.3f} s")
    print(f"  refit {fit_t:.3f} s, bounds + intervals {int_t:.3f} s, {ti.lower.size} entries")
    print(f"exact GP baseline (fit {steps} steps + predict): {e:.3f} s")
    print(f"ratio sparse / exact: {s / e:.3f}")
    print(f"ratio sparse / budget {BUDGET_S} s: {s / BUDGET_S:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
