"""The exploration's LTL action inside the chosen end component: a tour that keeps moving.

Inside the chosen MEC ``(T, Act)`` of the nonviolating sub-model every action of ``Act`` keeps
the robot in ``T`` under every adversary of the IMDP, so safety leaves the choice among them
free. A fixed choice (such as the component's lowest-index action) makes the robot shuttle
between two cells, so the data it collects for the GPs, and the reward it meets, stay where
it entered. The tour instead chooses targets afresh at every decision:

* ``mode="reward"`` (default): the component's cells of highest positive reward still to be
  collected (the robot heads for the rewarding cells that made the component the best
  choice); once none is left, as ``"coverage"``.
* ``mode="coverage"``: the component's cells that this run has visited least recently (cells
  never visited first) and, among those, the least known ones (largest ``uncertainty``, e.g.
  the width of a cell's landing-error interval), so exploration sweeps through the whole
  component, reaching first its frontier, where the data are thinnest and new data widen the
  safe region. (A tour that visits every state of the component equally often earns, in the
  long run, the component's average reward, the quantity by which the paper chooses it.)

The step towards the targets: every row (state, action) *aims* at one successor (``aim``:
for the grid, the cell the hop is aimed at; where it is not given, the successor of largest
upper bound). ``d(s)`` is the least number of aimed hops from ``s`` to a target through the
component (rows of ``Act`` only), and the action of ``Act`` in the current state whose aimed
successor has the least ``d`` wins, ties drawn from the run's generator. (Distances along all
``upper > 0`` edges would not do: under learned intervals a hop has small-probability
successors far to the side, and counting them as real moves sends the tour the wrong way.)
The current cell is never a target, so the tour always moves on. This is a heuristic for
where to go, with no probability claim: the component being closed is what keeps it safe.

The tour depends on the run's history (when each cell was last visited), which the paper's
control policies allow (maps from finite state sequences); :class:`planner.policy.SwitchingPolicy`
keeps that history.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from planner.errors import PolicyError
from planner.imdp import graph
from planner.imdp.graph import EndComponent
from planner.imdp.model import IMDP
from planner.modes import TourMode

TOUR_MODES: tuple[str, ...] = tuple(m.value for m in TourMode)
"""``reward``: rewarding cells first, then as ``coverage``; ``coverage``: least recently visited
(then least known) cells first."""


@dataclass(frozen=True)
class ComponentTour:
    """The in-component tour (see the module docstring).

    Attributes:
        model: the (product) IMDP.
        component: the end component toured.
        allowed: ``(n_states, n_actions)`` mask the tour's actions must also satisfy (the
            exploration phase's sub-model); the component's rows outside it are not used.
        state_cell: ``(n_states,)`` the cell of each state (the tour's targets are cells).
        reward: ``(n_states,)`` reward still to be collected per state (``mode="reward"``).
        uncertainty: ``(n_states,)`` how little is known where a state's cell is (larger: less
            known); among the cells unvisited for equally long the tour heads for the least
            known.
        mode: ``"reward"`` or ``"coverage"`` (:data:`TOUR_MODES`).
        aim: ``(n_rows,)`` the successor each row aims at (-1, or a state that is not one of
            the row's successors: the successor of largest upper bound); default: all -1.
    """

    model: IMDP
    component: EndComponent
    allowed: np.ndarray
    state_cell: np.ndarray
    reward: np.ndarray
    uncertainty: np.ndarray
    mode: TourMode = TourMode.REWARD
    aim: np.ndarray | None = None
    _rows: np.ndarray = field(init=False, repr=False)
    _inside: np.ndarray = field(init=False, repr=False)
    _reverse: sp.csr_matrix = field(init=False, repr=False)

    def __post_init__(self) -> None:
        m = self.model
        if self.mode not in TOUR_MODES:
            raise PolicyError(f"tour mode must be one of {TOUR_MODES}, got {self.mode!r}")
        cells = np.asarray(self.state_cell)
        reward = np.asarray(self.reward, dtype=np.float64)
        unc = np.asarray(self.uncertainty, dtype=np.float64)
        allowed = np.asarray(self.allowed, dtype=bool)
        if any(a.shape != (m.n_states,) for a in (cells, reward, unc)):
            raise PolicyError(f"state_cell, reward and uncertainty must have shape ({m.n_states},)")
        if allowed.shape != (m.n_states, m.n_actions):
            raise PolicyError(f"allowed must have shape ({m.n_states}, {m.n_actions})")
        rows = self.component.row_mask(m.n_rows) & graph.rows_from_actions(m, allowed)
        inside = self.component.state_mask(m.n_states) & graph.has_row(m, rows)
        object.__setattr__(self, "state_cell", cells.astype(np.int64))
        object.__setattr__(self, "reward", reward)
        object.__setattr__(self, "uncertainty", unc)
        object.__setattr__(self, "_rows", rows)
        object.__setattr__(self, "_inside", inside)
        aim = self._aimed_successors(np.full(m.n_rows, -1) if self.aim is None else self.aim)
        object.__setattr__(self, "aim", aim)
        idx = np.flatnonzero(rows)
        edges = sp.csr_matrix(
            (np.ones(idx.size, dtype=np.int8), (aim[idx], m.row_state[idx])),
            shape=(m.n_states, m.n_states),
        )
        object.__setattr__(self, "_reverse", edges)

    def _aimed_successors(self, aim: np.ndarray) -> np.ndarray:
        """``aim`` where it names a successor of its row, else the largest-upper successor."""
        m = self.model
        aim = np.asarray(aim, dtype=np.int64)
        if aim.shape != (m.n_rows,):
            raise PolicyError(f"aim must have shape ({m.n_rows},), got {aim.shape}")
        hit = m.successor == aim[m.entry_row]
        named = np.zeros(m.n_rows, dtype=bool)
        named[m.entry_row[hit]] = True
        # per row, the entry of largest upper bound (first of equals)
        order = np.lexsort((-m.upper, m.entry_row))
        first = order[np.searchsorted(m.entry_row[order], np.arange(m.n_rows))]
        return np.where(named, aim, m.successor[first])

    def with_reward(self, reward: np.ndarray) -> ComponentTour:
        """The same tour with a new reward still to be collected (e.g. after a collection)."""
        return replace(self, reward=reward)

    def covers(self, state: int) -> bool:
        """Whether ``state`` is in the component (with an allowed action of it)."""
        return bool(self._inside[state])

    def targets(self, state: int, last_visit: np.ndarray) -> np.ndarray:
        """Boolean ``(n_states,)`` mask of the states the tour heads for from ``state``.

        ``last_visit``: ``(n_states,)`` the step at which this run last was in each state, -1
        if never; a cell's last visit is the latest over its states.
        """
        here = self.state_cell[state]
        cells = self.state_cell
        cell_visit = np.full(int(cells.max()) + 1, -1, dtype=np.int64)
        np.maximum.at(cell_visit, cells, np.asarray(last_visit, dtype=np.int64))
        cand = self._inside & (cells != here)
        if not cand.any():
            return cand
        if self.mode == TourMode.REWARD:
            paying = cand & (self.reward > 0.0)
            if paying.any():
                return paying & (self.reward >= self.reward[paying].max())
        seen = cell_visit[cells]
        oldest = cand & (seen <= seen[cand].min())
        return oldest & (self.uncertainty >= self.uncertainty[oldest].max() - 1e-12)

    def action(self, state: int, last_visit: np.ndarray, rng: np.random.Generator) -> int:
        """The tour's action in ``state`` (-1 outside the component); ``last_visit`` as in
        :meth:`targets`; a tie costs one draw from ``rng``."""
        if not self._inside[state]:
            return -1
        m = self.model
        lo, hi = m.state_ptr[state], m.state_ptr[state + 1]
        rows = np.arange(lo, hi)[self._rows[lo:hi]]
        target = np.flatnonzero(self.targets(state, last_visit))
        if target.size == 0:
            score = np.zeros(rows.size)
        else:
            dist = dijkstra(self._reverse, unweighted=True, indices=target, min_only=True)
            score = np.where(np.isfinite(dist), dist, float(m.n_states))[self.aim[rows]]
        best = np.flatnonzero(score <= score.min())
        pick = best[0] if best.size == 1 else best[rng.integers(best.size)]
        return int(m.row_action[rows[pick]])
