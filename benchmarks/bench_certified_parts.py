"""Two parts of the certified solve against their plain versions, in the same process.

1. **Chain factorisation** (:func:`planner.imdp.evaluate.chain_lu`): the chain of the
   optimal strategy and its adversary on the 100 x 100 benchmark grid product
   (``benchmarks/bench_vi.py``), ``I - P`` on the states that reach the target, factorised
   by SuperLU's defaults (column ordering COLAMD, partial pivoting) and by ``chain_lu``
   (diagonal pivots, symmetric ordering of ``A + A^T``). Prints seconds (minimum of 5),
   the fill ``nnz(L + U)`` and the residual of one solve for each, and the ratio; then
   ``chain_lu`` of the same chain with the ordering of an earlier factorisation of its
   pattern reused (:class:`planner.imdp.evaluate.ChainOrderings`, as in the adversary's
   rounds of one strategy's evaluation) against a fresh ``chain_lu``.
2. **Interval iteration's rounds** (:mod:`planner.imdp.interval`): the worst-case
   satisfaction on the same product with the pass from above on the second thread (the
   default) and with both sides in turn on one thread (minimum of 3 each); the two
   solutions are checked identical.
3. **Passes from above** (:func:`planner.imdp.kernels.upper_sweep`): 100 passes
   ``U = min(U, T(U))`` from ``U = 1`` on the same product's free states, evaluating every
   row and lazily (the row cache); seconds (minimum of 3) and the largest difference of
   the two results.

Run from the repository root: ``PYTHONPATH=. python benchmarks/bench_certified_parts.py
[--seed 0] [--size 100]``
"""

from __future__ import annotations

import argparse
import importlib
import time
from concurrent.futures import Future

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from benchmarks.bench_vi import make_grid, until_automaton
from planner.imdp.analysis import satisfaction
from planner.imdp.evaluate import ChainOrderings, chain_lu, reaching
from planner.imdp.kernels import ReachSweeper
from planner.imdp.ordering import OrderingAdversary
from planner.imdp.product import ProductIMDP


def best_of(f, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return out, min(times)


class _InTurn:
    """An executor that runs each submitted call at once."""

    def submit(self, fn) -> Future:
        fut: Future = Future()
        fut.set_result(fn())
        return fut


def chain_of(prod: ProductIMDP, sol) -> tuple[sp.csr_matrix, np.ndarray]:
    """``P`` on the live states of the optimal strategy's chain, and its right-hand side."""
    m = prod.model
    acting = np.flatnonzero(~sol.fixed & (sol.strategy >= 0))
    rows = np.sort(m.row_index[acting, sol.strategy[acting]])
    states = m.row_state[rows]
    matrix = sp.csr_matrix(OrderingAdversary(m, True, rows=rows).matrix(sol.lower))
    base = np.where(sol.fixed, sol.lower, 0.0)
    b = matrix @ base
    inner = matrix[:, states].tocsr()
    live = np.flatnonzero(reaching(inner, b > 0))
    return inner[live][:, live].tocsr(), b[live]


def upper_passes(prod: ProductIMDP, sol, passes: int, lazy: bool) -> np.ndarray:
    """``passes`` passes from above from ``U = 1`` on the free states of ``sol``."""
    m = prod.model
    free_rows = np.flatnonzero(~sol.fixed[m.row_state])
    sweeper = ReachSweeper(m, free_rows, np.zeros(m.n_states), True, True)
    u = np.where(sol.fixed, sol.lower, 1.0)
    cache = sweeper.upper_cache() if lazy else None
    for _ in range(passes):
        sweeper.upper_pass(u, cache=cache)
    return u


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--size", type=int, default=100, help="grid side (cells)")
    args = ap.parse_args()
    small = ProductIMDP(make_grid(np.random.default_rng(1), 12)[0], until_automaton())
    satisfaction(small)  # load or compile the kernels
    grid = make_grid(np.random.default_rng(args.seed), args.size)[0]
    prod = ProductIMDP(grid, until_automaton())
    sol = satisfaction(prod)

    sub, b = chain_of(prod, sol)
    a = (sp.identity(sub.shape[0], format="csc") - sub).tocsc()
    plain, t_plain = best_of(lambda: splu(a), 5)
    chain, t_chain = best_of(lambda: chain_lu(sub), 5)
    print(f"chain of the optimal strategy: {sub.shape[0]} states, {sub.nnz} entries")
    for name, lu, t in (("SuperLU defaults", plain, t_plain), ("chain_lu", chain, t_chain)):
        res = np.max(np.abs(a @ lu.solve(b) - b))
        print(f"  {name:17s} {t:.4f} s, fill {lu.L.nnz + lu.U.nnz}, residual {res:.1e}")
    print(f"  ratio defaults/chain_lu = {t_plain / t_chain:.2f}")
    orderings = ChainOrderings()
    chain_lu(sub, orderings)
    again, t_again = best_of(lambda: chain_lu(sub, orderings), 5)
    res = np.max(np.abs(a @ again.solve(b) - b))
    print(
        f"  chain_lu, ordering reused {t_again:.4f} s, fill {again.fill}, residual {res:.1e}; "
        f"ratio fresh/reused = {t_chain / t_again:.2f}"
    )

    interval = importlib.import_module("planner.imdp.interval")
    threaded, t_threaded = best_of(lambda: satisfaction(prod), 3)
    worker = interval.worker
    interval.worker = lambda purpose: _InTurn()
    try:
        in_turn, t_in_turn = best_of(lambda: satisfaction(prod), 3)
    finally:
        interval.worker = worker
    same = np.array_equal(threaded.lower, in_turn.lower) and np.array_equal(
        threaded.upper, in_turn.upper
    )
    print(
        f"worst-case satisfaction, certified: pass from above on a second thread "
        f"{t_threaded:.2f} s, both sides in turn {t_in_turn:.2f} s, ratio "
        f"{t_in_turn / t_threaded:.2f}; identical solutions: {same}"
    )

    full, t_full = best_of(lambda: upper_passes(prod, sol, 100, False), 3)
    lazy, t_lazy = best_of(lambda: upper_passes(prod, sol, 100, True), 3)
    print(
        f"100 passes from above: every row {t_full:.3f} s, lazy {t_lazy:.3f} s, ratio "
        f"{t_full / t_lazy:.2f}; largest difference {np.max(np.abs(full - lazy)):.1e}"
    )


if __name__ == "__main__":
    main()
