"""The ordering adversary (:class:`planner.imdp.OrderingAdversary`) against a vectorised
numpy baseline, in the same process.

On the 100 x 100 benchmark grid product (``benchmarks/bench_vi.py``, about 30k states and
4.3M entries), with the worst-case satisfaction's lower values ``V``:

1. **Build**: the adversary's distribution matrix of every row at ``V``, from nothing
   (``OrderingAdversary(...).matrix(V)``: a compiled insertion sort per row and the
   mass handed out in the same pass) against the baseline, which sorts all rows at once
   through a padded ``(rows, longest row)`` array (``np.argsort`` along its rows) and
   hands out the mass by a segmented prefix sum (the implementation before the kernel).
2. **Update**: ``V`` moved by up to 1e-3 on 5 % of the states: the stored adversary
   re-sorts only the rows whose order broke; the baseline sorts everything again.

Both give the same expectations (the largest difference is printed). Seconds are the
minimum of 5; the ratio is baseline / hopnav.

Run from the repository root: ``PYTHONPATH=. python benchmarks/bench_ordering.py
[--seed 0]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp

from benchmarks.bench_certified_parts import best_of
from benchmarks.bench_vi import make_grid, until_automaton
from planner.imdp import IMDP, OrderingAdversary
from planner.imdp.analysis import satisfaction
from planner.imdp.product import ProductIMDP


def numpy_matrix(m: IMDP, values: np.ndarray) -> sp.csr_matrix:
    """The minimising adversary's distributions of every row, by array operations only."""
    lens = np.diff(m.row_ptr)
    n_rows, width = lens.size, int(lens.max())
    row = np.repeat(np.arange(n_rows), lens)
    pos = np.arange(m.n_entries) - m.row_ptr[row]
    padded = np.full((n_rows, width), np.inf)
    padded[row, pos] = values[m.successor]
    order = np.argsort(padded, axis=1, kind="stable")
    perm = (m.row_ptr[:-1, None] + order)[np.arange(width)[None, :] < lens[:, None]]
    lower, gap = m.lower[perm], (m.upper - m.lower)[perm]
    cum = gap.copy()  # Hillis-Steele scan restarted at every row
    d = 1
    while d < width:
        shifted = np.zeros_like(cum)
        shifted[d:] = cum[:-d]
        cum += np.where(pos >= d, shifted, 0.0)
        d *= 2
    prob = lower + np.clip((1.0 - m.row_lower_sum)[row] - (cum - gap), 0.0, gap)
    return sp.csr_matrix((prob, m.successor[perm], m.row_ptr), shape=(n_rows, m.n_states))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    small = ProductIMDP(make_grid(np.random.default_rng(1), 12)[0], until_automaton())
    OrderingAdversary(small.model).expectation(np.zeros(small.model.n_states))  # compile
    prod = ProductIMDP(make_grid(rng)[0], until_automaton())
    m = prod.model
    v = satisfaction(prod).lower
    print(f"grid product: {m.n_states} states, {m.n_rows} rows, {m.n_entries} entries")

    base, t_base = best_of(lambda: numpy_matrix(m, v), 5)
    ours, t_ours = best_of(lambda: OrderingAdversary(m).matrix(v), 5)
    diff = np.max(np.abs(base @ v - ours @ v))
    print(
        f"  build: numpy {t_base:.3f} s, hopnav {t_ours:.3f} s, ratio {t_base / t_ours:.1f}; "
        f"largest difference of the expectations {diff:.1e}"
    )

    moved = v.copy()
    pick = rng.random(m.n_states) < 0.05
    moved[pick] = np.clip(moved[pick] + rng.uniform(-1e-3, 1e-3, int(pick.sum())), 0.0, 1.0)

    def updated():
        adv = OrderingAdversary(m)
        adv.update(v)
        t0 = time.perf_counter()
        out = adv.matrix(moved)
        return out, time.perf_counter() - t0

    t_update = min(updated()[1] for _ in range(5))
    base2, t_base2 = best_of(lambda: numpy_matrix(m, moved), 5)
    diff2 = np.max(np.abs(base2 @ moved - updated()[0] @ moved))
    print(
        f"  update after moving 5 % of the values: numpy {t_base2:.3f} s, hopnav "
        f"{t_update:.4f} s, ratio {t_base2 / t_update:.1f}; largest difference {diff2:.1e}"
    )


if __name__ == "__main__":
    main()
