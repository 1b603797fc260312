from __future__ import annotations

import numpy as np
import pytest


def smooth_error(points: np.ndarray) -> np.ndarray:
    """A known smooth landing-error field (metres), amplitude about 0.3 m."""
    x, y = points[:, 0], points[:, 1]
    return np.stack(
        [0.3 * np.sin(x / 2.0) + 0.1 * np.cos(y / 3.0), 0.25 * np.cos(x / 3.0 + y / 2.0)], axis=1
    )


@pytest.fixture(scope="session")
def synthetic_data() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    pos = rng.uniform(0.0, 15.0, size=(600, 2))
    err = smooth_error(pos) + rng.normal(0.0, 0.1, size=pos.shape)
    return pos, err


@pytest.fixture(scope="session")
def fitted_gp(synthetic_data):
    from planner.gp import LandingErrorGP

    gp = LandingErrorGP(seed=3)
    gp.fit(*synthetic_data)
    gp.fit(*synthetic_data)
    return gp
