"""Per-batch update of the landing-error model on the 15 x 15 world, and how far the paper's
sparse GP (50 inducing points) departs from the exact posterior.

    python benchmarks/gp_update.py [--points 500] [--repeats 5]

1. Timing: the median over ``--repeats`` of one update of the direction-aware exact GP
   (:class:`planner.gp.LandingErrorGP`: fit on ``--points`` hops of all eight actions, bounds
   of every (cell, action) at 5 x 5 sample points, transition intervals), against the 0.5 s
   budget of the issue and against the paper's model measured in this process (two sparse
   GPs, 50 k-means inducing points, position only, 15 Adam steps, predictions at the same
   sample points): both ratios printed.
2. Sparse versus exact, fixed hyperparameters (RBF, length scale 2 m, std 0.124 m, noise
   0.1 m; one output): ``--points`` hops of a random walk over the grid, conditioned on in
   batches of 50. The exact posterior std can only shrink as data are added; the sparse one
   (50 inducing points re-placed by k-means at every refit) may grow, and it may fall below
   the exact one (over-confident). Printed: the fraction of (point, batch) pairs whose std
   grew, the largest growth, and the range of sparse / exact std over the cell centres.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sl
import torch
from sklearn.cluster import KMeans

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from planner.gp import LandingErrorGP, rbf_sparse_gp
from planner.imdp.grid import ACTION_OFFSETS, GridWorld
from planner.intervals import cell_error_bounds, cell_sample_points, transition_intervals
from planner.learning import PlannerConfig

BUDGET_S = 0.5
LENGTHSCALE, STD, NOISE = 2.0, 0.124, 0.1


def field(p: np.ndarray, a: np.ndarray) -> np.ndarray:
    x, y = p[:, 0], p[:, 1]
    smooth = np.stack([0.3 * np.sin(x / 2) + 0.1 * np.cos(y / 3), 0.25 * np.cos(x / 3 + y / 2)], 1)
    return smooth - 0.07 * ACTION_OFFSETS[a]


def walk(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Departures of a random walk of hops over the 15 x 15 grid and the actions taken."""
    pos = np.empty((n, 2))
    act = rng.integers(0, 8, size=n)
    xy = np.array([1.5, 7.5])
    for k in range(n):
        pos[k] = xy
        xy = np.clip(np.floor(xy) + 0.5 + ACTION_OFFSETS[act[k]], 0.5, 14.5)
        xy = xy + rng.uniform(-0.3, 0.3, 2)
    return pos, act


def sparse_update(pos, err, query, steps: int, seed: int) -> float:
    """The paper's model: 50 k-means inducing points, 15 Adam steps, prediction at query."""
    t0 = time.perf_counter()
    z = KMeans(n_clusters=50, n_init=1, random_state=seed).fit(pos).cluster_centers_
    model = rbf_sparse_gp(z)
    x = torch.as_tensor(pos)
    y = torch.as_tensor(err.T.copy())
    opt = torch.optim.Adam(model.parameters(), lr=0.05)
    for _ in range(steps):
        opt.zero_grad()
        loss = -model.elbo(x, y).sum() / len(pos)
        loss.backward()
        opt.step()
    model.posterior(x, y).predict(query)
    return time.perf_counter() - t0


def exact_std(pos: np.ndarray, query: np.ndarray) -> np.ndarray:
    def k(a, b):
        d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)
        return STD**2 * np.exp(-0.5 * d2 / LENGTHSCALE**2)

    chol = sl.cho_factor(k(pos, pos) + NOISE**2 * np.eye(len(pos)), lower=True)
    ks = k(query, pos)
    return np.sqrt(np.maximum(STD**2 - (ks * sl.cho_solve(chol, ks.T).T).sum(1), 0.0))


def sparse_std(pos: np.ndarray, query: np.ndarray, seed: int) -> np.ndarray:
    z = KMeans(n_clusters=50, n_init=1, random_state=seed).fit(pos).cluster_centers_
    model = rbf_sparse_gp(z, num_outputs=1, lengthscale=LENGTHSCALE, outputscale=STD**2,
                          noise=NOISE**2)  # fmt: skip
    post = model.posterior(torch.as_tensor(pos), torch.zeros(1, len(pos), dtype=torch.float64))
    return post.predict(query)[1][:, 0]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=500)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    grid = GridWorld(15, 15, 1.0)
    pos, act = walk(args.points, rng)
    err = field(pos, act) + rng.normal(0, 0.1, pos.shape)
    gp = LandingErrorGP()
    times, parts = [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        gp.fit(pos, err, act)
        t1 = time.perf_counter()
        bounds = cell_error_bounds(gp, grid, **PlannerConfig().interval_options())
        ti = transition_intervals(bounds, grid)
        t2 = time.perf_counter()
        times.append(t2 - t0)
        parts.append((t1 - t0, t2 - t1))
    query = cell_sample_points(grid, 5).reshape(-1, 2)
    sparse = statistics.median(sparse_update(pos, err, query, 15, k) for k in range(3))
    s = statistics.median(times)
    print(f"hops: {args.points}, all 8 actions; exact GP, no inducing points")
    print(f"update (fit + bounds of every (cell, action) + intervals): median {s:.3f} s")
    fit_t = statistics.median(p[0] for p in parts)
    int_t = statistics.median(p[1] for p in parts)
    print(f"  fit {fit_t:.3f} s, bounds + intervals {int_t:.3f} s, {ti.lower.size} entries")
    print(f"paper's sparse GP (50 inducing points, position only, 15 Adam steps): {sparse:.3f} s")
    print(f"ratio update / sparse baseline: {s / sparse:.3f}")
    print(f"ratio update / budget {BUDGET_S} s: {s / BUDGET_S:.3f}")

    centres = grid.centres()[: grid.n_cells]
    grew = total = 0
    growth = 0.0
    last_exact = last_sparse = None
    ratios = []
    for n in range(50, args.points + 1, 50):
        ex, sp = exact_std(pos[:n], centres), sparse_std(pos[:n], centres, seed=n)
        if last_exact is not None:
            assert (ex <= last_exact + 1e-12).all()  # conditioning on more data
            grew += int((sp > last_sparse + 1e-9).sum())
            total += sp.size
            growth = max(growth, float((sp - last_sparse).max()))
        last_exact, last_sparse = ex, sp
        ratios.append(sp / ex)
    r = np.concatenate(ratios)
    print(
        f"sparse (50 inducing points, fixed hyperparameters) vs exact posterior std at the "
        f"cell centres over {args.points // 50} batches of 50 hops:"
    )
    print(
        f"  std grew from one batch to the next at {grew} of {total} (point, batch) pairs "
        f"({grew / max(total, 1):.3f}); largest growth {growth:.4f} m (exact: never grows)"
    )
    print(f"  sparse / exact std: min {r.min():.3f}, max {r.max():.3f} (below 1: over-confident)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
