"""The legend of a figure: one lettered square per region class, the route's marks."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from hopper_sim.viz.figure_map import ROUTE_STYLE, halo, text_color, unit_rgb
from hopper_sim.viz.styles import GRID_COLOR, PHASE_COLORS, PHASE_NAMES, legend_entries

if TYPE_CHECKING:
    from hopper_sim.viz.figures import Route
    from planner.scenario import Scenario


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
            facecolor=unit_rgb(orig_handle.color),
            edgecolor=unit_rgb(GRID_COLOR),
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
            color=text_color(orig_handle.color),
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
    for phase, style in ROUTE_STYLE.items():
        if phase in phases:
            line = Line2D(
                [], [], color=unit_rgb(PHASE_COLORS[phase]), linewidth=1.4,
                linestyle=style["linestyle"], path_effects=halo(2.8, style["halo"]),
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


def add_legend(target, handles: list[tuple[Any, str]], **kwargs: Any):
    return target.legend(
        [h for h, _ in handles],
        [t for _, t in handles],
        handler_map={LetterPatch: _LetterHandler()},
        fontsize=7.5,
        frameon=False,
        **kwargs,
    )
