"""Saving and loading trained hop models with their provenance.

A checkpoint is one ``torch.save`` file holding plain data only (tensors, numbers, strings,
lists, dicts), read back with ``torch.load(weights_only=True)``:

    format        "hopnav-hop-model"
    version       CHECKPOINT_VERSION
    param_hash    hash of the MJCF parameters the data was simulated with
    hidden        layer widths
    ranges        (4, 2) training box (see :class:`InputRanges`)
    state_dict    weights and normalisation buffers
    metadata      free-form JSON-able dict (seed, metrics, steady state, thrust, ...)

Loading validates everything and raises :class:`CheckpointCorruptError`,
:class:`CheckpointVersionError` or :class:`CheckpointModelMismatchError`. Writes are atomic.
"""

from __future__ import annotations

import io
import json
import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import torch

from hopper_sim.controller.errors import (
    CheckpointCorruptError,
    CheckpointModelMismatchError,
    CheckpointVersionError,
)
from hopper_sim.controller.hop_model import N_OUTPUTS, HopNet, InputRanges
from planner.atomic import atomic_write

CHECKPOINT_FORMAT = "hopnav-hop-model"
CHECKPOINT_VERSION = 1
#: The shipped checkpoint (package data, ``hopper_sim/data/controller.pt``).
DEFAULT_CHECKPOINT = Path(str(resources.files("hopper_sim") / "data" / "controller.pt"))


@dataclass
class HopModelCheckpoint:
    """A trained network with the hash of the hopper it models and free-form metadata."""

    net: HopNet
    param_hash: str
    metadata: dict[str, Any] = field(default_factory=dict)


def save_checkpoint(checkpoint: HopModelCheckpoint, path: str | os.PathLike) -> Path:
    """Write ``checkpoint`` to ``path`` atomically (temporary file in the same folder, then
    ``os.replace``)."""
    path = Path(path)
    net = checkpoint.net
    payload = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "param_hash": str(checkpoint.param_hash),
        "hidden": list(net.hidden),
        "ranges": net.ranges.as_array().tolist(),
        "state_dict": {k: v.detach().clone() for k, v in net.state_dict().items()},
        "metadata_json": json.dumps(checkpoint.metadata),
    }
    buf = io.BytesIO()
    torch.save(payload, buf)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as fh:
        fh.write(buf.getvalue())
    return path


def _field(payload: dict, name: str, kind: type | tuple[type, ...], path: Path) -> Any:
    if name not in payload:
        raise CheckpointCorruptError(f"{path}: checkpoint lacks the field {name!r}")
    value = payload[name]
    if not isinstance(value, kind):
        raise CheckpointCorruptError(
            f"{path}: checkpoint field {name!r} has type {type(value).__name__}"
        )
    return value


def load_checkpoint(
    path: str | os.PathLike = DEFAULT_CHECKPOINT, *, expected_param_hash: str | None = None
) -> HopModelCheckpoint:
    """Read and validate a checkpoint.

    ``expected_param_hash`` (e.g. ``HopperModel.load().param_hash()``) must equal the stored
    hash, else :class:`CheckpointModelMismatchError`; ``None`` skips that check.
    """
    path = Path(path)
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise
    except Exception as exc:  # torch raises many types for unreadable files
        raise CheckpointCorruptError(f"{path}: cannot be read as a checkpoint ({exc})") from exc
    if not isinstance(payload, dict):
        raise CheckpointCorruptError(f"{path}: top level is {type(payload).__name__}, not a dict")
    fmt = _field(payload, "format", str, path)
    if fmt != CHECKPOINT_FORMAT:
        raise CheckpointCorruptError(f"{path}: format is {fmt!r}, want {CHECKPOINT_FORMAT!r}")
    version = _field(payload, "version", int, path)
    if version != CHECKPOINT_VERSION:
        raise CheckpointVersionError(
            f"{path}: checkpoint version {version}, this code reads version {CHECKPOINT_VERSION}"
        )
    param_hash = _field(payload, "param_hash", str, path)
    if expected_param_hash is not None and param_hash != expected_param_hash:
        raise CheckpointModelMismatchError(
            f"{path}: trained on hopper parameters {param_hash}, but the current model's "
            f"parameters hash to {expected_param_hash}; retrain with `hopnav train-controller`"
        )
    hidden = _field(payload, "hidden", list, path)
    state = _field(payload, "state_dict", dict, path)
    try:
        metadata = json.loads(_field(payload, "metadata_json", str, path))
        ranges = InputRanges.from_array(np.asarray(_field(payload, "ranges", list, path)))
        net = HopNet(ranges, np.zeros(N_OUTPUTS), np.ones(N_OUTPUTS), hidden=hidden)
        net.load_state_dict(state, strict=True)
    except (ValueError, RuntimeError, TypeError) as exc:
        raise CheckpointCorruptError(f"{path}: malformed checkpoint contents ({exc})") from exc
    if not all(torch.isfinite(t).all() for t in net.state_dict().values()):
        raise CheckpointCorruptError(f"{path}: weights hold non-finite values")
    net.eval()
    return HopModelCheckpoint(net, param_hash, metadata)
