"""Regenerate the README's figures under ``docs/figures/`` with one command.

    python scripts/make_figures.py [--workers N] [--runs 10] [--reuse-sweep]

1. ``hopnav figure --scenarios a,b,c,d``: runs the four case studies on their shipped settings
   and draws the 2 x 2 Figure 4 panel (the last run of each: the tenth of (c) and (d)) to
   ``fig4.png`` and ``fig4.pdf``; the recordings go to ``runs/fig4/<scenario>.rrd``.
2. ``hopnav sweep --runs R``: the Table I sweep into ``runs/sweep`` (skipped with
   ``--reuse-sweep`` when ``runs/sweep/sweep_runs.csv`` exists; otherwise it is rerun from
   scratch, so rows of older code are never mixed in).
3. ``hopnav figure --table-i runs/sweep/sweep_runs.csv``: the Table I plot to ``table_i.png``
   and ``table_i.pdf``.

Everything is seeded (the scenarios' seeds, sweep seed 0), so the same code gives the same
figures. On two cores step 1 takes a few minutes and step 2 several more.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hopper_sim.cli import main as hopnav  # noqa: E402
from planner.allocator import reuse_freed_memory_unless_disabled  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", default=str(ROOT / "docs" / "figures"), help="[docs/figures]")
    p.add_argument("--sweep-dir", default=str(ROOT / "runs" / "sweep"), help="[runs/sweep]")
    p.add_argument("--runs", type=int, default=10, help="sweep runs per cell [10]")
    p.add_argument("--workers", type=int, default=None, help="sweep workers [all cores]")
    p.add_argument("--reuse-sweep", action="store_true", help="plot an existing sweep's rows")
    p.add_argument("--skip-panel", action="store_true", help="only the Table I plot")
    args = p.parse_args(argv)
    out, sweep = Path(args.out), Path(args.sweep_dir)
    out.mkdir(parents=True, exist_ok=True)
    if not args.skip_panel:
        rrd = ROOT / "runs" / "fig4"
        code = hopnav(
            [
                "figure",
                "--scenarios",
                "a,b,c,d",
                "--save-rrd",
                str(rrd),
                "--out",
                str(out / "fig4.png"),
                "--out",
                str(out / "fig4.pdf"),
            ]
        )
        if code:
            return code
    rows = sweep / "sweep_runs.csv"
    if not (args.reuse_sweep and rows.is_file()):
        cmd = ["sweep", "--runs", str(args.runs), "--out", str(sweep)]
        if args.workers is not None:
            cmd += ["--workers", str(args.workers)]
        code = hopnav(cmd)
        if code:
            return code
    return hopnav(
        [
            "figure",
            "--table-i",
            str(rows),
            "--out",
            str(out / "table_i.png"),
            "--out",
            str(out / "table_i.pdf"),
        ]
    )


if __name__ == "__main__":
    reuse_freed_memory_unless_disabled()  # as the hopnav command does
    sys.exit(main())
