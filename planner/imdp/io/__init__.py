"""Reading and writing interval MDPs: PRISM explicit (``.tra``/``.lab``), Storm DRN with
interval values, and bmdp-tool's text format."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from planner.errors import ModelFormatError
from planner.imdp.io.bmdp import TERMINAL, read_bmdp, write_bmdp
from planner.imdp.io.drn import read_drn, write_drn
from planner.imdp.io.prism import read_prism, write_prism
from planner.imdp.model import IMDP

FORMATS = ("prism", "drn", "bmdp")


def guess_format(path: str | os.PathLike[str]) -> str:
    """``prism`` for ``.tra``, ``drn`` for ``.drn``, ``bmdp`` otherwise."""
    suffix = Path(path).suffix.lower()
    return {".tra": "prism", ".drn": "drn"}.get(suffix, "bmdp")


def read_model(path: str | os.PathLike[str], fmt: str | None = None) -> IMDP:
    """Read a model file in ``fmt`` (default: from the suffix)."""
    fmt = guess_format(path) if fmt is None else fmt
    if fmt == "prism":
        return read_prism(path)
    if fmt == "drn":
        return read_drn(path)
    if fmt == "bmdp":
        return read_bmdp(path)
    raise ModelFormatError(f"unknown model format {fmt!r}; expected one of {FORMATS}")


def write_model(
    model: IMDP,
    path: str | os.PathLike[str],
    fmt: str | None = None,
    terminal: np.ndarray | None = None,
) -> None:
    """Write ``model`` in ``fmt`` (default: from the suffix). ``terminal`` (bmdp only,
    default: no state) is the state mask written as bmdp-tool's terminal states."""
    fmt = guess_format(path) if fmt is None else fmt
    if fmt == "prism":
        write_prism(model, path)
    elif fmt == "drn":
        write_drn(model, path)
    elif fmt == "bmdp":
        term = np.zeros(model.n_states, dtype=bool) if terminal is None else terminal
        write_bmdp(model, path, term)
    else:
        raise ModelFormatError(f"unknown model format {fmt!r}; expected one of {FORMATS}")


__all__ = [
    "FORMATS",
    "TERMINAL",
    "guess_format",
    "read_bmdp",
    "read_drn",
    "read_model",
    "read_prism",
    "write_bmdp",
    "write_drn",
    "write_model",
    "write_prism",
]
