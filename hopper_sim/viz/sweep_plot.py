"""The Table I plot: mean reward and mean steps with confidence intervals against C and eps.

Two panels (reward, steps) with ``eps`` on the x axis and one series per ``P_RL,ee = C``:
the measured means as filled markers with their Student-t confidence intervals as error bars
(:func:`hopper_sim.experiments.sweep.mean_ci`), the paper's Table I values as hollow markers on
dashed
lines in the same colour (only where the paper has the cell). Series of different C are
shifted slightly along x so that their bars do not overlap. The number of runs that reached
the goal is written beside each measured point. When the values span more than two decades
the reward axis is symmetric-logarithmic (linear within +-10), as the measured rewards can
exceed the paper's by an order of magnitude; the axis label says so.

:func:`write_table_plot` writes the figure (PNG, SVG or PDF by extension, atomically);
``hopnav sweep`` calls it with :data:`PLOT_FILE` (``table_i.png``) beside its CSV files, and
``hopnav figure --table-i sweep_runs.csv --out FILE`` redraws it from a sweep's rows.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hopper_sim.viz.figure_files import (
    PNG_DPI,
    FigureError,
    check_destination,
    new_figure,
    save_figure,
)

if TYPE_CHECKING:
    from hopper_sim.experiments.sweep import CellSummary

PLOT_FILE = "table_i.png"
"""Name of the plot ``hopnav sweep`` writes beside its CSV files."""

SERIES_COLORS: tuple[str, ...] = ("#0077BB", "#EE7733", "#009988", "#CC3311", "#33BBEE", "#EE3377")
"""Colours of the C series (Paul Tol's vibrant scheme, colour-blind safe), then repeated."""
_MARKERS = ("o", "s", "^", "D", "v", "P")


def _values(cells: Sequence[CellSummary], attr: str) -> tuple[np.ndarray, np.ndarray]:
    mean = np.array([getattr(s, attr).mean for s in cells], dtype=float)
    half = np.array([getattr(s, attr).half_width for s in cells], dtype=float)
    return mean, half


def write_table_plot(
    cells: Sequence[CellSummary],
    path: str | os.PathLike[str],
    *,
    title: str = "",
    dpi: int = PNG_DPI,
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Draw the Table I plot of ``cells`` (:func:`build_table_plot`) and write it to ``path``
    (``.png``, ``.svg`` or ``.pdf``; its folder must exist), with ``metadata`` (e.g. the
    sweep's provenance) as in :func:`~hopper_sim.viz.figure_files.save_figure`.

    Raises:
        FigureError: no cells, an unknown extension or a missing folder.
    """
    check_destination(path)
    fig = build_table_plot(cells, title=title, dpi=dpi)
    return save_figure(fig, path, dpi=dpi, metadata=metadata)


def build_table_plot(cells: Sequence[CellSummary], *, title: str = "", dpi: int = PNG_DPI):
    """The Table I plot of ``cells`` as a matplotlib figure.

    Args:
        cells: per-cell summaries (:func:`hopper_sim.experiments.sweep.summarize`), any C x eps
        grid.
        title: the figure title (default: ``"Table I: ..."`` with the runs per cell).
        dpi: resolution of a PNG.

    Raises:
        FigureError: no cells.
    """
    if not cells:
        raise FigureError("the Table I plot needs at least one cell")
    cs = sorted({s.c for s in cells})
    epss = sorted({s.eps for s in cells})
    level = round(100 * cells[0].reward.level)
    runs = sorted({s.n for s in cells})
    fig = new_figure((10.0, 4.4), dpi)
    axes = fig.subplots(1, 2)
    width = max(epss) - min(epss) if len(epss) > 1 else max(abs(epss[0]), 1e-3)
    spread = 0.035 * width
    for ax, attr, paper_k, label in (
        (axes[0], "reward", 0, "mean reward"),
        (axes[1], "steps", 1, "mean steps (hops)"),
    ):
        every: list[float] = []
        for i, c in enumerate(cs):
            row = sorted((s for s in cells if s.c == c), key=lambda s: s.eps)
            shift = (i - 0.5 * (len(cs) - 1)) * spread
            every += _draw_series(ax, row, i, c, attr, paper_k, shift)
        _format_axis(ax, attr, label, every, epss, width, level)
    handles, labels = axes[0].get_legend_handles_labels()
    order = sorted(range(len(labels)), key=lambda i: ("paper" in labels[i], labels[i]))
    handles, labels = [handles[i] for i in order], [labels[i] for i in order]
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 6), fontsize=7.5,
               frameon=False)  # fmt: skip
    n_text = f"{runs[0]}" if len(runs) == 1 else f"{runs[0]}-{runs[-1]}"
    fig.suptitle(
        title
        or f"Table I: reward and steps against P_RL,ee = C and eps ({n_text} runs per cell; "
        "labels: runs that reached the goal)",
        fontsize=10,
    )
    fig.subplots_adjust(left=0.07, right=0.98, top=0.86, bottom=0.22, wspace=0.22)
    return fig


def _draw_series(
    ax, row: Sequence[CellSummary], i: int, c: float, attr: str, paper_k: int, shift: float
) -> list[float]:
    """Series ``i`` (the cells ``row`` of one C, by eps) of ``attr`` on ``ax``: the measured
    means with their intervals (shifted by ``shift`` along x), the goal counts beside them,
    the paper's values dashed; returns the values the y axis must show."""
    x = np.array([s.eps for s in row]) + shift
    mean, half = _values(row, attr)
    color, marker = SERIES_COLORS[i % len(SERIES_COLORS)], _MARKERS[i % len(_MARKERS)]
    ax.errorbar(
        x,
        mean,
        yerr=np.where(np.isfinite(half), half, 0.0),
        color=color,
        marker=marker,
        markersize=5,
        linewidth=1.2,
        capsize=3,
        label=f"C = {c:g} (hopnav)",
        zorder=3,
    )
    for xi, yi, s in zip(x, mean, row, strict=True):
        if np.isfinite(yi):
            ax.annotate(
                f"{s.successes}/{s.n}",
                (xi, yi),
                textcoords="offset points",
                xytext=(5, 4),
                fontsize=6,
                color=color,
            )
    every: list[float] = []
    paper = [(s.eps, s.paper[paper_k]) for s in row if s.paper is not None]
    if paper:
        px, py = np.array(paper).T
        ax.plot(
            px,
            py,
            linestyle="--",
            marker=marker,
            markerfacecolor="white",
            color=color,
            linewidth=1.0,
            markersize=6,
            label=f"C = {c:g} (paper)",
            zorder=2,
        )
        every += list(py)
    return every + list(mean[np.isfinite(mean)]) + list((mean + half)[np.isfinite(half)])


def _format_axis(
    ax, attr: str, label: str, every: list[float], epss: list[float], width: float, level: int
) -> None:
    """Ticks at ``epss``, labels, grid and title of one panel; the reward axis is
    symmetric-logarithmic when ``every`` spans more than two decades."""
    values = np.abs(np.asarray(every))
    positive = values[values > 0]
    if attr == "reward" and positive.size and positive.max() / max(positive.min(), 1.0) > 100:
        ax.set_yscale("symlog", linthresh=10.0)
        label += " (symlog axis)"
    ax.set_xticks(epss)
    ax.set_xticklabels([f"{e:g}" for e in epss])
    ax.set_xlabel("eps (decay rate of P_RL,gr = C exp(-eps m))")
    ax.set_xlim(min(epss) - 0.15 * width, max(epss) + 0.15 * width)
    ax.set_ylabel(label)
    ax.grid(True, color="0.88", linewidth=0.6)
    ax.set_title(f"{attr}: mean with {level} % CI, paper dashed", fontsize=9)
