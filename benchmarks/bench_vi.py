"""Robust value iteration speed, full re-synthesis, and Storm side by side.

1. A 100 x 100 grid world (1 m cells, 8 actions, 9-25 successors per action) times the
   3-state automaton of ``!Haz U Goal`` (about 30k product states): worst-case
   satisfaction (certified, tolerance 1e-8). With ``--full`` the whole re-synthesis of the
   learning loop's planning part is timed stage by stage: product, failure states,
   nonviolating sub-model, accepting end components (the MEC-choice candidates), certified
   value iteration (``analysis.satisfaction``, which finds the almost-sure region itself).
   They are timed one after the other, and together as ``planner.synthesis`` runs them:
   the certified value iteration on this thread while the failure states, the nonviolating
   sub-model and the accepting end components are found on a second one. Target: <= 1 s
   in all. The almost-sure region is also timed alone (the uncertified and Storm runs take
   it as their target), outside the total.
2. A random model of 100k states x 8 actions x 9 successors (7.2M entries; 5% goal, 30%
   bad states): worst-case ``(!bad) U goal``, seconds and entries/s.

Each is compared with a baseline run in the same process: one sweep of the same robust
update with a full re-sort (``np.lexsort``) of every row, no cached order and no graph
precomputation (the ratio is per sweep). With ``--storm`` (stormpy installed) Storm's robust
value iteration runs on the same models in the same process at the same tolerance (1e-8,
absolute), next to hopnav's uncertified mode (the same kind of stopping rule) and its
certified default, each the least of 5 runs taken in turns, and where Storm's values fall
outside hopnav's certified bracket (its stopping rule does not bound its error); Storm
needs every lower bound positive ("graph preservation"), so the random model's zero lower
bounds are raised to 1e-4 of the row's interval for that run (both tools solve the same
file). Model building and file writing are not timed.

Like the ``hopnav`` command, the benchmark first sets the process's allocator to reuse freed
large arrays (:mod:`planner.allocator`: the re-synthesis rebuilds arrays above glibc's
32 MiB mmap threshold on every call, and faulting their pages in anew costs about a tenth
of it); ``--system-allocator`` leaves it as it is.

The compiled kernels (numba) are loaded from numba's cache, or compiled on a fresh
checkout, by the first solve in a process; a small warm-up does that before the timed
solves and its time is printed. ``--seed`` draws another hazard layout and other intervals.

Run from the repository root:
``PYTHONPATH=. python benchmarks/bench_vi.py [--seed 0] [--full] [--storm] [--skip-random]
[--skip-grid] [--system-allocator]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planner._util.threads import concurrently
from planner.allocator import reuse_freed_memory
from planner.automaton import RabinAutomaton
from planner.imdp import IMDP, Problem, ReachAvoid, Specification, ValueIteration, solve
from planner.imdp.analysis import (
    accepting_end_components,
    failure_states,
    labelled_model,
    nonviolating,
    satisfaction,
    winning_states,
)
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


def random_model(
    rng: np.random.Generator, n: int, n_act: int = 8, k: int = 9, positive: bool = False
) -> IMDP:
    """``positive``: raise zero lower bounds to ``1e-4`` of the entry's upper bound."""
    return IMDP(**random_arrays(rng, n, n_act, k, positive))


def random_arrays(
    rng: np.random.Generator, n: int, n_act: int = 8, k: int = 9, positive: bool = False
) -> dict:
    """The arguments of :class:`IMDP` for :func:`random_model` (successors unsorted within a
    row, so the constructor sorts them)."""
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
    if positive:
        lo = np.maximum(lo, 1e-4 * up)
    kind = rng.random(n)
    labels = [("goal",) if x < 0.05 else ("bad",) if x < 0.35 else () for x in kind]
    return dict(
        n_states=n,
        state=s,
        action=a,
        successor=t.ravel(),
        lower=lo.ravel(),
        upper=up.ravel(),
        n_actions=n_act,
        labels=labels,
    )


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


