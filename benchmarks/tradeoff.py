"""Check the paper's trade-off theorem on a Table I sweep.

Reads the per-run CSV of ``hopnav sweep`` (``runs/sweep/sweep_runs.csv`` by default), or with
``--run`` first runs the sweep (real navigation runs; same options as ``hopnav sweep``), then
fits least-squares slopes on the per-run data and prints, for each predicted trend, the slope
with its 95 % confidence interval and whether the trend holds (interval entirely on the
predicted side), does not hold (entirely on the other side) or is inconclusive:

* steps vs eps at C = 0.25 and C = 0.5: predicted decreasing;
* reward vs C at each eps, and pooled: predicted increasing.

Run: ``python benchmarks/tradeoff.py [CSV]`` or ``python benchmarks/tradeoff.py --run``.
Exit code 0 whatever the trends show; 2 on a missing or malformed CSV.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hopper_sim.experiments.sweep_files import ROWS_FILE, SweepFileError, read_rows_csv
from hopper_sim.experiments.tradeoff import check_tradeoff, format_trends, paper_points


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "csv", nargs="?", default=str(Path("runs") / "sweep" / ROWS_FILE), help="per-run CSV"
    )
    parser.add_argument("--run", action="store_true", help="run the sweep first (hopnav sweep)")
    parser.add_argument("--scenario", default="a")
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--backend", default="process", choices=("process", "serial", "ray"))
    parser.add_argument("--level", type=float, default=0.95, help="confidence level [0.95]")
    parser.add_argument(
        "--paper", action="store_true", help="also check the paper's Table I (cell means only)"
    )
    args = parser.parse_args(argv)

    csv_path = Path(args.csv)
    if args.run:
        from hopper_sim.cli import main as hopnav

        sweep_args = ["sweep", "--scenario", args.scenario, "--runs", str(args.runs)]
        sweep_args += ["--seed", str(args.seed), "--backend", args.backend]
        sweep_args += ["--out", str(csv_path.parent)]
        if args.workers is not None:
            sweep_args += ["--workers", str(args.workers)]
        code = hopnav(sweep_args)
        if code:
            return code
        csv_path = csv_path.parent / ROWS_FILE
    try:
        rows = read_rows_csv(csv_path)
    except SweepFileError as err:
        print(f"tradeoff: {err}", file=sys.stderr)
        return 2
    print(f"{len(rows)} runs from {csv_path}")
    print(format_trends(check_tradeoff(rows, level=args.level)))
    if args.paper:
        print("\nThe paper's Table I, same checks on its nine cell means:")
        print(format_trends(check_tradeoff(paper_points(), level=args.level)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
