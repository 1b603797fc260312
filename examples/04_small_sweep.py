"""A small Table I sweep: mean reward and steps over P_RL,ee = C x eps, with 95 % intervals.

Two values of C, one of eps, two runs per cell with a short step cap, run in this process;
writes the raw rows, the summary and the Markdown table (each with its provenance) to
``--out`` and prints the table beside the paper's. ``hopnav sweep`` runs the full grid in
parallel.

    python examples/04_small_sweep.py [--out runs/example-sweep]
"""

import argparse

from hopper_sim import SweepSpec, provenance, run_sweep, write_outputs
from hopper_sim.experiments.sweep_files import format_table
from planner import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="runs/example-sweep")
    ap.add_argument("--max-steps", type=int, default=15)
    args = ap.parse_args()
    scenario = load_scenario("a")
    spec = SweepSpec(cs=(0.25, 0.75), epss=(0.005,), runs=2, seed=0)
    short = scenario.with_runner(max_steps=args.max_steps)
    result = run_sweep(
        short,
        spec,
        backend="serial",
        progress=lambda done, total, row: print(
            f"  run {done}/{total}: C={row.c:g} eps={row.eps:g} {row.outcome} {row.steps} hops"
        ),
    )
    paths = write_outputs(result, args.out, provenance(short))
    print(format_table(result))
    for kind, path in paths.items():
        print(f"{kind}: {path}")
    assert len(result.rows) == spec.n_runs


if __name__ == "__main__":
    main()
