"""Correctness sweep beyond the test suite: translate many random formulas (the benchmark's
generator: depth <= 4, 3 propositions) and compare every automaton with the independent
lasso evaluator of ``tests/planner/ltl_oracle.py`` on all lassos of the test bounds.

Formulas whose translation plus check exceed ``--limit`` seconds are counted as skipped
(POSIX ``SIGALRM``). Prints the counts and every disagreement; exit status 1 if any.

Usage: ``python benchmarks/sweep_ltl_oracle.py [--n 1000] [--seed 0] [--limit 2]``
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_ltl import random_formula  # noqa: E402

from planner.ltl.syntax import Formula  # noqa: E402
from planner.ltl.translate import translate  # noqa: E402
from tests.planner.ltl_oracle import PROPS, automaton_accepts, evaluate  # noqa: E402
from tests.planner.test_ltl_translate import BATCHES  # noqa: E402


def as_tuple(f: Formula) -> tuple:
    """The oracle's view of a parsed (not simplified) formula."""
    if f.op == "ap":
        return ("ap", f.name)
    if f.op in ("true", "false"):
        return (f.op,)
    return (f.op, *(as_tuple(c) for c in f.children))


class _Timeout(Exception):
    pass


def _alarm(*_):
    raise _Timeout


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--limit", type=int, default=2, help="seconds per formula")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    signal.signal(signal.SIGALRM, _alarm)
    ok = skipped = 0
    bad: list[str] = []
    t0 = time.perf_counter()
    for _ in range(args.n):
        f = random_formula(rng, 4)
        signal.alarm(args.limit)
        try:
            aut = translate(f, PROPS)
            pairs = [(p.good, p.bad) for p in aut.pairs]
            agree = all(
                np.array_equal(
                    evaluate(as_tuple(f), letters, start)[:, 0],
                    automaton_accepts(aut.transitions, aut.initial, pairs, letters, start),
                )
                for letters, start in BATCHES
            )
            signal.alarm(0)
            if agree:
                ok += 1
            else:
                bad.append(str(f))
        except _Timeout:
            skipped += 1
        finally:
            signal.alarm(0)
    print(
        f"{args.n} formulas (seed {args.seed}): {ok} agree, {len(bad)} disagree, "
        f"{skipped} skipped (> {args.limit} s); {time.perf_counter() - t0:.1f} s"
    )
    for text in bad:
        print("DISAGREE:", text)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
