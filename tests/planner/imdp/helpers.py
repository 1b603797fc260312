"""Small grid worlds and automata for the tests."""

from __future__ import annotations

import numpy as np

from planner.automaton import RabinAutomaton
from planner.imdp.grid import GridWorld


def until_automaton() -> RabinAutomaton:
    """``!Haz U Goal``: 0 waiting, 1 accepted (sink), 2 rejected (sink)."""
    # letters: bit 0 = Goal, bit 1 = Haz
    table = np.array([[0, 1, 2, 1], [1, 1, 1, 1], [2, 2, 2, 2]])
    return RabinAutomaton(("Goal", "Haz"), table, 0, [({1}, set())])


def corridor_intervals(grid: GridWorld, spill: float = 0.1):
    """Each hop lands on its target with [1 - 2 spill, 1] and on the x-neighbours of the
    target that are inside the world with [0, spill] (a 1-row world: ny == 1)."""
    cells, acts = np.nonzero(grid.enabled[: grid.n_cells])
    tgt = grid.target_cell[cells, acts]
    s, a, t, lo, up = [], [], [], [], []
    for d, (l_, u_) in ((-1, (0.0, spill)), (0, (1 - 2 * spill, 1.0)), (1, (0.0, spill))):
        ti = tgt // grid.ny + d
        ok = (ti >= 0) & (ti < grid.nx)
        s.append(cells[ok])
        a.append(acts[ok])
        t.append(ti[ok] * grid.ny)
        lo.append(np.full(ok.sum(), l_))
        up.append(np.full(ok.sum(), u_))
    return tuple(np.concatenate(x) for x in (s, a, t, lo, up))
