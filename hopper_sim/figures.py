"""Figures of navigation runs in the style of the paper's Figure 4 (PNG, SVG or PDF).

A map shows the grid world from above: every cell coloured by its class (initial region, goal,
hazard, optional regions, penalties, other labels; :mod:`hopper_sim.styles`) with a letter on
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

Runs are numbered from 1 in every title (``RunStart.run_index`` + 1), as in the summary table
of ``hopnav run``, ``hopnav replay`` and the recording's entity paths.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hopper_sim.events import HopEvent, Observer, RunEnd, RunStart
from hopper_sim.provenance import as_text
from hopper_sim.styles import (
    GRID_COLOR,
    INITIAL_COLOR,
    INITIAL_LETTER,
    PHASE_COLORS,
    PHASE_NAMES,
    WHITE,
    draw_order,
    label_colors,
    legend_entries,
    region_components,
    region_letters,
    simulate_cvd,
)
from planner._util.atomic import atomic_write

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from planner.scenario import Scenario

FIGURE_FORMATS: dict[str, str] = {".png": "png", ".svg": "svg", ".pdf": "pdf"}
"""File extension -> format written."""

PNG_DPI = 200
"""Resolution of PNG figures, dots per inch."""


class FigureError(ValueError):
    """A figure cannot be written (unknown format, missing folder, bad size...)."""


def figure_format(path: str | os.PathLike[str]) -> str:
    """The format of ``path`` by its extension (``png``, ``svg`` or ``pdf``).

    Raises:
        FigureError: an unknown or missing extension.
    """
    ext = Path(path).suffix.lower()
    if ext not in FIGURE_FORMATS:
        raise FigureError(
            f"cannot write {path}: unknown figure format {ext or '(no extension)'!r}; "
            f"use {', '.join(FIGURE_FORMATS)}"
        )
    return FIGURE_FORMATS[ext]


def check_destination(path: str | os.PathLike[str]) -> Path:
    """Check that a figure can be written at ``path`` (known extension, existing writable
    folder) before any long work; returns it as a :class:`~pathlib.Path`.

    Raises:
        FigureError: the extension is unknown, or the folder is missing or not writable.
    """
    path = Path(path)
    figure_format(path)
    folder = path.parent
    if not folder.is_dir():
        raise FigureError(f"cannot write {path}: folder {folder} missing")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise FigureError(f"cannot write {path}: folder {folder} is not writable")
    if path.is_dir():
        raise FigureError(f"cannot write {path}: it is a folder")
    return path


def save_figure(
    fig: Figure,
    path: str | os.PathLike[str],
    *,
    dpi: int = PNG_DPI,
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``fig`` atomically in the format of ``path``'s extension, without a date.

    ``metadata`` (e.g. the provenance of :func:`hopper_sim.provenance.provenance`) goes where
    each format has room for it: one PNG text chunk per key (values as text), and the whole
    record as JSON in the SVG's Dublin Core ``Description`` and the PDF's ``Subject``.
    """
    import matplotlib

    path = check_destination(path)
    fmt = figure_format(path)
    record = as_text(metadata or {})
    as_json = json.dumps(record, sort_keys=True) if record else None
    meta: dict[str, Any] = {
        "png": {"Software": None, **record},
        "svg": {"Date": None, "Creator": None, "Description": as_json},
        "pdf": {"CreationDate": None, "Creator": None, "Producer": None, "Subject": as_json},
    }[fmt]
    with matplotlib.rc_context({"svg.hashsalt": "hopnav", "svg.fonttype": "path"}):
        with atomic_write(path) as f:
            fig.savefig(f, format=fmt, dpi=dpi, metadata=meta)
    return path


