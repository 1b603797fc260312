"""Sparse Gaussian-process models of the hopper's mean landing error.

The landing error ``e(x) = landing - target`` (metres, per axis) is modelled as a function of
the departure position ``x = (x, y)`` (metres) by two independent sparse GPs, batched into one
gpytorch module (:class:`~planner.gp.sgpr.SparseGP`). The interval step
(:mod:`planner.intervals`) depends only on the small :class:`~planner.gp.protocol.ErrorPredictor`
protocol.
"""

from __future__ import annotations

from planner.gp.landing import FitReport, FitSettings, LandingErrorGP
from planner.gp.protocol import ErrorPredictor
from planner.gp.sgpr import SparseGP, SparsePosterior

__all__ = [
    "ErrorPredictor",
    "FitReport",
    "FitSettings",
    "LandingErrorGP",
    "SparseGP",
    "SparsePosterior",
]
