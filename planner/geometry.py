"""The grid geometry: square cells, their indices and the hops between them.

The world is ``nx x ny`` cells of side ``cell`` metres with its origin at the lower-left
corner; cell ``(i, j)`` covers ``[i*cell, (i+1)*cell) x [j*cell, (j+1)*cell)`` and has flat
index ``i * ny + j``. Every point outside the world maps to the index ``nx * ny``
(:attr:`GridGeometry.outside`; the abstraction's absorbing ``out`` state).

A hop action moves 1 or 2 cells along a compass direction; index 0..7:
``N1, N2, E1, E2, S1, S2, W1, W2`` (N = +y, E = +x; :data:`ACTION_OFFSETS`).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from planner.errors import ModelError

ACTIONS: tuple[str, ...] = ("N1", "N2", "E1", "E2", "S1", "S2", "W1", "W2")
"""Action names in index order."""

ACTION_OFFSETS: np.ndarray = np.array(
    [[0, 1], [0, 2], [1, 0], [2, 0], [0, -1], [0, -2], [-1, 0], [-2, 0]], dtype=np.int64
)
"""``(8, 2)`` cell offsets ``(di, dj)`` of the actions."""
ACTION_OFFSETS.setflags(write=False)


class GridGeometry:
    """``nx x ny`` square cells of side ``cell`` metres (see the module docstring).

    Raises:
        ModelError: on a non-positive size or cell.
    """

    def __init__(self, nx: int, ny: int, cell: float = 1.0) -> None:
        if int(nx) <= 0 or int(ny) <= 0 or not float(cell) > 0:
            raise ModelError(f"grid needs nx, ny >= 1 and cell > 0, got {nx}, {ny}, {cell}")
        self.nx, self.ny, self.cell = int(nx), int(ny), float(cell)

    @property
    def n_cells(self) -> int:
        return self.nx * self.ny

    @property
    def outside(self) -> int:
        """The index of every point (and cell ``(i, j)``) outside the world: ``nx * ny``."""
        return self.n_cells

    def cell_index(self, i: np.ndarray | int, j: np.ndarray | int) -> np.ndarray:
        """Flat index ``i * ny + j`` (:attr:`outside` where ``(i, j)`` lies outside)."""
        i, j = np.asarray(i), np.asarray(j)
        inside = (i >= 0) & (i < self.nx) & (j >= 0) & (j < self.ny)
        return np.where(inside, i * self.ny + j, self.outside)

    def cell_ij(self, index: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """``(i, j)`` of flat cell indices."""
        index = np.asarray(index)
        return index // self.ny, index % self.ny

    def locate(self, xy: np.ndarray) -> np.ndarray:
        """Flat cell index of points ``xy`` (shape ``(..., 2)``, metres); :attr:`outside`
        for points outside the world (and for NaN)."""
        xy = np.asarray(xy, dtype=np.float64)
        with np.errstate(invalid="ignore"):  # NaN and inf cast to an index outside
            ij = np.floor(xy / self.cell).astype(np.int64)
        return self.cell_index(ij[..., 0], ij[..., 1])

    def centres(self) -> np.ndarray:
        """``(n_cells, 2)`` cell centres in metres, flat-index order."""
        i, j = self.cell_ij(np.arange(self.n_cells))
        return np.stack([(i + 0.5) * self.cell, (j + 0.5) * self.cell], axis=-1)

    @cached_property
    def hop_targets(self) -> np.ndarray:
        """``(n_cells, 8, 2)`` cell ``(i, j)`` each action of each cell aims at (also where
        that lies outside the world), read-only."""
        i, j = self.cell_ij(np.arange(self.n_cells))
        target = np.stack([i, j], axis=-1)[:, None, :] + ACTION_OFFSETS[None]
        target.setflags(write=False)
        return target

    @cached_property
    def hop_target_centres(self) -> np.ndarray:
        """``(n_cells, 8, 2)`` centre in metres of each :attr:`hop_targets` cell, read-only."""
        centres = (self.hop_targets + 0.5) * self.cell
        centres.setflags(write=False)
        return centres

    def __repr__(self) -> str:
        return f"GridGeometry(nx={self.nx}, ny={self.ny}, cell={self.cell})"
