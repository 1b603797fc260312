"""Does the paper's narrative happen? Case studies (a)-(d) with the default settings.

Usage: python benchmarks/fidelity.py [--seeds 5] [--sequences 5] [--workers 2] [--seed 0]
       [--only ab|cd] [--beta B] [--tour reward|coverage]   (studies: the interval
       multiplier, the in-component tour)

Prints, and checks against the acceptance of issue #11 [fidelity]:

* (a) and (b), known reward, ``--seeds`` runs each (seeds ``seed .. seed + seeds - 1``): the A
  cells each run landed on. Holds when the sets of A cells landed on differ between the two
  scenarios and at least 4 of 5 runs of (b) (the same share of other counts) land on an A
  cell: in (b) the robot goes for the A cells in the lower right, behind the wall.
* (c) and (d), unknown reward, ``--sequences`` sequences of ten runs that keep the Q-learner
  (sequence ``k`` has the seeds ``seed + 10 k .. seed + 10 k + 9``): the reward of the first
  and of the tenth run. Holds when the tenth run collects more than the first in at least 4
  of 5 sequences: what was learned about the reward pays.
* every run: whether it entered a hazard or left the map (it must not).

Each run also reports how it ended, its switch step and the worst-case satisfaction
probability at its current state after every synthesis. Exit code 0 whatever the checks
show (the printout says which hold).
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hopper_sim.navigation.events import Observer, RunEnd
from hopper_sim.navigation.runner import NavigationConfig, NavigationRunner
from planner.scenario import load_scenario

VIOLATIONS = ("hazard", "left the map")


class _Cells(Observer):
    """Collects the cells landed on, per run."""

    def __init__(self) -> None:
        self.cells: list[list[int]] = []

    def on_run_start(self, event) -> None:
        self.cells.append([])

    def on_hop(self, event) -> None:
        self.cells[-1].append(int(event.cell))


def _settings(sc, beta: float | None, tour: str | None) -> NavigationConfig:
    changes: dict = {"planner.beta": beta}
    if tour is not None:
        changes["planner.tour"] = tour
    return NavigationConfig.from_scenario(sc).override(changes)


def _sequence(job: tuple) -> tuple[str, int, list[RunEnd], list[list[int]]]:
    """``runs`` consecutive runs of ``name`` from seed ``seed`` (one learner throughout)."""
    name, seed, runs, beta, tour = job
    sc = load_scenario(name)
    cells = _Cells()
    runner = NavigationRunner(sc, settings=_settings(sc, beta, tour), observer=cells)
    ends = runner.run_many(runs, seed)
    return name, seed, ends, cells.cells


def _a_cells(name: str, cells: list[int]) -> list[tuple[int, int]]:
    sc = load_scenario(name)
    mask = sc.region_mask("A").ravel()
    ny = sc.world.ny
    return sorted({(c // ny, c % ny) for c in cells if c < mask.size and mask[c]})


def _line(end: RunEnd) -> str:
    trace = " ".join(f"{p:.2f}" for p in end.p_worst_trace)
    return (
        f"{end.outcome:9s} {end.reason:25s} steps {end.steps:4d} reward {end.reward:6.1f} "
        f"switch {'-' if end.switch_step is None else end.switch_step!s:>4} P [{trace}]"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="runs of (a) and of (b)")
    ap.add_argument("--sequences", type=int, default=5, help="10-run sequences of (c), (d)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", choices=("ab", "cd"), default=None)
    ap.add_argument("--beta", type=float, default=None, help="interval multiplier override")
    ap.add_argument("--tour", choices=("reward", "coverage"), default=None)
    args = ap.parse_args()
    over = (args.beta, args.tour)
    jobs = []
    if args.only != "cd":
        jobs += [(n, args.seed + k, 1, *over) for n in ("a", "b") for k in range(args.seeds)]
    if args.only != "ab":
        jobs += [
            (n, args.seed + 10 * k, 10, *over) for n in ("c", "d") for k in range(args.sequences)
        ]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(_sequence, jobs))
    wall = time.perf_counter() - t0
    violations = 0
    n_runs = 0
    landed: dict[str, list[list[tuple[int, int]]]] = {"a": [], "b": []}
    better: dict[str, list[bool]] = {"c": [], "d": []}
    for name, seed, ends, cells in results:
        n_runs += len(ends)
        violations += sum(e.reason in VIOLATIONS for e in ends)
        if name in landed:
            a = _a_cells(name, cells[0])
            landed[name].append(a)
            print(f"({name}) seed {seed:3d}: {_line(ends[0])}  A cells {a}")
        else:
            first, last = ends[0], ends[-1]
            better[name].append(last.reward > first.reward)
            print(
                f"({name}) seeds {seed}-{seed + len(ends) - 1}: reward first {first.reward:6.1f}"
                f" tenth {last.reward:6.1f}; tenth run: {_line(last)}"
            )
    print(f"\n{n_runs} runs in {wall:.0f} s on {args.workers} workers")
    if landed["a"] and landed["b"]:
        set_a = set().union(*map(set, landed["a"]))
        set_b = set().union(*map(set, landed["b"]))
        hits = sum(bool(x) for x in landed["b"])
        n = len(landed["b"])
        ok = set_a != set_b and hits >= 0.8 * n
        print(
            f"(a) vs (b): A cells landed on differ: {set_a != set_b}; runs of (b) on an A cell: "
            f"{hits}/{n} (need >= {0.8 * n:g}) -> {'holds' if ok else 'does not hold'}"
        )
    for name in ("c", "d"):
        if better[name]:
            k, n = sum(better[name]), len(better[name])
            verdict = "holds" if k >= 0.8 * n else "does not hold"
            print(f"({name}) tenth run beats the first in {k}/{n} sequences -> {verdict}")
    print(f"runs that entered a hazard or left the map: {violations} of {n_runs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
