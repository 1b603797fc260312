"""Regenerate the case-study figures (a)-(d): ``python scripts/case_study_figures.py [--out DIR]``.

One ``hopnav run`` per case study with its default settings and seed (the scenario's), no
recording: (a) and (b) one run each, (c) and (d) their ten runs that keep the Q-learner; the
figure shows the last run (for (c)/(d) the tenth, as in the paper). Writes
``DIR/case_a.png`` .. ``DIR/case_d.png`` (default ``docs/figures``) and prints each summary
table. (``hopnav figure --scenarios a,b,c,d`` draws them as one panel, see
``scripts/make_figures.py``.)
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hopper_sim.cli import main as hopnav


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/figures", help="folder of the PNGs")
    ap.add_argument("--only", nargs="*", default=["a", "b", "c", "d"], help="case studies")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in args.only:
        png = str(out / f"case_{name}.png")
        code = hopnav(["run", "--scenario", name, "--no-rrd", "--quiet", "--png", png])
        if code:
            return code
    return 0


if __name__ == "__main__":
    sys.exit(main())
