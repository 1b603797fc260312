"""The closed loop on case study (a): plan on the learned abstraction, hop in MuJoCo, learn.

Runs one navigation run of scenario ``a`` with a short step cap and an observer of your own
(the runner never prints: it calls observers), which counts the phases and prints each
re-synthesis and the end of the run. ``--max-steps`` and ``--seed`` change the run.

    python examples/03_closed_loop.py [--max-steps 60] [--seed 0]
"""

import argparse
from collections import Counter

from hopper_sim import NavigationRunner, Observer
from planner import load_scenario


class Printer(Observer):
    """Counts the hops per phase and prints the syntheses and the outcome."""

    def __init__(self) -> None:
        self.phases: Counter[str] = Counter()

    def on_synthesis(self, event) -> None:
        print(
            f"  synthesis after {event.step:3d} hops: P_worst(initial) "
            f"{event.p_worst_initial:.3f}, {sum(event.timings.values()):.2f} s"
        )

    def on_hop(self, event) -> None:
        self.phases[event.phase] += 1

    def on_run_end(self, event) -> None:
        print(
            f"  run ended: {event.outcome} ({event.reason}) after {event.steps} hops, reward "
            f"{event.reward:.1f}, switch at {event.switch_step}, phases {dict(self.phases)}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-steps", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    scenario = load_scenario("a").with_runner(max_steps=args.max_steps, batch_size=20)
    printer = Printer()
    print(f"scenario {scenario.name}: {scenario.formula}, P_sat = {scenario.p_sat}")
    end = NavigationRunner(scenario, observer=printer).run(seed=args.seed)
    assert end.steps == sum(printer.phases.values()) or end.reason.startswith("hop failed")
    assert end.outcome in ("success", "violation", "timeout")


if __name__ == "__main__":
    main()
