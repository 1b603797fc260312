"""Saving and loading trained hop models with their provenance.

A checkpoint file is sealed (:mod:`planner._util.sealed`): a header line with the SHA-256 of all
its bytes, then one ``torch.save`` payload holding plain data only (tensors, numbers,
strings, lists, dicts), read back with ``torch.load(weights_only=True)``:

    format        "hopnav-hop-model"
    version       CHECKPOINT_VERSION
    param_hash    hash of the MJCF parameters the data was simulated with
    hidden        layer widths
    ranges        (4, 2) training box (see :class:`InputRanges`)
    state_dict    weights and normalisation buffers
    metadata      free-form JSON-able dict (seed, metrics, steady state, thrust, ...)

Loading checks the digest first (a flipped bit anywhere in the file, a truncation or an
appended tail is :class:`CheckpointCorruptError`), then validates every field, and refuses
weights whose magnitude exceeds :data:`MAX_WEIGHT` (no trained hop model comes near it; a
corrupted float can be finite and huge). It raises :class:`CheckpointCorruptError`,
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
from planner._util.atomic import atomic_write
from planner._util.sealed import SealError, read_limited, seal, unseal

CHECKPOINT_FORMAT = "hopnav-hop-model"
#: 2: sealed with a digest of the file (version 1 files have none and are refused).
CHECKPOINT_VERSION = 2
#: The kind named in the sealed file's header.
SEAL_KIND = "hop-model-checkpoint"
#: Largest checkpoint file read [bytes] (the shipped one is about 0.2 MiB).
MAX_CHECKPOINT_BYTES = 256 * 2**20
#: Most hidden layers, and widest layer, of a checkpoint read (checked before allocating).
MAX_LAYERS, MAX_WIDTH = 16, 4096
#: Largest magnitude of a weight or normalisation value accepted on load.
MAX_WEIGHT = 1.0e4
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
        fh.write(seal(SEAL_KIND, buf.getvalue()))
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
        data = read_limited(path, MAX_CHECKPOINT_BYTES)
    except FileNotFoundError:
        raise
    except (OSError, SealError) as exc:
        raise CheckpointCorruptError(f"{path}: cannot be read as a checkpoint ({exc})") from exc
    if data.startswith(b"PK\x03\x04"):
        raise CheckpointVersionError(
            f"{path}: checkpoint version 1 (no digest of its contents), this code reads "
            f"version {CHECKPOINT_VERSION}; retrain it with `hopnav train-controller`"
        )
    try:
        raw = unseal(data, SEAL_KIND)
    except SealError as exc:
        raise CheckpointCorruptError(f"{path}: not an intact checkpoint: {exc}") from None
    try:
        payload = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for unreadable payloads
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
    if not (
        1 <= len(hidden) <= MAX_LAYERS
        and all(isinstance(h, int) and 1 <= h <= MAX_WIDTH for h in hidden)
    ):
        raise CheckpointCorruptError(
            f"{path}: layer widths {hidden!r} are not 1..{MAX_LAYERS} widths of 1..{MAX_WIDTH}"
        )
    state = _field(payload, "state_dict", dict, path)
    try:
        metadata = json.loads(_field(payload, "metadata_json", str, path))
        ranges = InputRanges.from_array(np.asarray(_field(payload, "ranges", list, path)))
        net = HopNet(ranges, np.zeros(N_OUTPUTS), np.ones(N_OUTPUTS), hidden=hidden)
        net.load_state_dict(state, strict=True)
    except (ValueError, RuntimeError, TypeError) as exc:
        raise CheckpointCorruptError(f"{path}: malformed checkpoint contents ({exc})") from exc
    for name, t in net.state_dict().items():
        if not bool(torch.isfinite(t).all()):
            raise CheckpointCorruptError(f"{path}: weights {name!r} hold non-finite values")
        if t.numel() and float(t.abs().max()) > MAX_WEIGHT:
            raise CheckpointCorruptError(
                f"{path}: weights {name!r} reach {float(t.abs().max()):.3g}, beyond the "
                f"plausible magnitude {MAX_WEIGHT:g}"
            )
    net.eval()
    return HopModelCheckpoint(net, param_hash, metadata)
