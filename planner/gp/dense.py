"""Dense linear algebra of the exact landing-error GP (:mod:`planner.gp.landing`): the
squared-exponential kernel matrix and the inverse of a symmetric positive definite matrix."""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

from planner.errors import GPDataError


def sq_dist(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(len(p), len(q))`` squared Euclidean distances between the rows of ``p`` and ``q``
    (clipped at 0 against rounding)."""
    d2 = (p * p).sum(1)[:, None] + (q * q).sum(1)[None, :] - 2.0 * p @ q.T
    return np.maximum(d2, 0.0)


def rbf(p: np.ndarray, q: np.ndarray, lengthscale: float) -> np.ndarray:
    """``k(p_i, q_j) = exp(-|p_i - q_j|^2 / (2 lengthscale^2))`` for all rows."""
    return np.exp(-0.5 * sq_dist(p, q) / lengthscale**2)


def spd_inverse(a: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive definite matrix from its Cholesky factor (LAPACK)."""
    chol, info = lapack.dpotrf(a, lower=True, clean=False)
    if info != 0:
        raise GPDataError(f"the data's covariance matrix is not positive definite (info {info})")
    inv, info = lapack.dpotri(chol, lower=True)
    if info != 0:
        raise GPDataError(f"inverting the data's covariance matrix failed (info {info})")
    return np.tril(inv) + np.tril(inv, -1).T
