"""Every exception hopper_sim defines derives from the one base, HopperSimError, and keeps
its builtin base (so ``except ValueError`` callers keep working)."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import hopper_sim
from hopper_sim.errors import HopperSimError

#: Modules that need an optional extra to import (none of them defines an exception).
_OPTIONAL = {"ray", "gymnasium"}


def _exception_classes() -> dict[str, type[BaseException]]:
    found: dict[str, type[BaseException]] = {}
    for info in pkgutil.walk_packages(hopper_sim.__path__, "hopper_sim."):
        try:
            module = importlib.import_module(info.name)
        except ImportError as err:  # pragma: no cover - an optional extra is missing
            if err.name in _OPTIONAL:
                continue
            raise
        for name, obj in vars(module).items():
            if (
                inspect.isclass(obj)
                and issubclass(obj, BaseException)
                and obj.__module__ == module.__name__
            ):
                found[f"{module.__name__}.{name}"] = obj
    return found


CLASSES = _exception_classes()


def test_the_package_defines_exceptions():
    assert len(CLASSES) >= 20  # the walk found the modules


@pytest.mark.parametrize("name", sorted(CLASSES))
def test_every_exception_derives_from_the_base(name):
    assert issubclass(CLASSES[name], HopperSimError), name


def test_builtin_bases_are_kept():
    from hopper_sim.experiments.sweep import SweepBackendError, SweepRunError
    from hopper_sim.navigation.environment import EpisodeError
    from hopper_sim.physics.model import HopperModelError
    from hopper_sim.viz.recording import RecordingError

    assert issubclass(HopperModelError, ValueError) and issubclass(RecordingError, ValueError)
    assert issubclass(EpisodeError, RuntimeError) and issubclass(SweepRunError, RuntimeError)
    assert issubclass(SweepBackendError, RuntimeError)
    with pytest.raises(HopperSimError, match="flush_every"):
        from hopper_sim.viz.recording import RerunRecorder

        RerunRecorder("x.rrd", flush_every=0)
