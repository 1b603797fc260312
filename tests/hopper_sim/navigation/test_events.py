import numpy as np
import pytest

from hopper_sim.navigation.events import (
    EventError,
    HopEvent,
    Observer,
    ObserverProtocol,
    Observers,
    RunEnd,
    SynthesisEvent,
)
from planner.scenario import load_scenario
from tests.hopper_sim.synthetic_runs import feed, run_events


def test_synthetic_run_reaches_goal():
    events = run_events(load_scenario("a"), 0, 6)
    hops = [e for e in events if isinstance(e, HopEvent)]
    assert len(hops) == 6
    assert load_scenario("a").cell_labels[hops[-1].cell] == frozenset({"Goal"})
    assert not hops[0].landing.flags.writeable


def test_events_validate_fields():
    hop = run_events(load_scenario("a"), 0, 1)[2]
    kwargs = {k: getattr(hop, k) for k in hop.__dataclass_fields__}
    with pytest.raises(EventError, match="phase"):
        HopEvent(**{**kwargs, "phase": "resting"})
    with pytest.raises(EventError, match=r"com_path must have shape \(n, 3\)"):
        HopEvent(**{**kwargs, "com_path": np.zeros((4, 2))})
    with pytest.raises(EventError, match="com_time"):
        HopEvent(**{**kwargs, "com_time": np.zeros(3)})
    with pytest.raises(EventError, match="outcome"):
        RunEnd(0, "crashed", 1, 0.0, None, None, 0, 0.1)
    with pytest.raises(EventError, match="gp_std"):
        SynthesisEvent(
            0, 0, np.zeros(2), np.zeros(3), np.zeros((2, 3, 2)), np.zeros((3, 2, 2)), 0.5
        )


def test_observers_fan_out_in_order():
    calls = []

    class Recorder(Observer):
        def __init__(self, tag):
            self.tag = tag

        def on_hop(self, event):
            calls.append((self.tag, event.step))

        def close(self):
            calls.append((self.tag, "closed"))

    both = Observers([Recorder("a"), Recorder("b")])
    assert isinstance(both, ObserverProtocol)
    feed(both, run_events(load_scenario("a"), 0, 2))
    both.close()
    assert calls == [("a", 0), ("b", 0), ("a", 1), ("b", 1), ("a", "closed"), ("b", "closed")]
