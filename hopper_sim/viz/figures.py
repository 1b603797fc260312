"""Figures of navigation runs in the style of the paper's Figure 4 (PNG, SVG or PDF).

A map shows the grid world from above: every cell coloured by its class (initial region, goal,
hazard, optional regions, penalties, other labels; :mod:`hopper_sim.viz.styles`) with a letter on
each connected region, and, for a run, its route drawn once: each hop's CoM ground track,
coloured by phase (exploration yellow, goal reaching black, fallback teal dashed) with an
arrow at its middle pointing the way it went, crosses where the backup switch replaced the
action, a diamond where goal reaching began (the switch), and the start (star) and end
(square) on top. A legend lists every region class with its reward and the route's marks.
:func:`render_figure` draws one map or a grid of maps (two columns: ``a, b, c, d`` gives the
2 x 2 panel of Figure 4) with one shared legend.

Coordinates are world metres. The file's extension chooses the format: ``.png`` (raster,
:data:`PNG_DPI` dots per inch), ``.svg`` or ``.pdf`` (vector; cells, route and text are
vector objects). Files carry no creation date, so the same input gives the same file.
Rendering uses matplotlib's Agg canvas directly (no pyplot state, no display needed), and files
are written atomically (temporary file in the same folder, then moved into place).

The pieces live in siblings: :mod:`hopper_sim.viz.figure_files` (formats, destination checks,
the atomic save), :mod:`hopper_sim.viz.figure_map` (drawing one map and its route) and
:mod:`hopper_sim.viz.figure_legend` (the shared legend); this module holds the data drawn
(:class:`Route`, :class:`Panel`), the layout of one or several maps and the observer.

Runs are numbered from 1 in every title (``RunStart.run_index`` + 1), as in the summary table
of ``hopnav run``, ``hopnav replay`` and the recording's entity paths.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hopper_sim.navigation.events import HopEvent, Observer, RunEnd, RunStart
from hopper_sim.viz.figure_files import FIGURE_FORMATS as FIGURE_FORMATS  # re-exported
from hopper_sim.viz.figure_files import (
    PNG_DPI,
    FigureError,
    check_destination,
    figure_format,
    new_figure,
    save_figure,
)
from hopper_sim.viz.figure_legend import add_legend, region_handles, route_handles
from hopper_sim.viz.figure_map import draw_route, draw_world, route_cover
from hopper_sim.viz.figure_map import region_image as region_image  # re-exported
from planner.modes import Outcome

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from planner.scenario import Scenario


# --------------------------------------------------------------------------- data
@dataclass(frozen=True)
class Route:
    """A run's path as drawn.

    Attributes:
        start: ``(2,)`` CoM position where the run began, m.
        tracks: per hop, ``(T, 2)`` ground track of the CoM from its departure to its landing
            (or just ``[start, landing]``), m.
        phases: per hop, the phase (``exploration``, ``goal_reaching``, ``fallback``).
        backups: ``(n,)`` whether the backup switch replaced the hop's action.
        switch_step: the 0-based hop at which goal reaching began, or ``None``.
    """

    start: np.ndarray
    tracks: tuple[np.ndarray, ...]
    phases: tuple[str, ...]
    backups: np.ndarray
    switch_step: int | None = None

    def __post_init__(self) -> None:
        n = len(self.tracks)
        if len(self.phases) != n or len(self.backups) != n:
            raise FigureError(
                f"route: {n} tracks, {len(self.phases)} phases, {len(self.backups)} backups"
            )

    @classmethod
    def from_hops(
        cls, hops: Sequence[HopEvent], start: Sequence[float], switch_step: int | None = None
    ) -> Route:
        """The route of ``hops`` (in order) starting from ``start``."""
        tracks = []
        for h in hops:
            path = np.asarray(h.com_path)[:, :2]
            tracks.append(path if len(path) >= 2 else np.stack([h.start_pos, h.landing]))
        return cls(
            start=np.asarray(start, dtype=float),
            tracks=tuple(tracks),
            phases=tuple(h.phase for h in hops),
            backups=np.array([h.backup for h in hops], dtype=bool),
            switch_step=switch_step,
        )

    @property
    def n_hops(self) -> int:
        return len(self.tracks)

    @property
    def end(self) -> np.ndarray:
        """Where the run ended (the last landing, or the start)."""
        return self.tracks[-1][-1] if self.tracks else self.start


@dataclass(frozen=True)
class Panel:
    """One map of a figure: a scenario, optionally a run's route, and a title."""

    scenario: Scenario
    route: Route | None = None
    title: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def run_title(
    scenario: Scenario,
    *,
    run_number: int | None = None,
    n_runs: int | None = None,
    end: RunEnd | None = None,
    hops: int | None = None,
) -> str:
    """``"scenario a, run 10 of 10: success, 92 hops, reward 132.5"`` (runs 1-based)."""
    title = f"scenario {scenario.name}"
    if run_number is not None:
        title += f", run {run_number}" + (f" of {n_runs}" if n_runs else "")
    if end is not None:
        mission = getattr(end, "mission", None)
        what = end.outcome
        if end.outcome == Outcome.SATISFYING and mission is not None:
            what += f" ({mission.obligation})"
        title += f": {what}, {end.steps} hops, reward {end.reward:g}"
    elif hops is not None:
        title += f": {hops} hops"
    return title


