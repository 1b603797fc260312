"""Figure files: the formats by extension, the destination checked before long work, a
matplotlib figure on an Agg canvas (no pyplot, no display), and the atomic, dateless save.

The file's extension chooses the format: ``.png`` (raster, :data:`PNG_DPI` dots per inch),
``.svg`` or ``.pdf`` (vector). Files carry no creation date, so the same input gives the same
file; they are written atomically (temporary file in the same folder, then moved into place).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopper_sim.errors import HopperSimError
from hopper_sim.experiments.provenance import as_text
from planner._util.atomic import atomic_write

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FIGURE_FORMATS: dict[str, str] = {".png": "png", ".svg": "svg", ".pdf": "pdf"}
"""File extension -> format written."""

PNG_DPI = 200
"""Resolution of PNG figures, dots per inch."""


class FigureError(HopperSimError, ValueError):
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

    ``metadata`` (e.g. the provenance of :func:`hopper_sim.experiments.provenance.provenance`) goes
    where
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
