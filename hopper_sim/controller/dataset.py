"""Training data for the hop model: sampled interstitial states and touchdown angles, hopped
through a batched simulator, kept with their failures, saved as a compressed ``.npz``.

Each sample starts at the origin with its horizontal velocity along +x (heading ``psi = 0``),
so the world frame of the simulator *is* the heading frame of :mod:`hop_model`:

    inputs  (N, 4): (s, v_z, alpha, beta), see :class:`Sampling`
    outputs (N, 5): (dx, dy, v_x', v_y', v_z'), NaN where the hop failed
    ok      (N,)  : True where the hop reached the next interstitial state
    status  (N,)  : the simulator's status per hop (text)

The simulator is reached through a :class:`BatchHopFn` (see :func:`simulator_hop_fn` for the
MuJoCo one), so this module runs no physics itself.
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from hopper_sim.controller.errors import DatasetError, InputShapeError
from hopper_sim.controller.hop_model import N_INPUTS, N_OUTPUTS, InputRanges
from planner._util.atomic import atomic_write

DATASET_VERSION = 1

Progress = Callable[[int], None]
"""Progress callback: called with the number of hops just finished."""


@dataclass(frozen=True)
class HopSamples:
    """Outcome of a batch of hops, in the frame of the given velocities.

    ``ok`` (N,) bool; ``displacement`` (N, 2) [m] from the start to the next interstitial
    state; ``next_velocity`` (N, 3) [m/s]; ``status`` (N,) text. Failed rows may hold
    anything in the float arrays; consumers mask them with ``ok``.
    """

    ok: np.ndarray
    displacement: np.ndarray
    next_velocity: np.ndarray
    status: np.ndarray


class BatchHopFn(Protocol):
    """A batched hop map: velocities ``(N, 3)`` at the interstitial state (starting at the
    origin), touchdown angles ``alpha``, ``beta`` ``(N,)`` [rad] -> :class:`HopSamples`."""

    def __call__(self, velocity: np.ndarray, alpha: np.ndarray, beta: np.ndarray) -> HopSamples: ...


@dataclass
class HopDataset:
    """Inputs, outputs and success labels of simulated hops, with their provenance."""

    inputs: np.ndarray
    outputs: np.ndarray
    ok: np.ndarray
    status: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.inputs)
        checks = {
            "inputs": (self.inputs, (n, N_INPUTS)),
            "outputs": (self.outputs, (n, N_OUTPUTS)),
            "ok": (self.ok, (n,)),
            "status": (self.status, (n,)),
        }
        for name, (arr, shape) in checks.items():
            if np.shape(arr) != shape:
                raise DatasetError(
                    f"dataset array {name!r} has shape {np.shape(arr)}, want {shape}"
                )
        if self.ok.dtype != np.bool_:
            raise DatasetError(f"dataset array 'ok' must be boolean, got {self.ok.dtype}")
        if not np.all(np.isfinite(self.inputs)):
            raise DatasetError("dataset array 'inputs' holds non-finite values")
        if not np.all(np.isfinite(self.outputs[self.ok])):
            raise DatasetError("dataset array 'outputs' holds non-finite values on successful hops")

    def __len__(self) -> int:
        return len(self.inputs)

    @property
    def ranges(self) -> InputRanges:
        """The sampling box recorded in the metadata."""
        if "ranges" not in self.metadata:
            raise DatasetError("dataset metadata has no 'ranges'")
        return InputRanges.from_array(np.asarray(self.metadata["ranges"]))


@dataclass(frozen=True)
class Sampling:
    """How the interstitial velocities are drawn (alpha and beta are always uniform on the box).

    A fraction ``1 - shell_fraction`` is uniform on the whole box ``ranges``. The rest lies
    near the *operating shell* of the navigation: with the stance thrust regulating every hop's
    energy to the nominal one, each interstitial state has total speed ``|v| = V_nom``; there
    ``V ~ U[V_nom (1 - shell_width), V_nom (1 + shell_width)]``, descent angle
    ``gamma ~ U[0, gamma_max]``, ``s = V cos gamma``, ``v_z = -V sin gamma`` (clipped to the
    box). ``shell_speed=None`` disables the shell (all samples uniform).
    """

    shell_speed: float | None = None
    shell_fraction: float = 0.8
    shell_width: float = 0.03
    gamma_max: float = 1.5

    def __post_init__(self) -> None:
        if not 0.0 <= self.shell_fraction <= 1.0:
            raise InputShapeError(f"shell_fraction must lie in [0, 1], got {self.shell_fraction}")
        if self.shell_speed is not None and not self.shell_speed > 0:
            raise InputShapeError(f"shell_speed must be positive, got {self.shell_speed}")

    def as_dict(self) -> dict[str, Any]:
        return {
            "shell_speed": self.shell_speed,
            "shell_fraction": self.shell_fraction,
            "shell_width": self.shell_width,
            "gamma_max": self.gamma_max,
        }


def sample_inputs(
    rng: np.random.Generator, n: int, ranges: InputRanges, sampling: Sampling | None = None
) -> np.ndarray:
    """``(n, 4)`` inputs drawn as :class:`Sampling` says (default: uniform on ``ranges``)."""
    if n <= 0:
        raise InputShapeError(f"number of samples must be positive, got {n}")
    box = ranges.as_array()
    x = rng.uniform(box[:, 0], box[:, 1], size=(n, N_INPUTS))
    sampling = sampling or Sampling()
    if sampling.shell_speed is not None:
        shell = rng.random(n) < sampling.shell_fraction
        m = int(shell.sum())
        v = sampling.shell_speed * (1 + sampling.shell_width * rng.uniform(-1, 1, m))
        gamma = rng.uniform(0.0, sampling.gamma_max, m)
        x[shell, 0] = np.clip(v * np.cos(gamma), *box[0])
        x[shell, 1] = np.clip(-v * np.sin(gamma), *box[1])
    return x


def generate_dataset(
    hop_fn: BatchHopFn,
    n: int,
    *,
    seed: int,
    ranges: InputRanges | None = None,
    sampling: Sampling | None = None,
    chunk: int = 5000,
    metadata: Mapping[str, Any] | None = None,
    progress: Progress | None = None,
) -> HopDataset:
    """Sample ``n`` hops with ``numpy.random.default_rng(seed)`` (see :class:`Sampling`) and
    run them through ``hop_fn`` in chunks of ``chunk`` (``progress`` is called after each
    chunk with its size)."""
    ranges = ranges or InputRanges()
    sampling = sampling or Sampling()
    if chunk <= 0:
        raise InputShapeError(f"chunk must be positive, got {chunk}")
    x = sample_inputs(np.random.default_rng(seed), n, ranges, sampling)
    outputs = np.full((n, N_OUTPUTS), np.nan)
    ok = np.zeros(n, dtype=bool)
    status = np.empty(n, dtype=object)
    for start in range(0, n, chunk):
        sl = slice(start, min(n, start + chunk))
        m = sl.stop - sl.start
        velocity = np.stack([x[sl, 0], np.zeros(m), x[sl, 1]], axis=1)
        res = hop_fn(velocity, x[sl, 2].copy(), x[sl, 3].copy())
        good = np.asarray(res.ok, dtype=bool)
        y = np.concatenate([np.asarray(res.displacement), np.asarray(res.next_velocity)], axis=1)
        good &= np.all(np.isfinite(y), axis=1)
        outputs[sl][good] = y[good]
        ok[sl] = good
        status[sl] = np.asarray(res.status).astype(str)
        if progress is not None:
            progress(m)
    meta = {
        "version": DATASET_VERSION,
        "seed": int(seed),
        "count": int(n),
        "ranges": ranges.as_array().tolist(),
        "sampling": sampling.as_dict(),
        **dict(metadata or {}),
    }
    return HopDataset(x, outputs, ok, status.astype(str), meta)


def save_dataset(dataset: HopDataset, path: str | os.PathLike) -> Path:
    """Write ``dataset`` to a compressed ``.npz`` atomically (temporary file + ``os.replace``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as fh:
        np.savez_compressed(
            fh,
            inputs=dataset.inputs,
            outputs=dataset.outputs,
            ok=dataset.ok,
            status=dataset.status.astype(str),
            metadata_json=np.array(json.dumps(dataset.metadata)),
        )
    return path


#: Largest dataset read (its arrays, uncompressed) [bytes].
MAX_DATASET_BYTES = 1 << 30


def load_dataset(path: str | os.PathLike) -> HopDataset:
    """Read a dataset written by :func:`save_dataset`; malformed files raise
    :class:`DatasetError` naming the file and the problem."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as zf:  # sizes checked before anything is decompressed
            size = sum(info.file_size for info in zf.infolist())
        if size > MAX_DATASET_BYTES:
            raise DatasetError(
                f"{path}: its arrays hold {size} bytes, more than the limit of {MAX_DATASET_BYTES}"
            )
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in ("inputs", "outputs", "ok", "status", "metadata_json")}
    except KeyError as exc:
        raise DatasetError(f"{path}: missing array {exc}") from exc
    except DatasetError:
        raise
    except Exception as exc:  # zipfile, zlib and numpy raise many types for a damaged file
        raise DatasetError(f"{path}: not a readable .npz dataset ({exc})") from exc
    try:
        meta = json.loads(str(arrays["metadata_json"]))
    except ValueError as exc:
        raise DatasetError(f"{path}: metadata is not valid JSON ({exc})") from exc
    if not isinstance(meta, dict):
        raise DatasetError(f"{path}: metadata is not a JSON object")
    if meta.get("version") != DATASET_VERSION:
        raise DatasetError(
            f"{path}: dataset version {meta.get('version')!r}, this code reads {DATASET_VERSION}"
        )
    try:
        return HopDataset(
            arrays["inputs"].astype(np.float64),
            arrays["outputs"].astype(np.float64),
            arrays["ok"],
            arrays["status"],
            meta,
        )
    except DatasetError as exc:
        raise DatasetError(f"{path}: {exc}") from exc
