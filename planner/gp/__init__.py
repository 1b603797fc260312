"""Gaussian-process models of the hopper's mean landing error.

The landing error ``e(x, a) = landing - target`` (metres, per axis) is modelled as a function
of the departure position ``x = (x, y)`` (metres) and the executed action ``a`` by
:class:`~planner.gp.landing.LandingErrorGP` (exact GP regression with a fixed prior; the
hop-to-hop part is :mod:`planner.gp.noise`). The interval step (:mod:`planner.intervals`)
depends only on the small :class:`~planner.gp.protocol.ErrorPredictor` protocol.
:class:`~planner.gp.sgpr.SparseGP` is a batched sparse GP (Titsias), kept for comparison with
the paper's 50-inducing-point model (``benchmarks/gp_update.py``).
"""

from __future__ import annotations

from planner.gp.landing import FitReport, GPConfig, LandingErrorGP
from planner.gp.noise import ResidualNoise, TruncatedGaussianNoise
from planner.gp.protocol import ErrorPredictor
from planner.gp.sgpr import SparseGP, SparsePosterior, rbf_sparse_gp

__all__ = [
    "ErrorPredictor",
    "FitReport",
    "GPConfig",
    "LandingErrorGP",
    "ResidualNoise",
    "SparseGP",
    "SparsePosterior",
    "TruncatedGaussianNoise",
    "rbf_sparse_gp",
]
