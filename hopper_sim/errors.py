"""The one error base of :mod:`hopper_sim`.

Every exception the simulation side raises derives from :class:`HopperSimError`, so a caller
can catch all of them in one clause. Each also keeps its own other base (``ValueError`` for
bad input or files, ``RuntimeError`` for a run or backend that failed), so that
``except ValueError`` callers keep working. The exceptions stay in the modules that raise
them (``HopperModelError`` in :mod:`hopper_sim.physics.model`, ``RecordingError`` in
:mod:`hopper_sim.viz.recording`, the controller's under :mod:`hopper_sim.controller.errors`...).
"""

from __future__ import annotations


class HopperSimError(Exception):
    """Base class of every exception raised by :mod:`hopper_sim`."""
