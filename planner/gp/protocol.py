"""The protocol that the interval step needs from a model of the landing error."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class ErrorPredictor(Protocol):
    """A model of the mean landing error ``e(x, a)`` (metres) as a function of the departure
    position ``x`` (metres) and the executed action ``a`` (``0 .. n_actions - 1``).

    ``predict`` returns the posterior mean and standard deviation of ``e`` per action and
    axis. ``variation`` bounds how much they can change near given points: for every point
    ``p = points[m]``, every ``x`` with ``|x_i - p_i| <= half_width[i]``, each action ``a``
    and axis ``d``, ``|mean(x, a, d) - mean(p, a, d)| <= dmean[m, a, d]`` and
    ``|std(x, a, d) - std(p, a, d)| <= dstd[a, d]``. It is what turns a finite set of samples
    into a bound over a whole cell. ``residual_std`` is the std of the hop-to-hop error beyond
    the known landing noise (what the departure position and action do not explain), per
    action and axis.
    """

    n_actions: int

    def predict(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``points`` (M, 2) -> ``(mean (M, n_actions, 2), std (M, n_actions, 2))``, metres."""
        ...

    def variation(
        self, points: np.ndarray, half_width: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``points`` (M, 2), ``half_width`` (2,) -> ``(dmean (M, n_actions, 2),
        dstd (n_actions, 2))``, metres."""
        ...

    def residual_std(self) -> np.ndarray:
        """``(n_actions, 2)`` std of the residual beyond the landing noise, metres."""
        ...
