"""PNG figures of navigation runs, in the style of the paper's Figure 4.

A figure shows the grid world seen from above with its coloured regions (initial region blue,
goal green, hazards red, ``A``/``B`` purple with their letters, weak hazards pink, other labels
from a fixed cycle), the CoM path of every hop projected on the ground, the landing points
(orange in exploration, dark red in goal reaching, crossed where the backup switch replaced
the action), the start (a star), and a title with the outcome,
the number of hops and the reward. Coordinates are world metres.

Rendering uses matplotlib's Agg canvas directly (no pyplot state, no display needed). Files
are written atomically: to a temporary file in the same folder, then moved into place.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from hopper_sim.events import HopEvent, Observer, RunEnd, RunStart
from hopper_sim.provenance import as_text
from hopper_sim.styles import INITIAL_COLOR, label_colors
from planner.atomic import atomic_write
from planner.scenario import Scenario

EXPLORATION_COLOR = "#ff8c00"
GOAL_REACHING_COLOR = "#8b0000"
_LETTER_LABELS = ("A", "B")


class FigureError(ValueError):
    """A figure cannot be written (bad size, missing folder...)."""


def _rgb(color: tuple[int, int, int]) -> np.ndarray:
    return np.asarray(color, dtype=float) / 255.0


def region_image(scenario: Scenario) -> np.ndarray:
    """RGB image ``(ny, nx, 3)`` in [0, 1] of the cells, row 0 at y = 0 (for ``origin="lower"``).

    Background white; then the initial region, the labels in scenario order, goal and hazard
    on top, so a hazard cell always shows red.
    """
    w = scenario.world
    image = np.ones((w.nx, w.ny, 3))
    image[scenario.initial_mask] = _rgb(INITIAL_COLOR)
    colors = label_colors(scenario.labels, scenario.goal, scenario.hazard)
    order = [lab for lab in scenario.regions if lab not in (scenario.goal, scenario.hazard)]
    order += [lab for lab in (scenario.goal, scenario.hazard) if lab in scenario.regions]
    for label in order:
        image[scenario.region_mask(label)] = _rgb(colors[label])
    return image.transpose(1, 0, 2)


def render_run_figure(
    scenario: Scenario,
    hops: Sequence[HopEvent],
    path: str | os.PathLike[str],
    *,
    end: RunEnd | None = None,
    run_index: int | None = None,
    size_inches: tuple[float, float] = (6.0, 6.0),
    dpi: int = 100,
    metadata: dict[str, Any] | None = None,
) -> Path:
    """Draw one run over its scenario and write it as a PNG of ``size_inches * dpi`` pixels.

    Args:
        scenario: the world and regions.
        hops: the run's hops, in order (may be empty).
        path: the PNG to write; its folder must exist.
        end: the run's end event, for the title (outcome, steps, reward).
        run_index: shown in the title (default: from ``end`` or the hops).
        size_inches: figure size; with ``dpi`` it sets the pixel size exactly.
        dpi: dots per inch.
        metadata: written as PNG text chunks, values as text (e.g. the provenance of
            :func:`hopper_sim.provenance.provenance`).

    Returns:
        The path written.

    Raises:
        FigureError: a non-positive size, or the folder of ``path`` does not exist.
    """
    path = Path(path)
    if min(size_inches) <= 0 or dpi <= 0:
        raise FigureError(f"figure size {size_inches} in at {dpi} dpi must be positive")
    if not path.parent.is_dir():
        raise FigureError(f"cannot write {path}: folder {path.parent} missing")
    w = scenario.world
    fig = Figure(figsize=size_inches, dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.08, 0.07, 0.88, 0.84))
    ax.imshow(
        region_image(scenario),
        extent=(0.0, w.width, 0.0, w.height),
        origin="lower",
        interpolation="nearest",
    )
    ax.vlines(np.arange(w.nx + 1) * w.cell, 0, w.height, colors="0.75", linewidths=0.5)
    ax.hlines(np.arange(w.ny + 1) * w.cell, 0, w.width, colors="0.75", linewidths=0.5)
    centers = w.cell_centers().reshape(w.nx, w.ny, 2)
    for label in _LETTER_LABELS:
        for x, y in centers[scenario.region_mask(label)]:
            ax.text(x, y, label, ha="center", va="center", color="white", fontsize=8, weight="bold")

    if hops:
        for hop in hops:
            ax.plot(hop.com_path[:, 0], hop.com_path[:, 1], color="0.25", linewidth=0.6)
        landings = np.array([h.landing for h in hops])
        route = np.vstack([hops[0].start_pos, landings])
        ax.plot(route[:, 0], route[:, 1], color="black", linewidth=1.0, alpha=0.6)
        goal = np.array([h.phase == "goal_reaching" for h in hops])
        for mask, color in ((~goal, EXPLORATION_COLOR), (goal, GOAL_REACHING_COLOR)):
            ax.scatter(
                landings[mask, 0], landings[mask, 1], s=14, color=color, zorder=3, linewidths=0
            )
        backup = np.array([h.backup for h in hops])
        if backup.any():
            ax.scatter(
                landings[backup, 0], landings[backup, 1], s=40, marker="x", color="black", zorder=4
            )
    ax.scatter(*scenario.start, s=60, marker="*", color="white", edgecolors="black", zorder=4)
    ax.set_xlim(0, w.width)
    ax.set_ylim(0, w.height)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(
        handles=[
            Line2D([], [], marker="o", linestyle="", color=EXPLORATION_COLOR, label="exploration"),
            Line2D(
                [], [], marker="o", linestyle="", color=GOAL_REACHING_COLOR, label="goal reaching"
            ),
            Line2D([], [], marker="x", linestyle="", color="black", label="backup action"),
        ],
        loc="upper right",
        fontsize=7,
        framealpha=0.8,
    )
    k = run_index if run_index is not None else (end.run_index if end else None)
    if k is None and hops:
        k = hops[0].run_index
    title = f"scenario {scenario.name}" + (f", run {k}" if k is not None else "")
    if end is not None:
        title += f": {end.outcome}, {end.steps} steps, reward {end.reward:g}"
    else:
        title += f": {len(hops)} hops"
    ax.set_title(title, fontsize=10)

    text = {"Software": "hopnav", **as_text(metadata or {})}
    with atomic_write(path) as f:
        fig.savefig(f, format="png", dpi=dpi, metadata=text)
    return path


class FigureWriter(Observer):
    """Observer collecting each run's hops and writing its PNG at ``on_run_end``.

    Args:
        path: where to write: a callable ``run_index -> path``, or a path that may hold
            ``{run}`` (formatted with the run index). A fixed path is overwritten by every
            run, so it keeps the last run's figure (the paper shows the tenth run of (c)/(d)).
        size_inches, dpi, metadata: as in :func:`render_run_figure`.

    Attributes:
        written: the paths written, in order.
    """

    def __init__(
        self,
        path: str | os.PathLike[str] | Callable[[int], str | os.PathLike[str]],
        *,
        size_inches: tuple[float, float] = (6.0, 6.0),
        dpi: int = 100,
        metadata: dict[str, Any] | None = None,
    ) -> None:
        self._path = path
        self.metadata = metadata
        self.size_inches = size_inches
        self.dpi = dpi
        self._scenario: dict[int, Scenario] = {}
        self._hops: dict[int, list[HopEvent]] = {}
        self.written: list[Path] = []

    def path_for(self, run_index: int) -> Path:
        """The file written for ``run_index``."""
        if callable(self._path):
            return Path(self._path(run_index))
        return Path(str(self._path).replace("{run}", str(run_index)))

    def on_run_start(self, event: RunStart) -> None:
        self._scenario[event.run_index] = event.scenario
        self._hops[event.run_index] = []

    def on_hop(self, event: HopEvent) -> None:
        self._hops.setdefault(event.run_index, []).append(event)

    def on_run_end(self, event: RunEnd) -> None:
        k = event.run_index
        if k not in self._scenario:
            raise FigureError(f"run {k} ended without a RunStart: no scenario to draw")
        out = render_run_figure(
            self._scenario.pop(k),
            self._hops.pop(k, []),
            self.path_for(k),
            end=event,
            size_inches=self.size_inches,
            dpi=self.dpi,
            metadata=self.metadata,
        )
        self.written.append(out)