def new_figure(size_inches: tuple[float, float], dpi: int = PNG_DPI) -> Figure:
    """A matplotlib figure on an Agg canvas (no pyplot, no display)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if min(size_inches) <= 0 or dpi <= 0:
        raise FigureError(f"figure size {size_inches} in at {dpi} dpi must be positive")
    fig = Figure(figsize=size_inches, dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def _rgb(color: Sequence[int]) -> tuple[float, ...]:
    return tuple(float(c) / 255.0 for c in color)


def _text_color(color: Sequence[int]) -> str:
    """Black on light cells, white on dark ones (CIELAB lightness below 55)."""
    return "white" if simulate_cvd(np.asarray(color), "normal")[0] < 55 else "black"


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
        if end.outcome == "satisfying" and mission is not None:
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


# --------------------------------------------------------------------------- drawing
def class_grid(scenario: Scenario) -> tuple[np.ndarray, list[str], list[tuple[int, int, int]]]:
    """Visible class of every cell: ``(grid (nx, ny) int, names, colours)``, class 0 the empty
    cell (white), 1 the initial region, then the labels from background to foreground (goal
    and hazard last, so a hazard cell always shows as one)."""
    w = scenario.world
    grid = np.zeros((w.nx, w.ny), dtype=np.int64)
    names, colors = ["", "initial"], [WHITE, INITIAL_COLOR]
    grid[scenario.initial_mask] = 1
    palette = label_colors(scenario.labels, scenario.goal, scenario.hazard)
    for label in draw_order(scenario.labels, scenario.goal, scenario.hazard):
        mask = scenario.region_mask(label)
        if mask.any():
            names.append(label)
            colors.append(palette[label])
            grid[mask] = len(names) - 1
    return grid, names, colors


def region_image(scenario: Scenario) -> np.ndarray:
    """RGB image ``(ny, nx, 3)`` in [0, 1] of the visible cell classes, row 0 at y = 0."""
    grid, _, colors = class_grid(scenario)
    return (np.asarray(colors, dtype=float) / 255.0)[grid].transpose(1, 0, 2)


def _cell_points(ax: Axes, scenario: Scenario) -> float:
    """Size of one cell on the page, points."""
    fig = ax.figure
    box = ax.get_position()
    w, h = fig.get_size_inches()
    world = scenario.world
    return 72.0 * min(box.width * w / world.width, box.height * h / world.height) * world.cell


def draw_world(ax: Axes, scenario: Scenario, cover: np.ndarray | None = None) -> None:
    """Cells as vector quads coloured by class, the cell grid, and a letter per region, in
    its cell least covered by ``cover`` (``(nx, ny)``, e.g. :func:`route_cover`)."""
    from matplotlib.colors import ListedColormap

    w = scenario.world
    grid, names, colors = class_grid(scenario)
    xs = np.arange(w.nx + 1) * w.cell
    ys = np.arange(w.ny + 1) * w.cell
    ax.pcolormesh(
        xs,
        ys,
        grid.T,
        cmap=ListedColormap([_rgb(c) for c in colors]),
        vmin=-0.5,
        vmax=len(colors) - 0.5,
        edgecolors=_rgb(GRID_COLOR),
        linewidth=0.3,
        zorder=0,
    )
    letters = {"initial": INITIAL_LETTER, **region_letters(scenario.labels)}
    size = float(np.clip(0.5 * _cell_points(ax, scenario), 3.0, 11.0))
    for k, name in enumerate(names[1:], start=1):
        for i, j in region_components(grid == k, cover):
            covered = cover is not None and cover[i, j] > 0
            ax.text(
                (i + 0.5) * w.cell,
                (j + 0.5) * w.cell,
                letters[name],
                ha="center",
                va="center",
                fontsize=size,
                weight="bold",
                color=_text_color(colors[k]),
                zorder=9 if covered else 1,  # above a route that crosses every cell
                path_effects=_halo(2.0, _rgb(colors[k])) if covered else None,
            )
    ax.set_xlim(0, w.width)
    ax.set_ylim(0, w.height)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def _halo(width: float, color: str) -> list:
    from matplotlib import patheffects

    return [patheffects.Stroke(linewidth=width, foreground=color), patheffects.Normal()]


_ROUTE_STYLE: dict[str, dict[str, Any]] = {
    "exploration": {"halo": "black", "linestyle": "-"},
    "goal_reaching": {"halo": "white", "linestyle": "-"},
    "fallback": {"halo": "black", "linestyle": (0, (2.0, 1.2))},
}


def draw_route(ax: Axes, route: Route, scenario: Scenario) -> None:
    """The route drawn once, coloured by phase, an arrow per hop, backups, switch, start, end."""
    from matplotlib.collections import LineCollection

    cell = scenario.world.cell
    lw = float(np.clip(0.06 * _cell_points(ax, scenario), 0.6, 1.6))
    phases = np.asarray(route.phases)
    for phase, style in _ROUTE_STYLE.items():
        idx = np.flatnonzero(phases == phase)
        if not idx.size:
            continue
        lines = LineCollection(
            [route.tracks[k] for k in idx],
            colors=[_rgb(PHASE_COLORS[phase])],
            linewidths=lw,
            linestyles=style["linestyle"],
            capstyle="round",
            zorder=3 if phase == "goal_reaching" else 2,
        )
        lines.set_path_effects(_halo(lw + 1.4, style["halo"]))
        ax.add_collection(lines)
    if route.n_hops:
        mids, dirs = [], []
        for track in route.tracks:
            seg = np.linalg.norm(np.diff(track, axis=0), axis=1)
            s = np.concatenate([[0.0], np.cumsum(seg)])
            half = 0.5 * s[-1]
            mids.append([np.interp(half, s, track[:, d]) for d in range(2)])
            chord = track[-1] - track[0]
            dirs.append(chord / max(float(np.linalg.norm(chord)), 1e-12))
        mids, dirs = np.asarray(mids), np.asarray(dirs) * 0.45 * cell
        arrow_colors = [_rgb(PHASE_COLORS[p]) for p in route.phases]
        ax.quiver(
            mids[:, 0],
            mids[:, 1],
            dirs[:, 0],
            dirs[:, 1],
            color=arrow_colors,
            angles="xy",
            scale_units="xy",
            scale=1.0,
            pivot="mid",
            width=0.0035,
            headwidth=4.5,
            headlength=5.0,
            headaxislength=4.5,
            edgecolor="black",
            linewidth=0.35,
            zorder=4,
        )
        ends = np.array([t[-1] for t in route.tracks])
        if route.backups.any():
            ax.scatter(
                ends[route.backups, 0],
                ends[route.backups, 1],
                s=22,
                marker="x",
                color="black",
                linewidths=1.1,
                zorder=5,
                path_effects=_halo(2.4, "white"),
            )
        if route.switch_step is not None and 0 <= route.switch_step < route.n_hops:
            sx, sy = route.tracks[route.switch_step][0]
            ax.scatter(
                sx, sy, s=70, marker="D", color="white", edgecolors="black", linewidths=1.2,
                zorder=6,
            )  # fmt: skip
        ex, ey = route.end
        ax.scatter(
            ex, ey, s=80, marker="s", color="white", edgecolors="black", linewidths=1.4, zorder=7
        )
    ax.scatter(
        *route.start, s=190, marker="*", color="white", edgecolors="black", linewidths=1.2,
        zorder=8,
    )  # fmt: skip


# --------------------------------------------------------------------------- legend
class LetterPatch:
    """Legend handle: a square of a region's colour with its letter."""

    def __init__(self, letter: str, color: Sequence[int]) -> None:
        self.letter, self.color = letter, tuple(color)


