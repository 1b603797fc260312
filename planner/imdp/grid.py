"""The grid abstraction of the world (docs/design.md, "Abstraction").

The world is ``nx x ny`` cells of side ``cell`` metres with its origin at the lower-left
corner; cell ``(i, j)`` covers ``[i*cell, (i+1)*cell) x [j*cell, (j+1)*cell)`` and has flat
index ``i * ny + j``. State ``nx * ny`` is the absorbing ``out`` state, labelled with the
hazard label. Actions, index 0..7: ``N1, N2, E1, E2, S1, S2, W1, W2`` (N = +y, E = +x; hop
1 or 2 cells). A cell's action is enabled iff its target cell is inside the world.

``out`` has exactly one enabled action, :data:`OUT_ACTION` (index 0, ``N1``), a self-loop
with bounds ``[1, 1]``; it stands for "stay", not for a hop.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from planner.errors import IndexOutOfRangeError, MissingRowError, ModelError
from planner.imdp.model import BOUND_TOLERANCE, IMDP

ACTIONS: tuple[str, ...] = ("N1", "N2", "E1", "E2", "S1", "S2", "W1", "W2")
"""Action names in index order."""

ACTION_OFFSETS: np.ndarray = np.array(
    [[0, 1], [0, 2], [1, 0], [2, 0], [0, -1], [0, -2], [-1, 0], [-2, 0]], dtype=np.int64
)
"""``(8, 2)`` cell offsets ``(di, dj)`` of the actions."""
ACTION_OFFSETS.setflags(write=False)

OUT_ACTION = 0
"""The only enabled action of ``out``: a self-loop."""


class GridWorld:
    """The cells, their labels, the actions and the ``out`` state.

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
        if int(nx) <= 0 or int(ny) <= 0 or not float(cell) > 0:
            raise ModelError(f"grid needs nx, ny >= 1 and cell > 0, got {nx}, {ny}, {cell}")
        self.nx, self.ny, self.cell = int(nx), int(ny), float(cell)
        n = self.nx * self.ny
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
        i, j = self.cell_ij(np.arange(n))
        ti = i[:, None] + ACTION_OFFSETS[None, :, 0]
        tj = j[:, None] + ACTION_OFFSETS[None, :, 1]
        inside = (ti >= 0) & (ti < self.nx) & (tj >= 0) & (tj < self.ny)
        self.target_cell: np.ndarray = np.where(inside, ti * self.ny + tj, -1)
        """``(n_cells, 8)`` target cell index of each action (-1: not enabled)."""
        enabled = np.zeros((n + 1, len(ACTIONS)), dtype=bool)
        enabled[:n] = inside
        enabled[n, OUT_ACTION] = True
        self.enabled: np.ndarray = enabled
        """``(n_states, 8)`` enabled actions (``out``: only :data:`OUT_ACTION`)."""
        centres = np.stack([(ti + 0.5) * self.cell, (tj + 0.5) * self.cell], axis=-1)
        self.target_centres: np.ndarray = np.where(inside[..., None], centres, np.nan)
        """``(n_cells, 8, 2)`` target centre in metres (NaN where not enabled)."""
        for a in (self.target_cell, self.enabled, self.target_centres):
            a.setflags(write=False)

    @property
    def n_cells(self) -> int:
        return self.nx * self.ny

    @property
    def n_states(self) -> int:
        return self.n_cells + 1

    @property
    def out(self) -> int:
        """Index of the absorbing ``out`` state."""
        return self.n_cells

    def cell_index(self, i: np.ndarray | int, j: np.ndarray | int) -> np.ndarray:
        """Flat index ``i * ny + j`` (``out`` where ``(i, j)`` lies outside the world)."""
        i, j = np.asarray(i), np.asarray(j)
        inside = (i >= 0) & (i < self.nx) & (j >= 0) & (j < self.ny)
        return np.where(inside, i * self.ny + j, self.out)

    def cell_ij(self, index: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """``(i, j)`` of flat cell indices."""
        index = np.asarray(index)
        return index // self.ny, index % self.ny

    def locate(self, xy: np.ndarray) -> np.ndarray:
        """State index of points ``xy`` (shape ``(..., 2)``, metres); ``out`` outside."""
        xy = np.asarray(xy, dtype=np.float64)
        ij = np.floor(xy / self.cell).astype(np.int64)
        return self.cell_index(ij[..., 0], ij[..., 1])

    def centres(self) -> np.ndarray:
        """``(n_cells, 2)`` cell centres in metres."""
        i, j = self.cell_ij(np.arange(self.n_cells))
        return np.stack([(i + 0.5) * self.cell, (j + 0.5) * self.cell], axis=-1)

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
