"""The learned hop map: a torch MLP with built-in normalisation, in the heading frame.

Symmetry (docs/design.md, "Hopper"): the SLIP hop map is invariant to rotation about the vertical
axis once the touchdown azimuth ``beta`` is measured from the heading
``psi = atan2(v_y, v_x)`` of the horizontal interstitial velocity. The network therefore sees
only

    x = (s, v_z, alpha, beta)    s = |(v_x, v_y)| [m/s], v_z [m/s], alpha, beta [rad]

and predicts, in the heading frame (x' along the heading, y' to its left),

    y = (dx', dy', v_x', v_y', v_z')   displacement to the next interstitial state [m] and
                                        next interstitial velocity [m/s]

together with a feasibility logit ``l`` (``sigmoid(l)`` is the predicted probability that the
hop succeeds). :func:`heading_frame` and :func:`rotate_xy` move vectors between frames.

Normalisation is part of the module: inputs are mapped affinely from the training ranges to
[-1, 1]; outputs are predicted in standardised units and mapped back with the training mean
and standard deviation, so callers only ever handle physical units.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from hopper_sim.controller.errors import InputShapeError

INPUT_NAMES: tuple[str, ...] = ("speed", "vz", "alpha", "beta")
OUTPUT_NAMES: tuple[str, ...] = ("dx", "dy", "vx", "vy", "vz")
N_INPUTS = len(INPUT_NAMES)
N_OUTPUTS = len(OUTPUT_NAMES)


@dataclass(frozen=True)
class InputRanges:
    """Box of the training inputs: interstitial horizontal speed [m/s], vertical velocity
    [m/s], leg elevation alpha [rad] and azimuth beta [rad] (relative to the heading).

    The default box, horizontal speed [0.25, 8] m/s and v_z [-4.5, 0] m/s, covers the issue's
    [1, 8] m/s and the steep descents (|v| = 4 m/s, descent angle up to 1.5 rad) that
    turning hops and the apex margin of the optimiser produce.
    """

    speed: tuple[float, float] = (0.25, 8.0)
    vz: tuple[float, float] = (-4.5, 0.0)
    alpha: tuple[float, float] = (float(np.pi / 4), float(np.pi / 2))
    beta: tuple[float, float] = (float(-np.pi / 2), float(np.pi / 2))

    def __post_init__(self) -> None:
        for name in INPUT_NAMES:
            lo, hi = getattr(self, name)
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise InputShapeError(
                    f"InputRanges.{name} must be finite with low < high, got {(lo, hi)}"
                )

    def as_array(self) -> np.ndarray:
        """``(4, 2)`` array of (low, high) per input, in :data:`INPUT_NAMES` order."""
        return np.array([getattr(self, name) for name in INPUT_NAMES], dtype=np.float64)

    @classmethod
    def from_array(cls, array: np.ndarray) -> InputRanges:
        a = np.asarray(array, dtype=np.float64)
        if a.shape != (N_INPUTS, 2):
            raise InputShapeError(f"input ranges must have shape (4, 2), got {a.shape}")
        return cls(**{name: (float(a[i, 0]), float(a[i, 1])) for i, name in enumerate(INPUT_NAMES)})


def heading_frame(velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split world velocities ``(..., 3)`` into horizontal speed, vertical velocity and heading.

    Returns ``(s, v_z, psi)`` with ``s = |(v_x, v_y)|``, ``psi = atan2(v_y, v_x)`` [rad].
    """
    v = np.asarray(velocity, dtype=np.float64)
    if v.shape[-1:] != (3,):
        raise InputShapeError(f"velocity must have a last axis of length 3, got shape {v.shape}")
    return np.hypot(v[..., 0], v[..., 1]), v[..., 2].copy(), np.arctan2(v[..., 1], v[..., 0])