class _LetterHandler:
    def legend_artist(self, legend, orig_handle: LetterPatch, fontsize: float, handlebox):
        from matplotlib.patches import Rectangle
        from matplotlib.text import Text

        x0, y0 = handlebox.xdescent, handlebox.ydescent
        side = min(handlebox.width, handlebox.height * 1.4)
        square = Rectangle(
            (x0 + 0.5 * (handlebox.width - side), y0 + 0.5 * handlebox.height - 0.5 * side),
            side,
            side,
            facecolor=_rgb(orig_handle.color),
            edgecolor=_rgb(GRID_COLOR),
            linewidth=0.6,
            transform=handlebox.get_transform(),
        )
        text = Text(
            x0 + 0.5 * handlebox.width,
            y0 + 0.5 * handlebox.height,
            orig_handle.letter,
            ha="center",
            va="center",
            fontsize=0.8 * fontsize,
            weight="bold",
            color=_text_color(orig_handle.color),
            transform=handlebox.get_transform(),
        )
        handlebox.add_artist(square)
        handlebox.add_artist(text)
        return square


def region_handles(scenarios: Sequence[Scenario]) -> list[tuple[Any, str]]:
    """``(handle, text)`` of every region class in ``scenarios`` (each distinct text once)."""
    out: dict[tuple, tuple[Any, str]] = {}
    for sc in scenarios:
        for letter, text, color in legend_entries(sc):
            out.setdefault((letter, text, color), (LetterPatch(letter, color), text))
    return list(out.values())


