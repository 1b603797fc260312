"""Wall time of a sweep on the process backend against the serial backend (the baseline).

Both sweeps run the same CPU-bound stand-in run function (a fixed amount of pure-Python
arithmetic per run, ``--work`` million multiply-adds, no I/O, one thread) over a
``--runs``-per-cell Table I grid, in this process; the script prints both wall times, the
speed-up ``serial / process`` and checks that both produced the same rows. With ``w`` free
cores the ideal speed-up is ``w``; the difference is the cost of starting the workers
(``spawn``: each imports numpy, scipy and the project) and of passing results back.

Run: ``python benchmarks/sweep_backends.py [--runs 2] [--workers 2] [--work 3]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hopper_sim.experiments.sweep import SweepSpec, available_cores, run_sweep
from hopper_sim.navigation.events import RunEnd
from planner.scenario import load_scenario


def busy_run(scenario, seed: int, run_index: int) -> RunEnd:
    """``scenario.runner.max_steps`` million multiply-adds; steps = seed mod 100."""
    acc = 0
    for i in range(scenario.runner.max_steps * 1_000_000):
        acc = (acc * 31 + i) & 0xFFFF
    return RunEnd(run_index, "success", seed % 100, float(acc), None, None, 0, 0.0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=2, help="runs per cell [2]")
    ap.add_argument("--workers", type=int, default=available_cores(), help="[cores]")
    ap.add_argument("--work", type=int, default=3, help="million multiply-adds per run [3]")
    args = ap.parse_args()
    sc = load_scenario("a").with_runner(max_steps=args.work)  # the work travels in the scenario
    spec = SweepSpec(runs=args.runs)
    t0 = time.perf_counter()
    serial = run_sweep(sc, spec, run=busy_run, backend="serial")
    t_serial = time.perf_counter() - t0
    t0 = time.perf_counter()
    par = run_sweep(sc, spec, run=busy_run, backend="process", workers=args.workers)
    t_par = time.perf_counter() - t0
    same = serial.rows == par.rows
    print(f"{spec.n_runs} runs of {args.work} M multiply-adds each")
    print(f"serial (baseline): {t_serial:.2f} s")
    print(f"process, {args.workers} workers: {t_par:.2f} s")
    print(f"speed-up serial/process: {t_serial / t_par:.2f}x; same rows: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
