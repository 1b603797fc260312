"""The grid abstraction of the world (docs/design.md, "Abstraction").

A :class:`GridWorld` is the cells of a :class:`~planner.geometry.GridGeometry` (indices,
point location and hop targets are defined there) with their labels, the enabled actions
and the absorbing ``out`` state, index ``nx * ny``, labelled with the hazard label; it builds
the abstraction's IMDP (:meth:`GridWorld.imdp_from_intervals`). Actions, index 0..7:
``N1, N2, E1, E2, S1, S2, W1, W2`` (:data:`~planner.geometry.ACTIONS`). A cell's action is
enabled iff its target cell is inside the world.

``out`` has exactly one enabled action, :data:`OUT_ACTION` (index 0, ``N1``), a self-loop
with bounds ``[1, 1]``; it stands for "stay", not for a hop.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from planner.errors import IndexOutOfRangeError, MissingRowError, ModelError
from planner.geometry import ACTION_OFFSETS, ACTIONS, GridGeometry
from planner.imdp.model import BOUND_TOLERANCE, IMDP

if TYPE_CHECKING:
    from planner.scenario import Scenario

__all__ = ["ACTIONS", "ACTION_OFFSETS", "OUT_ACTION", "GridWorld"]

OUT_ACTION = 0
"""The only enabled action of ``out``: a self-loop."""


class GridWorld(GridGeometry):
    """The cells of a grid geometry, their labels, the actions and the ``out`` state.

    Args:
        nx, ny: number of cells along x and y.
        cell: cell side in metres.
        labels: per-cell label sets, either a sequence of ``nx * ny`` iterables of names
            (flat index ``i * ny + j``) or an ``(nx, ny)`` object array (default: none).
        hazard_label: the label of ``out`` (and of hazard cells).

    Raises:
        ModelError: on a non-positive size or a label array of the wrong shape.
    """

    def __init__(
        self,
        nx: int,
        ny: int,
        cell: float = 1.0,
        labels: Sequence[Iterable[str]] | np.ndarray | None = None,
        hazard_label: str = "Haz",
    ) -> None:
        super().__init__(nx, ny, cell)
        n = self.n_cells
        if labels is None:
            cell_labels = [frozenset()] * n
        else:
            arr = labels
            if isinstance(labels, np.ndarray) and labels.ndim == 2:
                if labels.shape != (self.nx, self.ny):
                    raise ModelError(f"label array has shape {labels.shape}, expected ({nx}, {ny})")
                arr = labels.ravel(order="C")
            cell_labels = [frozenset([x] if isinstance(x, str) else (x or ())) for x in list(arr)]
            if len(cell_labels) != n:
                raise ModelError(f"{len(cell_labels)} label sets for {n} cells")
        self.hazard_label = str(hazard_label)
        self.labels: tuple[frozenset[str], ...] = (
            *cell_labels,
            frozenset({self.hazard_label}),
        )
        self.propositions: tuple[str, ...] = tuple(sorted(set().union(*self.labels)))
        ti, tj = self.hop_targets[..., 0], self.hop_targets[..., 1]
        inside = (ti >= 0) & (ti < self.nx) & (tj >= 0) & (tj < self.ny)
        self.target_cell: np.ndarray = np.where(inside, ti * self.ny + tj, -1)
        """``(n_cells, 8)`` target cell index of each action (-1: not enabled)."""
        enabled = np.zeros((n + 1, len(ACTIONS)), dtype=bool)
        enabled[:n] = inside
        enabled[n, OUT_ACTION] = True
        self.enabled: np.ndarray = enabled
        """``(n_states, 8)`` enabled actions (``out``: only :data:`OUT_ACTION`)."""
        self.target_centres: np.ndarray = np.where(
            inside[..., None], self.hop_target_centres, np.nan
        )
        """``(n_cells, 8, 2)`` target centre in metres (NaN where not enabled)."""
        for a in (self.target_cell, self.enabled, self.target_centres):
            a.setflags(write=False)

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> GridWorld:
        """The grid of ``scenario``'s world with its cells' labels and its hazard label."""
        w = scenario.world
        return cls(w.nx, w.ny, w.cell, scenario.cell_labels, scenario.hazard)

    @property
    def n_states(self) -> int:
        return self.n_cells + 1

    @property
    def out(self) -> int:
        """Index of the absorbing ``out`` state (:attr:`outside`)."""
        return self.outside

    def label_mask(self, name: str) -> np.ndarray:
        """``(n_states,)`` mask of the states carrying label ``name``."""
        return np.array([name in ls for ls in self.labels], dtype=bool)

    def imdp_from_intervals(
        self,
        state: np.ndarray,
        action: np.ndarray,
        successor: np.ndarray,
        lower: np.ndarray,
        upper: np.ndarray,
        initial: Iterable[int] = (0,),
        tolerance: float = BOUND_TOLERANCE,
    ) -> IMDP:
        """The IMDP of this grid from COO interval arrays.

        ``state`` must be cells (``out``'s self-loop is added here) and ``action`` an
        enabled action of its cell; every enabled (cell, action) needs at least one entry.

        Raises:
            IndexOutOfRangeError: a state that is not a cell or a disabled action.
            MissingRowError: an enabled (cell, action) without transitions.
            plus every error of :class:`IMDP`.
        """
        s = np.asarray(state, dtype=np.int64)
        a = np.asarray(action, dtype=np.int64)
        bad = np.flatnonzero((s < 0) | (s >= self.n_cells))
        if bad.size:
            raise IndexOutOfRangeError(
                f"entry {bad[0]}: state {s[bad[0]]} is not a cell index in [0, {self.n_cells})"
            )
        bad = np.flatnonzero((a < 0) | (a >= len(ACTIONS)))
        if bad.size:
            raise IndexOutOfRangeError(f"entry {bad[0]}: action {a[bad[0]]} is not in [0, 8)")
        bad = np.flatnonzero(~self.enabled[s, a])
        if bad.size:
            i, j = self.cell_ij(s[bad[0]])
            raise IndexOutOfRangeError(
                f"entry {bad[0]}: action {ACTIONS[a[bad[0]]]} of cell ({i}, {j}) leaves the "
                "world and is not enabled"
            )
        given = np.zeros_like(self.enabled)
        given[s, a] = True
        missing = np.argwhere(self.enabled[: self.n_cells] & ~given[: self.n_cells])
        if missing.size:
            c, act = missing[0]
            i, j = self.cell_ij(c)
            raise MissingRowError(
                f"enabled action {ACTIONS[act]} of cell ({i}, {j}) (state {c}) has no "
                f"transition intervals ({len(missing)} such pairs)"
            )
        return IMDP(
            self.n_states,
            np.append(s, self.out),
            np.append(a, OUT_ACTION),
            np.append(np.asarray(successor), self.out),
            np.append(np.asarray(lower, dtype=np.float64), 1.0),
            np.append(np.asarray(upper, dtype=np.float64), 1.0),
            n_actions=len(ACTIONS),
            labels=self.labels,
            propositions=self.propositions,
            initial=initial,
            action_names=ACTIONS,
            tolerance=tolerance,
        )

    def __repr__(self) -> str:
        return f"GridWorld(nx={self.nx}, ny={self.ny}, cell={self.cell})"
