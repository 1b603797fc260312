"""The mission gallery over seeds: outcome counts per scenario of examples/scenarios/.

    python benchmarks/missions.py [--seeds 10] [--first 0]

Per scenario: runs with seeds ``first .. first + seeds - 1`` at the scenario's own step cap;
prints the outcome counts, and for recurrence runs the least number of landings in each
region of the formula within the judged window. A gallery scenario passes when it has no
violation and at least 9 of 10 runs end in success (co-safe) or satisfying (recurrence).
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

from hopper_sim.navigation.runner import NavigationRunner
from planner.scenario import load_scenario

GALLERY = Path(__file__).resolve().parents[1] / "examples" / "scenarios"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first", type=int, default=0)
    args = ap.parse_args()
    for path in sorted(GALLERY.glob("*.toml")):
        sc = load_scenario(path)
        runner = NavigationRunner(sc)
        counts: Counter[str] = Counter()
        least: dict[str, int] = {}
        steps = []
        for seed in range(args.first, args.first + args.seeds):
            end = runner.run(seed)
            counts[end.outcome] += 1
            steps.append(end.steps)
            if end.outcome == "satisfying" and end.mission is not None:
                for k, v in end.mission.label_visits.items():
                    least[k] = min(least.get(k, v), v)
        good = counts["success"] + counts["satisfying"]
        ok = counts["violation"] == 0 and good >= 0.9 * args.seeds
        print(
            f"{sc.name:12s} {dict(counts)}  good {good}/{args.seeds}  steps "
            f"{min(steps)}-{max(steps)}  least window landings {least or '-'}  "
            f"{'PASS' if ok else 'FAIL'}",
            flush=True,
        )


if __name__ == "__main__":
    main()
