import numpy as np
import pytest

from planner.automaton import RabinAutomaton
from planner.errors import AutomatonError, UnknownPropositionError


def reach_avoid() -> RabinAutomaton:
    """!Haz U Goal over (Goal, Haz): 0 = waiting, 1 = accepted sink, 2 = rejecting sink."""
    # letters: bit0 = Goal, bit1 = Haz
    table = np.array([[0, 1, 2, 1], [1, 1, 1, 1], [2, 2, 2, 2]])
    return RabinAutomaton(["Goal", "Haz"], table, 0, [({1}, set())])


def test_accepts_lassos():
    a = reach_avoid()
    assert a.accepts([[], ["Goal"]], [[]])
    assert not a.accepts([["Haz"]], [["Goal"]])
    assert not a.accepts([], [[]])
    assert a.accepts([], [["Goal"]])


def test_step_and_run():
    a = reach_avoid()
    assert a.step(0, {"Goal", "Haz"}) == 1
    assert a.run([[], ["Haz"]]) == [0, 0, 2]


def test_bad_inputs():
    with pytest.raises(AutomatonError, match="shape"):
        RabinAutomaton(["a"], np.zeros((2, 3), int), 0, [])
    with pytest.raises(AutomatonError, match="not a state"):
        RabinAutomaton(["a"], np.array([[0, 5]]), 0, [])
    with pytest.raises(AutomatonError, match="initial"):
        RabinAutomaton(["a"], np.array([[0, 0]]), 3, [])
    with pytest.raises(AutomatonError, match="pair 0"):
        RabinAutomaton(["a"], np.array([[0, 0]]), 0, [({4}, set())])
    with pytest.raises(UnknownPropositionError, match="'b'"):
        reach_avoid().step(0, {"b"})
    with pytest.raises(AutomatonError, match="non-empty"):
        reach_avoid().accepts([], [])
