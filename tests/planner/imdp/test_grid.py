import numpy as np
import pytest

from planner.errors import IndexOutOfRangeError, MissingRowError, ModelError
from planner.imdp.grid import ACTIONS, OUT_ACTION, GridWorld


def test_indexing_actions_and_out():
    g = GridWorld(3, 2, cell=0.5, labels=[(), ("A",), (), (), ("Goal",), ()])
    assert g.n_states == 7 and g.out == 6
    assert g.labels[g.out] == frozenset({"Haz"})
    assert g.propositions == ("A", "Goal", "Haz")
    assert g.cell_index(1, 1) == 3 and g.cell_index(3, 0) == g.out
    assert g.locate(np.array([[0.74, 0.6], [1.49, 0.99], [-0.01, 0.2]])).tolist() == [3, 5, 6]
    # cell (1, 0): N1 -> (1, 1) enabled, N2 -> (1, 2) outside, E1 -> (2, 0), W2 -> (-1, 0)
    c = g.cell_index(1, 0)
    assert dict(zip(ACTIONS, g.enabled[c].tolist(), strict=True)) == {
        "N1": True,
        "N2": False,
        "E1": True,
        "E2": False,
        "S1": False,
        "S2": False,
        "W1": True,
        "W2": False,
    }
    assert g.target_cell[c, ACTIONS.index("E1")] == g.cell_index(2, 0)
    assert g.target_centres[c, 0].tolist() == [0.75, 0.75]
    assert np.isnan(g.target_centres[c, 1]).all()
    assert g.enabled[g.out].tolist() == [i == OUT_ACTION for i in range(8)]


def test_label_array_in_c_order():
    lab = np.empty((2, 3), dtype=object)
    lab[:] = [[(), (), ("x",)], [(), (), ()]]
    g = GridWorld(2, 3, labels=lab)
    assert g.labels[2] == frozenset({"x"})
    with pytest.raises(ModelError, match="shape"):
        GridWorld(3, 2, labels=lab)


def test_imdp_from_intervals_validates():
    g = GridWorld(2, 1)
    # cell 0: E1 -> 1; cell 1: W1 -> 0
    m = g.imdp_from_intervals([0, 0, 1], [2, 2, 6], [0, 1, 0], [0, 0.9, 1], [0.1, 1, 1])
    assert m.n_states == 3 and m.action_names == ACTIONS
    assert m.enabled[g.out].tolist() == [i == OUT_ACTION for i in range(8)]
    with pytest.raises(MissingRowError, match="W1 of cell"):
        g.imdp_from_intervals([0, 0], [2, 2], [0, 1], [0, 0.9], [0.1, 1])
    with pytest.raises(IndexOutOfRangeError, match="E1 of cell \\(1, 0\\)"):
        g.imdp_from_intervals([0, 1, 1], [2, 6, 2], [1, 0, 1], [1, 1, 1], [1, 1, 1])
    with pytest.raises(IndexOutOfRangeError, match="not a cell"):
        g.imdp_from_intervals([2], [0], [0], [1], [1])
