"""Robust value iteration speed.

1. A 100 x 100 grid world (1 m cells, 8 actions, 9-25 successors per action) times the
   3-state automaton of ``!Haz U Goal`` (about 30k product states): pessimistic maximal
   reachability of the accepting states to 1e-8. Target: <= 1 s.
2. A random model of 100k states x 8 actions x 9 successors (7.2M entries; 5% goal, 30%
   bad states): pessimistic ``(!bad) U goal`` to 1e-8, seconds and entries/s (entries x
   sweeps / second).

Each is compared with a baseline run in the same process: the time of one sweep of the
same robust update with a full re-sort (``np.lexsort``) of every row, no cached order and no
graph precomputation (timed over 3 sweeps; the ratio is per sweep).

The solver's compiled kernels (numba) are loaded from numba's cache, or compiled on a fresh
checkout, by the first solve in a process; a small warm-up solve does that before the timed
solves and its time is printed. ``--seed`` draws another hazard layout and other intervals
(the sweeps needed vary with the layout).

Run from the repository root:
``PYTHONPATH=. python benchmarks/bench_vi.py [--seed 0] [--skip-random] [--skip-grid]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planner.automaton import RabinAutomaton
from planner.imdp import IMDP, Problem, ReachAvoid, Specification, ValueIteration, solve
from planner.imdp.grid import GridWorld
from planner.imdp.product import ProductIMDP


def grid_intervals(grid: GridWorld, rng: np.random.Generator, sigma=(0.3, 0.9)):
    """Landing spread around each target: a 3x3 or 5x5 window (by a random sigma per cell),
    lower = 0.8 p, upper = min(1, 1.2 p + 1e-3); mass off the world goes to ``out``."""
    cells, acts = np.nonzero(grid.enabled[: grid.n_cells])
    tgt = grid.target_cell[cells, acts]
    ti, tj = grid.cell_ij(tgt)
    sigma = rng.uniform(*sigma, size=grid.n_cells)[cells]
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
    kind = rng.random(n)
    labels = [("goal",) if x < 0.05 else ("bad",) if x < 0.35 else () for x in kind]
    return IMDP(n, s, a, t.ravel(), lo.ravel(), up.ravel(), n_actions=n_act, labels=labels)


def baseline_sweep_seconds(model: IMDP, target: np.ndarray, sweeps: int = 3) -> float:
    """Seconds per sweep of the same robust Bellman update without a cached order: every
    row is re-sorted (``np.lexsort``) in every sweep. Timed over ``sweeps`` sweeps."""
    m = model
    v = target.astype(float)
    rem = (1.0 - m.row_lower_sum)[m.entry_row]
    t0 = time.perf_counter()
    for _ in range(sweeps):
        order = np.lexsort((v[m.successor], m.entry_row))
        lo, gap = m.lower[order], (m.upper - m.lower)[order]
        cs = np.cumsum(gap)
        before = cs - gap - (cs - gap)[m.row_ptr[:-1]][m.entry_row]
        p = lo + np.clip(rem - before, 0.0, gap)
        q = np.add.reduceat(p * v[m.successor[order]], m.row_ptr[:-1])
        v = np.where(target, 1.0, np.maximum.reduceat(q, m.state_ptr[:-1]))
    return (time.perf_counter() - t0) / sweeps


def timed(f):
    t0 = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-random", action="store_true")
    ap.add_argument("--skip-grid", action="store_true")
    ap.add_argument("--random-states", type=int, default=100_000)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)

    # the compiled kernels are loaded (or, on a fresh checkout, compiled) on first use in a
    # process: do that outside the timed solves and report it
    warm = random_model(np.random.default_rng(12345), 50)
    _, t_warm = timed(lambda: solve(Problem(warm, Specification(ReachAvoid("goal")))))
    print(f"first solve in this process (loads or compiles the kernels): {t_warm:.2f} s")
    if not args.skip_grid:
        bench_grid(rng)
    if not args.skip_random:
        bench_random(rng, args.random_states)


def bench_grid(rng: np.random.Generator) -> None:
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
    sol, t_solve = timed(lambda: solve(Problem(pm, spec), ValueIteration(1e-8)))
    print(
        f"grid 100x100 x 3: {pm.n_states} product states, {pm.n_rows} rows, "
        f"{pm.n_entries} entries (IMDP {t_build:.2f} s, product {t_prod:.2f} s, "
        f"accepting end components {t_acc:.2f} s)"
    )
    free = int((~sol.fixed).sum())
    per_sweep = t_solve / max(sol.iterations, 1)
    base = baseline_sweep_seconds(pm, acc)
    print(
        f"  hopnav solve (graph precomputation + value iteration): {t_solve:.2f} s, "
        f"{sol.iterations} sweeps over {free} free states, residual {sol.residual:.1e}, "
        f"worst-case value at the start {sol.values[prod.initial]:.4f} (target: <= 1 s)"
    )
    print(
        f"  baseline sweep (all rows re-sorted): {base:.3f} s; hopnav {per_sweep:.3f} s per "
        f"sweep incl. precomputation; ratio baseline/hopnav per sweep = {base / per_sweep:.1f}"
    )


def bench_random(rng: np.random.Generator, n: int) -> None:
    rm, t_rbuild = timed(lambda: random_model(rng, n))
    tgt = rm.states_labelled("goal")
    rspec = Specification(ReachAvoid(tgt, rm.states_labelled("bad")))
    rsol, t_rvi = timed(lambda: solve(Problem(rm, rspec), ValueIteration(1e-8)))
    rbase = baseline_sweep_seconds(rm, tgt)
    r_per = t_rvi / max(rsol.iterations, 1)
    print(
        f"random {n} states x 8 x 9: {rm.n_entries} entries (build {t_rbuild:.1f} s); "
        f"hopnav solve of (!bad) U goal {t_rvi:.2f} s, {rsol.iterations} sweeps over "
        f"{int((~rsol.fixed).sum())} free states, residual {rsol.residual:.1e}, "
        f"{rm.n_entries * rsol.iterations / t_rvi:.3g} entries/s; baseline sweep "
        f"{rbase:.2f} s, ratio baseline/hopnav per sweep = {rbase / r_per:.1f}"
    )


if __name__ == "__main__":
    main()
