"""Rabin pairs whose accepting part no run can leave (:func:`closed_accepting`).

For a pair ``(G, B)`` let ``S = G \\ B``. Where no allowed row of a state of ``S`` may
(``upper > 0``) leave it, a run that enters ``S`` stays in ``G`` and out of ``B`` for ever
and so satisfies the pair; and a run that satisfies the pair visits ``G`` infinitely often
and ``B`` finitely often, so it visits ``S``. Satisfying the pair is then *reaching* ``S``.
This is the shape of every co-safe formula's product (``!Haz U Goal``: the automaton's
accepting state is absorbing), and it spares the end-component searches of the general
case: :func:`planner.imdp.analysis.failure_states` and
:func:`planner.imdp.graph.accepting_end_components` take it where it holds.
"""

from __future__ import annotations

import numpy as np

from planner.imdp.kernels.pruning import closed_under
from planner.imdp.model import IMDP


def closed_accepting(
    model: IMDP, good: np.ndarray, bad: np.ndarray, rows: np.ndarray | None = None
) -> np.ndarray | None:
    """``S = good & ~bad`` (a mask over the states), restricted to the states with a row in
    ``rows`` (all rows by default), where no such row at a state of ``S`` has an
    ``upper > 0`` successor outside it; ``None`` where one has. A state without an allowed
    row stops a run there (it cannot satisfy the pair), so it is left out of ``S``, and a
    row into it then leaves ``S``."""
    m = model
    allowed = np.ones(m.n_rows, dtype=bool) if rows is None else np.asarray(rows, dtype=bool)
    s = np.asarray(good, dtype=bool) & ~np.asarray(bad, dtype=bool)
    s &= np.logical_or.reduceat(allowed, m.state_ptr[:-1])
    if not closed_under(s, allowed, m.state_ptr, m.row_ptr, m.successor, m.upper):
        return None
    return s
