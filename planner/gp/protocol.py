"""The protocol that the interval step needs from a model of the landing error."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class ErrorPredictor(Protocol):
    """A model of the mean landing error ``e(x)`` (metres) as a function of position (metres).

    ``predict`` returns the posterior mean and standard deviation of ``e`` per axis.
    ``variation`` bounds how much they can change between two points whose coordinates differ by
    at most ``half_width`` (per axis, metres): for all such ``x, x'`` and each axis ``d``,
    ``|mean_d(x) - mean_d(x')| <= dmean[d]`` and ``|std_d(x) - std_d(x')| <= dstd[d]``. It is
    what turns a finite set of samples into a bound over a whole cell.
    """

    def predict(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``points`` (M, 2) -> ``(mean (M, 2), std (M, 2))``, all in metres."""
        ...

    def variation(self, half_width: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``half_width`` (2,) -> ``(dmean (2,), dstd (2,))``, metres."""
        ...
