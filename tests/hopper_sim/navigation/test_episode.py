import numpy as np

from hopper_sim.navigation.episode import RunClock, hop_outcome
from planner.imdp.grid import GridWorld
from planner.imdp.product import ProductIMDP
from planner.modes import Outcome
from planner.verdict import AutomatonVerdicts
from tests.planner.imdp.helpers import corridor_intervals, until_automaton


def _product():
    g = GridWorld(5, 1, labels=[("Haz",), (), (), (), ("Goal",)])
    m = g.imdp_from_intervals(*corridor_intervals(g), initial=[1])
    return g, ProductIMDP(m, until_automaton())


def test_the_outcome_is_a_function_of_the_product_state_entered():
    g, p = _product()
    verdicts = AutomatonVerdicts(p.automaton, excluded="Haz")
    assert hop_outcome(p, verdicts, p.state_index(2, 0)) is None
    assert hop_outcome(p, verdicts, p.state_index(4, 1)) == (
        Outcome.SUCCESS,
        "specification satisfied",
    )
    assert hop_outcome(p, verdicts, p.state_index(4, 1), start=True) == (
        "success",
        "accepted at the start",
    )
    assert hop_outcome(p, verdicts, p.state_index(0, 2)) == ("violation", "specification violated")
    hazard = hop_outcome(p, verdicts, p.state_index(0, 2), terminated=True, out=g.out)
    assert hazard == ("violation", "hazard")
    off = hop_outcome(p, verdicts, p.state_index(g.out, 2), terminated=True, out=g.out)
    assert off == ("violation", "left the map")


def test_the_run_clock_sums_stages_and_keeps_the_longest_synthesis():
    ticks = iter(np.arange(0.0, 100.0, 1.0))
    clock = RunClock(lambda: float(next(ticks)))  # starts at 0
    with clock.timed("hops"):  # 1 -> 2
        pass
    clock.add_synthesis({"gp_fit": 1.0, "abstraction": 2.0, "synthesis": 3.0})
    clock.add_synthesis({"gp_fit": 0.5, "abstraction": 0.5, "synthesis": 0.5})
    report = clock.report()
    assert list(report) == ["gp_fit", "abstraction", "synthesis", "hops", "replan", "batch_max"]
    assert report["hops"] == 1.0 and report["gp_fit"] == 1.5 and report["batch_max"] == 6.0
    assert clock.elapsed() == 3.0
