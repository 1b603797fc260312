"""The world of a scenario: a rectangle of square cells, and regions of cells.

The world is ``width x height`` metres with its origin at the lower-left corner, split into
``nx x ny`` square cells of side ``cell`` metres; cell ``(i, j)`` covers
``[i*cell, (i+1)*cell) x [j*cell, (j+1)*cell)`` and has the flat index ``i * ny + j``
(:class:`planner.geometry.GridGeometry`).

A region is a union of axis-aligned rectangles ``[x0, y0, x1, y1]`` in world metres and of
single cells ``[i, j]``. A rectangle covers the cells whose centres lie in
``[x0, x1) x [y0, y1)``; a cell-aligned rectangle therefore covers exactly the cells inside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from planner.errors import ScenarioValueError
from planner.geometry import GridGeometry

#: Most cells of a scenario's grid. The transition intervals of a synthesis are dense
#: (rows x cells, :func:`planner.intervals.transition_intervals`), so memory grows with the
#: square of the cells: ``imdp export --scenario`` of 45 x 45 cells took 1.2 GB, of 64 x 64
#: 3.6 GB, of 256 x 256 it asked for 254 GiB.
MAX_CELLS = 1 << 11

Rect = tuple[float, float, float, float]
Cell = tuple[int, int]


@dataclass(frozen=True)
class World:
    """A rectangle ``[0, width) x [0, height)`` in metres, split into square cells; their
    indices and point location are :attr:`geometry`'s.

    Raises:
        ScenarioValueError: on a non-positive size or cell, or a size that is not a whole
            number of cells.
    """

    width: float
    height: float
    cell: float = 1.0

    def __post_init__(self) -> None:
        for name in ("width", "height", "cell"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                key = "world.cell" if name == "cell" else "world.size"
                raise ScenarioValueError(
                    f"{name} must be positive and finite, got {value}", key=key
                )
        cells = (self.width / self.cell) * (self.height / self.cell)
        if not cells <= MAX_CELLS:
            raise ScenarioValueError(
                f"a {self.width} x {self.height} m world of {self.cell} m cells has {cells:.4g} "
                f"cells, more than the limit of {MAX_CELLS}",
                key="world.size",
            )
        for name in ("width", "height"):
            n = getattr(self, name) / self.cell
            if abs(n - round(n)) > 1e-9 * max(1.0, n):
                raise ScenarioValueError(
                    f"{name} {getattr(self, name)} m is not a whole number of {self.cell} m cells",
                    key="world.size",
                )

    @property
    def nx(self) -> int:
        """Number of cells along x."""
        return round(self.width / self.cell)

    @property
    def ny(self) -> int:
        """Number of cells along y."""
        return round(self.height / self.cell)

    @property
    def n_cells(self) -> int:
        """``nx * ny``; also the index of the ``out`` state."""
        return self.geometry.n_cells

    @cached_property
    def geometry(self) -> GridGeometry:
        """The ``nx x ny`` cells of side :attr:`cell`: indices, point location, centres."""
        return GridGeometry(self.nx, self.ny, self.cell)


@dataclass(frozen=True)
class Region:
    """A union of rectangles ``(x0, y0, x1, y1)`` in metres and of cells ``(i, j)``."""

    rects: tuple[Rect, ...] = ()
    cells: tuple[Cell, ...] = ()

    def mask(self, world: World) -> np.ndarray:
        """Boolean ``(nx, ny)`` array of the covered cells (no bounds checks; see Scenario)."""
        centers = world.geometry.centres().reshape(world.nx, world.ny, 2)
        out = np.zeros((world.nx, world.ny), dtype=bool)
        if self.rects:
            r = np.asarray(self.rects, dtype=float)  # (R, 4)
            x = centers[None, :, :, 0]
            y = centers[None, :, :, 1]
            inside = (
                (x >= r[:, 0, None, None])
                & (x < r[:, 2, None, None])
                & (y >= r[:, 1, None, None])
                & (y < r[:, 3, None, None])
            )
            out |= inside.any(axis=0)
        if self.cells:
            c = np.asarray(self.cells, dtype=np.int64)
            out[c[:, 0], c[:, 1]] = True
        return out
