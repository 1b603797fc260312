"""Terrain force field: a seeded sample of a Gaussian-process prior, one per horizontal axis.

Each axis a in {x, y} is an independent draw from GP(0, A^2 exp(-|x - x'|^2 / (2 ell^2)))
(RBF kernel, amplitude A [N], length scale ell [m]), approximated by D random Fourier
features:

    f_a(x) = A sqrt(2 / D) sum_i w_ai cos(omega_ai . x + b_ai),
    omega_ai ~ N(0, I / ell^2),  b_ai ~ U[0, 2 pi),  w_ai ~ N(0, 1),

whose covariance tends to the RBF kernel as D grows (Rahimi & Recht, 2007), plus a uniform
part ``o_a ~ N(0, A_0^2)`` that is the same everywhere (a slope or a steady push: ``A_0`` [N],
the scene's ``terrain_offset``), drawn after the features. The field is then a draw from
GP(0, A^2 exp(-|x - x'|^2 / (2 ell^2)) + A_0^2). The draw is made from
``numpy.random.default_rng(seed)``, so one seed gives one field, bit for bit.

The force acts on the CoM during stance only and is evaluated where the foot stands, so it is
constant over a stance. Default A and ell come from the scene's custom numerics
(``terrain_amplitude``, ``terrain_lengthscale``, ``terrain_features``, ``terrain_offset``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from hopper_sim.errors import HopperSimError
from hopper_sim.physics.model import HopperModel


class TerrainError(HopperSimError, ValueError):
    """Invalid terrain parameters or query points."""


@dataclass(frozen=True)
class TerrainField:
    """Seeded random-Fourier-feature field; see the module docstring.

    Attributes:
        amplitude: A [N]; lengthscale: ell [m]; seed: the generator seed.
        omega: frequencies (2, D, 2) [rad/m]; phase: (2, D) [rad]; weight: (2, D).
        offset: the uniform part ``(o_x, o_y)`` [N].
    """

    amplitude: float
    lengthscale: float
    seed: int
    omega: np.ndarray
    phase: np.ndarray
    weight: np.ndarray
    offset: np.ndarray = field(default_factory=lambda: np.zeros(2))

    @classmethod
    def from_seed(
        cls,
        seed: int,
        amplitude: float,
        lengthscale: float,
        features: int = 256,
        offset: float = 0.0,
    ) -> TerrainField:
        """Draw the field with ``numpy.random.default_rng(seed)`` (``offset``: ``A_0`` [N])."""
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise TerrainError(f"terrain seed must be a non-negative integer: {seed!r}")
        if not (np.isfinite(amplitude) and amplitude >= 0.0):
            raise TerrainError(f"terrain amplitude must be finite and >= 0 N: {amplitude}")
        if not (np.isfinite(offset) and offset >= 0.0):
            raise TerrainError(f"terrain offset must be finite and >= 0 N: {offset}")
        if not (np.isfinite(lengthscale) and lengthscale > 0.0):
            raise TerrainError(f"terrain length scale must be finite and > 0 m: {lengthscale}")
        if int(features) < 1:
            raise TerrainError(f"terrain needs at least one Fourier feature: {features}")
        rng = np.random.default_rng(seed)
        d = int(features)
        omega = rng.normal(0.0, 1.0 / lengthscale, size=(2, d, 2))
        phase = rng.uniform(0.0, 2.0 * np.pi, size=(2, d))
        weight = rng.normal(0.0, 1.0, size=(2, d))
        uniform = rng.normal(0.0, 1.0, size=2) * float(offset)
        return cls(float(amplitude), float(lengthscale), int(seed), omega, phase, weight, uniform)

    @classmethod
    def for_model(
        cls,
        model: HopperModel,
        seed: int,
        amplitude: float | None = None,
        lengthscale: float | None = None,
    ) -> TerrainField:
        """The field with the model's defaults (scene numerics) unless given."""
        pp = model.perturbation
        return cls.from_seed(
            seed,
            pp.terrain_amplitude if amplitude is None else amplitude,
            pp.terrain_lengthscale if lengthscale is None else lengthscale,
            pp.terrain_features,
            pp.terrain_offset,
        )

    def force(self, xy: np.ndarray) -> np.ndarray:
        """Horizontal force [N], (N, 2), at points xy (N, 2) [m] (also accepts (2,))."""
        xy = np.asarray(xy, dtype=float)
        single = xy.ndim == 1
        pts = np.atleast_2d(xy)
        if pts.shape[-1] != 2 or pts.ndim != 2:
            raise TerrainError(f"terrain query points must have shape (N, 2): {xy.shape}")
        if not np.all(np.isfinite(pts)):
            raise TerrainError("terrain query points must be finite")
        d = self.weight.shape[1]
        scale = self.amplitude * np.sqrt(2.0 / d)
        arg = np.einsum("nk,adk->and", pts, self.omega) + self.phase[:, None, :]
        out = scale * np.einsum("and,ad->na", np.cos(arg), self.weight) + self.offset
        return out[0] if single else out


class ForceField(Protocol):
    """Anything with ``force(xy (N, 2)) -> (N, 2)`` [N]: a horizontal force field."""

    def force(self, xy: np.ndarray) -> np.ndarray: ...
