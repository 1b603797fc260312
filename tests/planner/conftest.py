from __future__ import annotations

import numpy as np
import pytest

from planner.imdp.grid import ACTION_OFFSETS


def smooth_error(points: np.ndarray) -> np.ndarray:
    """A known smooth landing-error field (metres), amplitude about 0.3 m."""
    x, y = points[:, 0], points[:, 1]
    return np.stack(
        [0.3 * np.sin(x / 2.0) + 0.1 * np.cos(y / 3.0), 0.25 * np.cos(x / 3.0 + y / 2.0)], axis=1
    )


def action_error(points: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """A known mean landing error (metres) that differs per action, shaped like the
    controller's measured one: an undershoot along the hop (0.07 m per cell hopped, more for
    two cells), the smooth field scaled per action, and for two-cell hops along their axis
    a field of their own instead of the shared one."""
    act = np.asarray(actions, dtype=int)
    off = ACTION_OFFSETS[act].astype(float)
    length = np.abs(off).sum(axis=1, keepdims=True)
    bias = -np.sign(off) * (0.07 * length**1.4)
    scale = 0.9 + 0.03 * act[:, None]
    shared = smooth_error(points) * scale
    own = 0.15 * np.stack([np.cos(points[:, 1] / 2.5 + act), np.sin(points[:, 0] / 2.5 - act)], 1)
    along2 = np.abs(off) == 2
    return bias + np.where(along2, own, shared)


@pytest.fixture(scope="session")
def synthetic_data() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """600 hops with random actions: landing error = action_error + N(0, 0.1^2) per axis."""
    rng = np.random.default_rng(7)
    pos = rng.uniform(0.0, 15.0, size=(600, 2))
    act = rng.integers(0, 8, size=600)
    err = action_error(pos, act) + rng.normal(0.0, 0.1, size=pos.shape)
    return pos, err, act


@pytest.fixture(scope="session")
def fitted_gp(synthetic_data):
    from planner.gp import LandingErrorGP

    gp = LandingErrorGP()
    gp.fit(*synthetic_data)
    return gp
