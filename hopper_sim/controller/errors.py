"""Exceptions raised by :mod:`hopper_sim.controller`.

Every error says what is wrong and where (a file, a field, an array and its shape). All derive
from :class:`ControllerError`, itself a ``ValueError``.
"""

from __future__ import annotations

from hopper_sim.errors import HopperSimError


class ControllerError(HopperSimError, ValueError):
    """Base class of every error raised by :mod:`hopper_sim.controller`."""


class InputShapeError(ControllerError):
    """An array argument has the wrong shape, dtype or non-finite entries."""


class DatasetError(ControllerError):
    """A hop dataset is malformed (missing array, inconsistent lengths, bad metadata)."""


class CheckpointError(ControllerError):
    """Base class of the checkpoint loading errors."""


class CheckpointCorruptError(CheckpointError):
    """The checkpoint file cannot be read, or it lacks a field, or a field is malformed."""


class CheckpointVersionError(CheckpointError):
    """The checkpoint was written by an incompatible format version."""


class CheckpointModelMismatchError(CheckpointError):
    """The checkpoint was trained on a hopper whose MJCF parameters differ from the current one."""


class SteadyStateError(ControllerError):
    """The steady-hopping fixed point could not be found to the requested tolerance."""


class ActionError(ControllerError):
    """The requested action is not among the allowed actions, or the action set is empty."""