def rotate_xy(xy: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """Rotate the first two components of ``(..., 2|3)`` vectors by ``angle`` [rad] about z
    (counter-clockwise); a third component is passed through."""
    v = np.asarray(xy, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    out = v.copy()
    out[..., 0] = c * v[..., 0] - s * v[..., 1]
    out[..., 1] = s * v[..., 0] + c * v[..., 1]
    return out


class AffineScaler(nn.Module):
    """``y = (x - shift) / scale`` (``forward``) and its inverse (``inverse``), per column."""

    def __init__(self, shift: Sequence[float] | np.ndarray, scale: Sequence[float] | np.ndarray):
        super().__init__()
        shift_t = torch.as_tensor(np.asarray(shift, dtype=np.float32))
        scale_t = torch.as_tensor(np.asarray(scale, dtype=np.float32))
        if shift_t.shape != scale_t.shape or shift_t.ndim != 1:
            raise InputShapeError(
                f"scaler shift and scale must be equal-length vectors, got "
                f"{tuple(shift_t.shape)} and {tuple(scale_t.shape)}"
            )
        if not torch.all(scale_t > 0):
            raise InputShapeError(f"scaler scales must be positive, got {scale_t.tolist()}")
        self.register_buffer("shift", shift_t)
        self.register_buffer("scale", scale_t)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.shift) / self.scale

    def inverse(self, z: torch.Tensor) -> torch.Tensor:
        return z * self.scale + self.shift


class HopNet(nn.Module):
    """MLP ``(s, v_z, alpha, beta) -> ((dx', dy', v_x', v_y', v_z'), logit)`` in physical units.

    Composition: an input :class:`AffineScaler` (training box to [-1, 1]), a trunk of
    ``Linear + SiLU`` layers (smooth, so the leg-angle optimiser gets useful gradients), a
    linear head with ``N_OUTPUTS + 1`` units, and an output :class:`AffineScaler` (standard
    scores to physical units) for the regression part.
    """

    def __init__(
        self,
        ranges: InputRanges,
        output_mean: Sequence[float] | np.ndarray,
        output_std: Sequence[float] | np.ndarray,
        hidden: Sequence[int] = (128, 128, 128),
    ):
        super().__init__()
        if len(hidden) == 0 or any(int(h) <= 0 for h in hidden):
            raise InputShapeError(f"hidden layer widths must be positive, got {list(hidden)}")
        box = ranges.as_array()
        self.ranges = ranges
        self.hidden = tuple(int(h) for h in hidden)
        self.input_scaler = AffineScaler(box.mean(axis=1), (box[:, 1] - box[:, 0]) / 2.0)
        self.output_scaler = AffineScaler(output_mean, output_std)
        if self.output_scaler.shift.shape != (N_OUTPUTS,):
            raise InputShapeError(
                f"output mean/std must have length {N_OUTPUTS}, got "
                f"{tuple(self.output_scaler.shift.shape)}"
            )
        layers: list[nn.Module] = []
        width = N_INPUTS
        for h in self.hidden:
            layers += [nn.Linear(width, h), nn.SiLU()]
            width = h
        layers.append(nn.Linear(width, N_OUTPUTS + 1))
        self.trunk = nn.Sequential(*layers)

    def forward_standardised(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Standard-score outputs ``(N, 5)`` and feasibility logits ``(N,)`` for raw inputs."""
        z = self.trunk(self.input_scaler(x))
        return z[..., :N_OUTPUTS], z[..., N_OUTPUTS]

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Physical outputs ``(..., 5)`` and feasibility logits ``(...,)`` for raw inputs
        ``(..., 4)``."""
        z, logit = self.forward_standardised(x)
        return self.output_scaler.inverse(z), logit

    @torch.inference_mode()
    def predict(self, inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """NumPy convenience: ``(N, 4)`` inputs to ``(N, 5)`` outputs and ``(N,)`` success
        probabilities."""
        x = np.asarray(inputs, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != N_INPUTS:
            raise InputShapeError(f"inputs must have shape (N, {N_INPUTS}), got {x.shape}")
        y, logit = self(torch.from_numpy(x))
        return y.double().numpy(), torch.sigmoid(logit).double().numpy()