def scenario_title(scenario: Scenario) -> str:
    """Title of a map without a run: name, formula, P_sat and whether the reward is known."""
    known = "known" if scenario.reward_known else "unknown"
    return (
        f"scenario {scenario.name}: {scenario.formula}, P_sat = {scenario.p_sat:g}, {known} reward"
    )


# --------------------------------------------------------------------------- figures
def build_figure(
    panels: Sequence[Panel],
    *,
    size_inches: tuple[float, float] | None = None,
    dpi: int = PNG_DPI,
    columns: int = 2,
) -> Figure:
    """Draw ``panels`` (one map each) with one legend on a new figure.

    One panel: the map with the legend on its right. Several: a grid of ``columns`` columns,
    row by row, with the shared legend below (four panels give the 2 x 2 Figure 4).

    Args:
        panels: the maps.
        size_inches: figure size (default: 8 x 5.6 for one map, 5 in per map otherwise).
        dpi: resolution of a PNG.
        columns: columns of the grid of several panels.

    Raises:
        FigureError: no panels or a bad size.
    """
    if not panels:
        raise FigureError("a figure needs at least one panel")
    routes = [p.route for p in panels if p.route is not None]
    handles = region_handles([p.scenario for p in panels]) + route_handles(routes)
    if len(panels) == 1:
        (panel,) = panels
        fig = new_figure(size_inches or (8.0, 5.6), dpi)
        ax = fig.add_axes((0.075, 0.09, 0.56, 0.82))
        _draw_panel(ax, panel)
        add_legend(ax, handles, loc="center left", bbox_to_anchor=(1.03, 0.5), borderaxespad=0.0)
        return fig
    cols = max(1, min(columns, len(panels)))
    rows = math.ceil(len(panels) / cols)
    legend_h = 0.2 * math.ceil(len(handles) / 3) + 0.3
    fig = new_figure(size_inches or (5.0 * cols, 5.0 * rows + legend_h), dpi)
    bottom = legend_h / fig.get_size_inches()[1]
    gs = fig.add_gridspec(
        rows, cols, left=0.07, right=0.98, top=0.96, bottom=bottom + 0.04, hspace=0.25, wspace=0.18
    )
    for k, panel in enumerate(panels):
        _draw_panel(fig.add_subplot(gs[k // cols, k % cols]), panel)
    add_legend(fig, handles, loc="lower center", ncol=3, bbox_to_anchor=(0.5, 0.005))
    return fig


def render_figure(
    panels: Sequence[Panel],
    path: str | os.PathLike[str],
    *,
    size_inches: tuple[float, float] | None = None,
    dpi: int = PNG_DPI,
    columns: int = 2,
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Draw ``panels`` (:func:`build_figure`) and write them to ``path`` (``.png``, ``.svg``
    or ``.pdf``; its folder must exist), with ``metadata`` as in :func:`save_figure`.

    Returns:
        The path written.

    Raises:
        FigureError: no panels, an unknown extension, a missing folder or a bad size.
    """
    check_destination(path)
    fig = build_figure(panels, size_inches=size_inches, dpi=dpi, columns=columns)
    return save_figure(fig, path, dpi=dpi, metadata=metadata)


def _draw_panel(ax: Axes, panel: Panel) -> None:
    draw_world(ax, panel.scenario, route_cover(panel.scenario, panel.route))
    if panel.route is not None:
        draw_route(ax, panel.route, panel.scenario)
    ax.set_title(panel.title or scenario_title(panel.scenario), fontsize=9)


def render_run_figure(
    scenario: Scenario,
    hops: Sequence[HopEvent],
    path: str | os.PathLike[str],
    *,
    end: RunEnd | None = None,
    run_index: int | None = None,
    n_runs: int | None = None,
    size_inches: tuple[float, float] | None = None,
    dpi: int = PNG_DPI,
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Draw one run (or, with no hops and no ``end``, the empty world) and write it.

    Args:
        scenario: the world and regions.
        hops: the run's hops, in order (may be empty).
        path: ``.png``, ``.svg`` or ``.pdf``; its folder must exist.
        end: the run's end event, for the title and the switch mark.
        run_index: the 0-based run index (shown 1-based; default from ``end`` or the hops).
        n_runs: runs in the invocation, for the title (``run 10 of 10``).
        size_inches, dpi: as in :func:`render_figure`.
        metadata: written into the file (e.g. the provenance of
            :func:`hopper_sim.experiments.provenance.provenance`), as in :func:`save_figure`.

    Raises:
        FigureError: an unknown extension, a missing folder or a bad size.
    """
    if not hops and end is None and run_index is None:
        return render_figure(
            [Panel(scenario)], path, size_inches=size_inches, dpi=dpi, metadata=metadata
        )
    k = run_index if run_index is not None else (end.run_index if end else None)
    if k is None and hops:
        k = hops[0].run_index
    route = Route.from_hops(hops, scenario.start, end.switch_step if end else None)
    title = run_title(
        scenario,
        run_number=None if k is None else k + 1,
        n_runs=n_runs,
        end=end,
        hops=len(hops),
    )
    return render_figure(
        [Panel(scenario, route, title)],
        path,
        size_inches=size_inches,
        dpi=dpi,
        metadata=metadata,
    )


class FigureWriter(Observer):
    """Observer collecting each run's hops and writing its figure.

    Args:
        path: where to write: a callable ``run_number -> path`` (1-based), or a path that may
            hold ``{run}`` (formatted with the 1-based run number): each run's figure is
            written at its ``on_run_end``. A fixed path (no ``{run}``) keeps only the last
            finished run (the paper shows the tenth run of (c)/(d)), written once, on
            :meth:`close`. The extension chooses the format.
        n_runs: runs in the invocation, for the titles.
        size_inches, dpi: as in :func:`render_figure`.
        metadata: written into every figure, as in :func:`render_run_figure`.

    Attributes:
        written: the paths written, in order.

    Raises:
        FigureError: the extension of ``path`` (if not a callable) is unknown.
    """

    def __init__(
        self,
        path: str | os.PathLike[str] | Callable[[int], str | os.PathLike[str]],
        *,
        n_runs: int | None = None,
        size_inches: tuple[float, float] | None = None,
        dpi: int = PNG_DPI,
        metadata: Mapping[str, Any] | None = None,
    ) -> None:
        if not callable(path):
            figure_format(path)
        self._path = path
        self._per_run = callable(path) or "{run}" in str(path)
        self.n_runs = n_runs
        self.metadata = metadata
        self.size_inches = size_inches
        self.dpi = dpi
        self._scenario: dict[int, Scenario] = {}
        self._hops: dict[int, list[HopEvent]] = {}
        self._last: tuple[Scenario, list[HopEvent], RunEnd] | None = None
        self.written: list[Path] = []

    def path_for(self, run_index: int) -> Path:
        """The file written for the 0-based ``run_index`` (named by its 1-based number)."""
        if callable(self._path):
            return Path(self._path(run_index + 1))
        return Path(str(self._path).replace("{run}", str(run_index + 1)))

    def on_run_start(self, event: RunStart) -> None:
        self._scenario[event.run_index] = event.scenario
        self._hops[event.run_index] = []

    def on_hop(self, event: HopEvent) -> None:
        self._hops.setdefault(event.run_index, []).append(event)

    def on_run_end(self, event: RunEnd) -> None:
        k = event.run_index
        if k not in self._scenario:
            raise FigureError(f"run {k + 1} ended without a RunStart: no scenario to draw")
        self._last = (self._scenario.pop(k), self._hops.pop(k, []), event)
        if self._per_run:
            self._write()

    def close(self) -> None:
        """Write the last finished run's figure (for a fixed path)."""
        if not self._per_run:
            self._write()

    def _write(self) -> None:
        if self._last is None:
            return
        scenario, hops, end = self._last
        self._last = None
        out = render_run_figure(
            scenario,
            hops,
            self.path_for(end.run_index),
            end=end,
            n_runs=self.n_runs,
            size_inches=self.size_inches,
            dpi=self.dpi,
            metadata=self.metadata,
        )
        self.written.append(out)
