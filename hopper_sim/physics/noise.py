"""Per-hop landing noise nu: per axis a Gaussian with standard deviation sigma truncated to
[-bound, bound] (the paper's case study: sigma = 0.1 m, bound = 0.2 m, the scene's
``noise_sigma`` and ``noise_bound``)."""

from __future__ import annotations

import numpy as np
from scipy.stats import truncnorm

from hopper_sim.physics.model import HopperModel


def sample_noise(
    rng: np.random.Generator, n: int, sigma: float = 0.1, bound: float = 0.2
) -> np.ndarray:
    """n draws of nu, (n, 2) [m], from ``rng``."""
    if not (sigma > 0.0 and bound > 0.0):
        raise ValueError(f"noise sigma and bound must be > 0: sigma={sigma}, bound={bound}")
    b = bound / sigma
    return truncnorm.rvs(-b, b, loc=0.0, scale=sigma, size=(int(n), 2), random_state=rng)


def sample_model_noise(model: HopperModel, rng: np.random.Generator, n: int) -> np.ndarray:
    """n draws of nu with the model's default sigma and bound."""
    pp = model.perturbation
    return sample_noise(rng, n, pp.noise_sigma, pp.noise_bound)