def best_of(f, first: float, runs: int = 3) -> float:
    """The least of ``first`` (a run already timed) and ``runs - 1`` more runs of ``f``."""
    return min([first] + [timed(f)[1] for _ in range(runs - 1)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--full", action="store_true", help="time the full re-synthesis")
    ap.add_argument("--storm", action="store_true", help="Storm side by side (stormpy)")
    ap.add_argument("--skip-random", action="store_true")
    ap.add_argument("--skip-grid", action="store_true")
    ap.add_argument("--random-states", type=int, default=100_000)
    ap.add_argument(
        "--system-allocator",
        action="store_true",
        help="leave the allocator as it is (by default freed large arrays are reused, as the "
        "hopnav command sets it: planner.allocator)",
    )
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    reused = not args.system_allocator and reuse_freed_memory()
    print(f"freed large arrays reused (planner.allocator, as in the hopnav command): {reused}")

    # the compiled kernels are loaded (or, on a fresh checkout, compiled) on first use in a
    # process: do that outside the timed solves and report it
    t0 = time.perf_counter()
    warm = random_model(np.random.default_rng(12345), 50)
    solve(Problem(warm, Specification(ReachAvoid("goal"))))
    small = ProductIMDP(make_grid(np.random.default_rng(1), 12)[0], until_automaton())
    satisfaction(small)
    nonviolating(small)
    accepting_end_components(small)
    t_warm = time.perf_counter() - t0
    print(f"first solves in this process (load or compile the kernels): {t_warm:.2f} s")
    if not args.skip_grid:
        bench_grid(rng, args.full, args.storm)
    if not args.skip_random:
        bench_random(rng, args.random_states, args.storm)


def make_grid(rng: np.random.Generator, n: int = 100) -> tuple[IMDP, GridWorld]:
    labels = np.empty((n, n), dtype=object)
    labels[:] = [[() for _ in range(n)] for _ in range(n)]
    haz = rng.random((n, n)) < 0.03
    haz[: n // 10, : n // 10] = False
    for i, j in zip(*np.nonzero(haz), strict=True):
        labels[i, j] = ("Haz",)
    for i in range(n - n // 10, n):
        for j in range(n - n // 10, n):
            labels[i, j] = ("Goal",)
    grid = GridWorld(n, n, 1.0, labels)
    return grid.imdp_from_intervals(*grid_intervals(grid, rng)), grid


def two_threads(model: IMDP) -> None:
    """The full re-synthesis as :func:`planner.synthesis.synthesise` arranges it: the
    product, its reverse index, then satisfaction here and the safety steps on the
    synthesis worker."""
    prod = ProductIMDP(model, until_automaton())
    prod.model.reverse_index()

    def safety():
        fail = failure_states(prod)
        nonviolating(prod, fail)
        accepting_end_components(prod)

    concurrently(safety, lambda: satisfaction(prod), "synthesis")


def bench_grid(rng: np.random.Generator, full: bool, storm: bool) -> None:
    model, t_build = timed(lambda: make_grid(rng)[0])
    stages = {}
    prod, stages["product"] = timed(lambda: ProductIMDP(model, until_automaton()))
    fail, stages["failure states"] = timed(lambda: failure_states(prod))
    _, stages["nonviolating"] = timed(lambda: nonviolating(prod, fail))
    _, stages["accepting ECs"] = timed(lambda: accepting_end_components(prod))
    sol, stages["certified VI"] = timed(lambda: satisfaction(prod))
    acc, t_acc = timed(lambda: winning_states(prod))
    pm = prod.model
    print(
        f"grid 100x100 x 3: {pm.n_states} product states, {pm.n_rows} rows, "
        f"{pm.n_entries} entries (grid IMDP built in {t_build:.2f} s)"
    )
    total = sum(stages.values())
    if full:
        split = ", ".join(f"{k} {v:.2f} s" for k, v in stages.items())
        _, t_two = timed(lambda: two_threads(model))
        t_two = best_of(lambda: two_threads(model), t_two)
        print(
            f"  full re-synthesis {t_two:.2f} s (least of 3) on two threads as "
            f"planner.synthesis runs it "
            f"(target: <= 1 s): the product, then the certified VI while the failure states, "
            f"the nonviolating sub-model and the accepting ECs are found on a second thread; "
            f"the stages one after the other {total:.2f} s: {split} (the certified VI "
            f"includes the almost-sure region, {t_acc:.2f} s alone)"
        )
    s0 = prod.initial
    print(
        f"  worst-case satisfaction at the start {sol.values[s0]:.10f}, bracket "
        f"[{sol.lower[s0]:.10f}, {sol.upper[s0]:.10f}], max width {sol.error:.1e}, "
        f"certified {sol.converged}; {sol.iterations} sweeps, {sol.upper_sweeps} checking "
        f"passes, {sol.evaluations} strategy evaluations"
    )
    spec = Specification(ReachAvoid(acc))

    def solve_fast():
        return solve(Problem(pm, spec), ValueIteration(1e-8, certified=False))

    fast, t_fast = timed(solve_fast)
    base = baseline_sweep_seconds(pm, acc)
    per_sweep = t_fast / max(fast.iterations, 1)
    print(
        f"  uncertified solve: {t_fast:.2f} s, {fast.iterations} sweeps over "
        f"{int((~fast.fixed).sum())} free states, residual {fast.residual:.1e}; baseline sweep "
        f"{base:.3f} s, ratio baseline/hopnav per sweep = {base / per_sweep:.1f}"
    )
    if storm:
        side_by_side(
            "grid product",
            labelled_model(prod, acc, fail),
            'F "accept"',
            solve_fast,
            t_fast,
            lambda: solve(Problem(pm, spec)),
        )


def bench_random(rng: np.random.Generator, n: int, storm: bool) -> None:
    arrays, t_draw = timed(lambda: random_arrays(rng, n, positive=storm))
    rm, t_rbuild = timed(lambda: IMDP(**arrays))
    tgt = rm.states_labelled("goal")
    rspec = Specification(ReachAvoid(tgt, rm.states_labelled("bad")))

    def solve_fast():
        return solve(Problem(rm, rspec), ValueIteration(1e-8, certified=False))

    def solve_cert():
        return solve(Problem(rm, rspec))

    rsol, t_rvi = timed(solve_fast)
    cert, t_cert = timed(solve_cert)
    rbase = baseline_sweep_seconds(rm, tgt)
    r_per = t_rvi / max(rsol.iterations, 1)
    lower = "lower bounds >= 1e-4 u" if storm else "20% zero lower bounds"
    print(
        f"random {n} states x 8 x 9 ({lower}): {rm.n_entries} entries (drawn in {t_draw:.1f} "
        f"s; the IMDP constructor, validation and sorting included, {t_rbuild:.2f} s); "
        f"uncertified solve of (!bad) U goal {t_rvi:.2f} s, "
        f"{rsol.iterations} sweeps over {int((~rsol.fixed).sum())} free states, residual "
        f"{rsol.residual:.1e}, {rm.n_entries * rsol.iterations / t_rvi:.3g} entries/s; "
        f"certified {t_cert:.2f} s (bracket {cert.error:.1e}, certified {cert.converged}); "
        f"baseline sweep {rbase:.2f} s, ratio baseline/hopnav per sweep = {rbase / r_per:.1f}"
    )
    if storm:
        side_by_side(
            "random model", rm, '!"bad" U "goal"', solve_fast, t_rvi, solve_cert, (cert, t_cert)
        )


SIDE_RUNS = 5
"""Runs of each tool side by side (:func:`side_by_side`)."""


def side_by_side(name, model, path_formula, solve_fast, t_fast, solve_cert, first_cert=None):
    """Storm's robust value iteration on the same model (DRN file), precision 1e-8 absolute,
    timed like hopnav's solves: model checking only, the least of ``SIDE_RUNS`` runs for
    each tool, taken in turns (one of each tool per round, so that a noisy stretch of the
    machine falls on both alike; every run is printed too, with the ratio of the medians)
    (``t_fast``, ``first_cert = (solution, seconds)``:
    hopnav's first runs, already timed and counted; the model's reverse index, built by
    the first, is model data like Storm's built matrix)."""
    import os
    import tempfile

    import stormpy

    from planner.imdp.io import write_drn

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "model.drn")
        write_drn(model, path)
        smodel = stormpy.build_model_from_drn[stormpy.Interval](path)
    prop = stormpy.parse_properties(f"Pmax=? [{path_formula}]")[0]
    env = stormpy.Environment()
    mm = env.solver().min_max()
    mm.precision = stormpy.Rational(1e-8)
    mm.relative_termination_criterion = False

    def storm():
        return stormpy.model_checking(
            smodel,
            prop,
            only_initial_states=False,
            uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.ROBUST,
            environment=env,
        )

    cert, t_cert = timed(solve_cert) if first_cert is None else first_cert
    res, t_storm = timed(storm)
    runs = {"Storm": [t_storm], "uncertified": [t_fast], "certified": [t_cert]}
    for _ in range(SIDE_RUNS - 1):
        runs["Storm"].append(timed(storm)[1])
        runs["uncertified"].append(timed(solve_fast)[1])
        runs["certified"].append(timed(solve_cert)[1])
    t_storm, t_fast, t_cert = (min(runs[k]) for k in ("Storm", "uncertified", "certified"))
    values = np.array([res.get_value(i) for i in range(model.n_states)])
    diff = float(np.max(np.abs(values - cert.values)))
    # Storm stops on the change of an iteration, which does not bound its error: where
    # its values leave hopnav's certified bracket, by how much
    off = np.maximum(cert.lower - values, values - cert.upper)
    print(
        f"  Storm on the {name}: robust VI {t_storm:.2f} s vs hopnav uncertified "
        f"{t_fast:.2f} s ({t_storm / t_fast:.1f}x) and certified {t_cert:.2f} s "
        f"({t_storm / t_cert:.1f}x), each the least of {SIDE_RUNS} runs in turns; max "
        f"|Storm - hopnav| = "
        f"{diff:.1e}; Storm outside hopnav's bracket (width {cert.error:.1e}, certified "
        f"{cert.converged}) at "
        f"{int((off > 0).sum())} states, by up to {max(float(off.max()), 0.0):.1e}"
    )
    # every run, in the order taken: the spread shows how noisy the machine was
    spread = "; ".join(f"{k} " + " ".join(f"{t:.2f}" for t in ts) for k, ts in runs.items())
    print(
        f"    runs (s): {spread}; median ratio Storm / uncertified "
        f"{np.median(runs['Storm']) / np.median(runs['uncertified']):.1f}x"
    )


if __name__ == "__main__":
    main()
