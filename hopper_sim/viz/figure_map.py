"""Drawing one map of a figure (the paper's Figure 4 style) on matplotlib axes.

Every cell is coloured by its visible class (:func:`class_grid`: initial region, then the
labels from background to foreground, goal and hazard last) with a letter on each connected
region, placed in its cell least covered by the route (:func:`route_cover`); a run's route is
drawn once (:func:`draw_route`): each hop's CoM ground track coloured by phase with an arrow
at its middle, crosses at backups, a diamond at the switch, the start (star) and end (square).
Coordinates are world metres; colours from :mod:`hopper_sim.viz.styles`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from hopper_sim.viz.styles import (
    GRID_COLOR,
    INITIAL_COLOR,
    INITIAL_LETTER,
    PHASE_COLORS,
    WHITE,
    draw_order,
    label_colors,
    region_components,
    region_letters,
    simulate_cvd,
)
from planner.modes import Phase

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from hopper_sim.viz.figures import Route
    from planner.scenario import Scenario


def unit_rgb(color: Sequence[int]) -> tuple[float, ...]:
    return tuple(float(c) / 255.0 for c in color)


def text_color(color: Sequence[int]) -> str:
    """Black on light cells, white on dark ones (CIELAB lightness below 55)."""
    return "white" if simulate_cvd(np.asarray(color), "normal")[0] < 55 else "black"


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
        cmap=ListedColormap([unit_rgb(c) for c in colors]),
        vmin=-0.5,
        vmax=len(colors) - 0.5,
        edgecolors=unit_rgb(GRID_COLOR),
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
                color=text_color(colors[k]),
                zorder=9 if covered else 1,  # above a route that crosses every cell
                path_effects=halo(2.0, unit_rgb(colors[k])) if covered else None,
            )
    ax.set_xlim(0, w.width)
    ax.set_ylim(0, w.height)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def halo(width: float, color: str) -> list:
    from matplotlib import patheffects

    return [patheffects.Stroke(linewidth=width, foreground=color), patheffects.Normal()]


ROUTE_STYLE: dict[str, dict[str, Any]] = {
    Phase.EXPLORATION: {"halo": "black", "linestyle": "-"},
    Phase.GOAL_REACHING: {"halo": "white", "linestyle": "-"},
    Phase.FALLBACK: {"halo": "black", "linestyle": (0, (2.0, 1.2))},
}


def draw_route(ax: Axes, route: Route, scenario: Scenario) -> None:
    """The route drawn once, coloured by phase, an arrow per hop, backups, switch, start, end."""
    from matplotlib.collections import LineCollection

    cell = scenario.world.cell
    lw = float(np.clip(0.06 * _cell_points(ax, scenario), 0.6, 1.6))
    phases = np.asarray(route.phases)
    for phase, style in ROUTE_STYLE.items():
        idx = np.flatnonzero(phases == phase)
        if not idx.size:
            continue
        lines = LineCollection(
            [route.tracks[k] for k in idx],
            colors=[unit_rgb(PHASE_COLORS[phase])],
            linewidths=lw,
            linestyles=style["linestyle"],
            capstyle="round",
            zorder=3 if phase == Phase.GOAL_REACHING else 2,
        )
        lines.set_path_effects(halo(lw + 1.4, style["halo"]))
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
        arrow_colors = [unit_rgb(PHASE_COLORS[p]) for p in route.phases]
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
                path_effects=halo(2.4, "white"),
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
