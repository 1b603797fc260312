import numpy as np
import pytest

from planner.automaton import RabinAutomaton
from planner.imdp import analysis, graph
from planner.imdp.closed import closed_accepting
from planner.imdp.product import ProductIMDP
from tests.planner.imdp.reference import random_imdp
from tests.planner.imdp.test_graph import as_sets, mask, model

# letters: bit 0 = goal, bit 1 = bad; 0 waiting, 1 accepted (sink), 2 rejected (sink)
_TABLE = np.array([[0, 1, 2, 1], [1, 1, 1, 1], [2, 2, 2, 2]])


def _automata():
    until = RabinAutomaton(("goal", "bad"), _TABLE, 0, [({1}, set())])
    # a second pair whose G \ B (the waiting state) runs leave: the general analyses
    two = RabinAutomaton(("goal", "bad"), _TABLE, 0, [({1}, set()), ({0}, {2})])
    return until, two


def test_a_closed_accepting_set_and_one_that_runs_leave():
    # 0 -> {1, 2}; 1 -> 2; 2 -> {1, 2}: {1, 2} is closed, {0, 1} is not
    rows = [
        (0, 0, [(1, 0.5, 0.5), (2, 0.5, 0.5)]),
        (1, 0, [(2, 1.0, 1.0)]),
        (2, 0, [(1, 0.0, 0.5), (2, 0.5, 1.0)]),
    ]
    m = model(3, rows)
    none = np.zeros(3, dtype=bool)
    assert closed_accepting(m, mask(3, [0, 1, 2]), mask(3, [0])).tolist() == [0, 1, 1]
    assert closed_accepting(m, mask(3, [0, 1]), none) is None
    # an entry that may not carry mass (upper 0) does not leave
    rows[2] = (2, 0, [(1, 0.0, 0.5), (2, 0.5, 1.0), (0, 0.0, 0.0)])
    m = model(3, rows)
    assert closed_accepting(m, mask(3, [1, 2]), none).tolist() == [0, 1, 1]
    # a state without an allowed row stops a run: left out, and a row into it leaves
    allowed = np.ones(m.n_rows, dtype=bool)
    allowed[m.row_index[1, 0]] = False
    assert closed_accepting(m, mask(3, [1, 2]), none, allowed) is None
    assert closed_accepting(m, mask(3, [1]), none, allowed).tolist() == [0, 0, 0]


@pytest.mark.parametrize("zero_lower", [False, True])
def test_closed_pairs_give_what_the_end_component_searches_give(zero_lower, monkeypatch):
    rng = np.random.default_rng(7 + zero_lower)
    closed = leaving = 0
    for k in range(80):
        m = random_imdp(rng, int(rng.integers(5, 25)), 3, 4, zero_lower)
        p = ProductIMDP(m, _automata()[k % 2])
        pairs = zip(p.good, p.bad, strict=True)
        found = [closed_accepting(p.model, g, b) is not None for g, b in pairs]
        closed += sum(found)
        leaving += len(found) - sum(found)
        fail = analysis.failure_states(p)
        components = analysis.accepting_end_components(p)
        with monkeypatch.context() as mp:
            mp.setattr(analysis, "closed_accepting", lambda *a, **k: None)
            mp.setattr(graph, "closed_accepting", lambda *a, **k: None)
            assert analysis.failure_states(p).tolist() == fail.tolist()
            general = analysis.accepting_end_components(p)
        assert as_sets(components, p.model) == as_sets(general, p.model)
        assert [ec.pair for ec in components] == [ec.pair for ec in general]
    # the accepted sink's pair always; the waiting state's where no label is in reach
    assert closed >= 80 and leaving > 30
