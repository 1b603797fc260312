"""Robust value iteration speed.

1. A 100 x 100 grid world (1 m cells, 8 actions, 9-25 successors per action) times the
   3-state automaton of ``!Haz U Goal`` (about 30k product states): pessimistic maximal
   reachability of the accepting states to 1e-8. Target: <= 1 s.
2. A random model of 100k states x 8 actions x 9 successors (7.2M entries): pessimistic
   reachability to 1e-8, seconds and entries/s (entries x sweeps / second).

Each is compared with a baseline run in the same process: the same value iteration but
with a full per-row re-sort (``np.lexsort``) of every row in every sweep, no cached order.

Run from the repository root: ``PYTHONPATH=. python benchmarks/bench_vi.py [--skip-random]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planner.automaton import RabinAutomaton
from planner.imdp import IMDP, Problem, ReachAvoid, Specification, ValueIteration, solve
from planner.imdp.grid import GridWorld
from planner.imdp.product import ProductIMDP


def grid_intervals(grid: GridWorld, rng: np.random.Generator):
    """Landing spread around each target: a 3x3 or 5x5 window (by a random sigma per cell),
    lower = 0.8 p, upper = min(1, 1.2 p + 1e-3); mass off the world goes to ``out``."""
    cells, acts = np.nonzero(grid.enabled[: grid.n_cells])
    tgt = grid.target_cell[cells, acts]
    ti, tj = grid.cell_ij(tgt)
    sigma = rng.uniform(0.3, 0.9, size=grid.n_cells)[cells]
    half = np.where(sigma < 0.55, 1, 2)
    d = np.arange(-2, 3)
    w = np.exp(-0.5 * (d[None, :] / sigma[:, None]) ** 2) * (np.abs(d)[None, :] <= half[:, None])
    w /= w.sum(axis=1, keepdims=True)
    p = (w[:, :, None] * w[:, None, :]).reshape(len(cells), 25)
    di, dj = np.meshgrid(d, d, indexing="ij")
    si = ti[:, None] + di.ravel()[None, :]
    sj = tj[:, None] + dj.ravel()[None, :]
    succ = grid.cell_index(si, sj)
    keep = p > 0
    row = np.broadcast_to(np.arange(len(cells))[:, None], p.shape)[keep]
    succ, p = succ[keep], p[keep]
    # merge the (several) off-world successors into one ``out`` entry per row
    key = row * grid.n_states + succ
    uniq, inv = np.unique(key, return_inverse=True)
    pm = np.bincount(inv, weights=p)
    r, s = uniq // grid.n_states, uniq % grid.n_states
    lo = 0.8 * pm
    up = np.minimum(1.0, 1.2 * pm + 1e-3)
    return cells[r], acts[r], s, lo, up


def until_automaton() -> RabinAutomaton:
    table = np.array([[0, 1, 2, 1], [1, 1, 1, 1], [2, 2, 2, 2]])
    return RabinAutomaton(("Goal", "Haz"), table, 0, [({1}, set())])


def random_model(rng: np.random.Generator, n: int, n_act: int = 8, k: int = 9) -> IMDP:
    rows = n * n_act
    s = np.repeat(np.arange(n), n_act * k)
    a = np.tile(np.repeat(np.arange(n_act), k), n)
    # k distinct successors per row: a random start and random distinct strides
    base = rng.integers(0, n, size=(rows, 1))
    t = (base + np.cumsum(rng.integers(1, n // (2 * k), size=(rows, k)), axis=1)) % n
    p = rng.dirichlet(np.ones(k), size=rows)
    lo = p * rng.uniform(0.5, 1.0, size=p.shape)
    lo[rng.random(p.shape) < 0.2] = 0.0
    up = np.minimum(1.0, p + rng.uniform(0.0, 0.2, size=p.shape))
    labels = [("goal",) if x else () for x in rng.random(n) < 0.01]
    return IMDP(n, s, a, t.ravel(), lo.ravel(), up.ravel(), n_actions=n_act, labels=labels)


def baseline_vi(model: IMDP, target: np.ndarray, tol: float = 1e-8) -> tuple[np.ndarray, int]:
    """Same fixed point, no cached order: lexsort of all entries in every sweep."""
    m = model
    v = target.astype(float)
    rem = (1.0 - m.row_lower_sum)[m.entry_row]
    it = 0
    while True:
        it += 1
        order = np.lexsort((v[m.successor], m.entry_row))
        lo, gap = m.lower[order], (m.upper - m.lower)[order]
        cs = np.cumsum(gap)
        before = cs - gap - (cs - gap)[m.row_ptr[:-1]][m.entry_row]
        p = lo + np.clip(rem - before, 0.0, gap)
        q = np.add.reduceat(p * v[m.successor[order]], m.row_ptr[:-1])
        vn = np.where(target, 1.0, np.maximum.reduceat(q, m.state_ptr[:-1]))
        res = np.max(np.abs(vn - v))
        v = vn
        if res < tol:
            return v, it


def timed(f):
    t0 = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-random", action="store_true")
    ap.add_argument("--random-states", type=int, default=100_000)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)

    nx = ny = 100
    labels = np.empty((nx, ny), dtype=object)
    labels[:] = [[() for _ in range(ny)] for _ in range(nx)]
    haz = rng.random((nx, ny)) < 0.03
    haz[:10, :10] = False
    for i, j in zip(*np.nonzero(haz), strict=True):
        labels[i, j] = ("Haz",)
    for i in range(90, 100):
        for j in range(90, 100):
            labels[i, j] = ("Goal",)
    grid = GridWorld(nx, ny, 1.0, labels)
    model, t_build = timed(lambda: grid.imdp_from_intervals(*grid_intervals(grid, rng)))
    prod, t_prod = timed(lambda: ProductIMDP(model, until_automaton()))
    acc, t_acc = timed(prod.accepting_states)
    pm = prod.model
    spec = Specification(ReachAvoid(acc))
    sol, t_vi = timed(lambda: solve(Problem(pm, spec), ValueIteration(1e-8)))
    (vb, itb), t_base = timed(lambda: baseline_vi(pm, acc))
    print(
        f"grid 100x100 x 3: {pm.n_states} product states, {pm.n_rows} rows, "
        f"{pm.n_entries} entries (IMDP {t_build:.2f} s, product {t_prod:.2f} s, "
        f"accepting ECs {t_acc:.2f} s)"
    )
    print(
        f"  hopnav solve: {t_vi:.3f} s, {sol.iterations} sweeps, residual {sol.residual:.1e}; "
        f"baseline (re-sort every sweep, no graph precomputation): {t_base:.3f} s, {itb} sweeps; "
        f"ratio baseline/hopnav = {t_base / t_vi:.1f}; max |diff| = "
        f"{np.max(np.abs(vb - sol.values)):.1e}; value at start "
        f"{sol.values[prod.initial]:.4f}"
    )
    if args.skip_random:
        return
    n = args.random_states
    rm, t_rbuild = timed(lambda: random_model(rng, n))
    tgt = rm.states_labelled("goal")
    rsol, t_rvi = timed(
        lambda: solve(Problem(rm, Specification(ReachAvoid(tgt))), ValueIteration(1e-8))
    )
    print(
        f"random {n} states x 8 x 9: {rm.n_entries} entries (build {t_rbuild:.1f} s); "
        f"hopnav solve {t_rvi:.2f} s, {rsol.iterations} sweeps, "
        f"{rm.n_entries * rsol.iterations / t_rvi:.3g} entries/s"
    )
    (rvb, ritb), t_rbase = timed(lambda: baseline_vi(rm, tgt))
    print(
        f"  baseline {t_rbase:.2f} s, {ritb} sweeps; ratio baseline/hopnav = "
        f"{t_rbase / t_rvi:.1f}; max |diff| = {np.max(np.abs(rvb - rsol.values)):.1e}"
    )


if __name__ == "__main__":
    main()