def route_handles(routes: Sequence[Route]) -> list[tuple[Any, str]]:
    """``(handle, text)`` of the route's marks present in ``routes``."""
    from matplotlib.lines import Line2D

    out: list[tuple[Any, str]] = []
    phases = {p for r in routes for p in r.phases}
    for phase, style in _ROUTE_STYLE.items():
        if phase in phases:
            line = Line2D(
                [], [], color=_rgb(PHASE_COLORS[phase]), linewidth=1.4,
                linestyle=style["linestyle"], path_effects=_halo(2.8, style["halo"]),
            )  # fmt: skip
            out.append((line, f"{PHASE_NAMES[phase]} (arrow: direction)"))

    def mark(marker: str, size: float, text: str, face: str = "white") -> None:
        handle = Line2D(
            [], [], marker=marker, linestyle="", markersize=size, markerfacecolor=face,
            markeredgecolor="black", color="black",
        )  # fmt: skip
        out.append((handle, text))

    if any(r.backups.any() for r in routes):
        mark("x", 6, "backup replaced the action", face="black")
    if any(r.switch_step is not None and r.switch_step < r.n_hops for r in routes):
        mark("D", 6, "switch to goal reaching")
    mark("*", 11, "start")
    if any(r.n_hops for r in routes):
        mark("s", 7, "end")
    return out


def _legend(target, handles: list[tuple[Any, str]], **kwargs: Any):
    return target.legend(
        [h for h, _ in handles],
        [t for _, t in handles],
        handler_map={LetterPatch: _LetterHandler()},
        fontsize=7.5,
        frameon=False,
        **kwargs,
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
        _legend(ax, handles, loc="center left", bbox_to_anchor=(1.03, 0.5), borderaxespad=0.0)
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
    _legend(fig, handles, loc="lower center", ncol=3, bbox_to_anchor=(0.5, 0.005))
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


def route_cover(scenario: Scenario, route: Route | None) -> np.ndarray:
    """``(nx, ny)``: how much each cell is covered by the start mark and the route (its
    track points, and its end and switch marks heavily), for placing letters."""
    w = scenario.world
    cover = np.zeros((w.nx, w.ny))

    def add(points: np.ndarray, weight: float) -> None:
        ij = np.floor(np.atleast_2d(points) / w.cell).astype(np.int64)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < w.nx) & (ij[:, 1] >= 0) & (ij[:, 1] < w.ny)
        np.add.at(cover, (ij[ok, 0], ij[ok, 1]), weight)

    add(np.asarray(scenario.start), 1e6)
    if route is not None and route.n_hops:
        add(np.concatenate(route.tracks), 1.0)
        add(route.end, 1e6)
        if route.switch_step is not None and route.switch_step < route.n_hops:
            add(route.tracks[route.switch_step][0], 1e6)
    return cover


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
            :func:`hopper_sim.provenance.provenance`), as in :func:`save_figure`.

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
