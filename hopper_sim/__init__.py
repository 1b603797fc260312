"""hopnav's simulation side: the MuJoCo SLIP hopper, its learned controller and the runner.

The nouns of the pipeline are importable from here (``from hopper_sim import HopperModel``);
each is imported on first use, so ``import hopper_sim`` does not load MuJoCo or torch.

Pipeline: :class:`HopperModel` (the MJCF, physical values read back by name) and
:func:`simulate_hop` / :func:`simulate_hops` (one or a batch of MuJoCo hops, with a
:class:`TerrainField` and landing noise); the :class:`LegAngleController` (learned hop model,
:func:`load_checkpoint`) turns grid actions into touchdown angles; :class:`HopperGridEnv`
(a Gymnasium environment) is the hopper in a scenario's grid world; the
:class:`NavigationRunner` plans on the learned abstraction (:mod:`planner`), hops and learns,
reporting to observers (:class:`Observer`, :class:`RerunRecorder`, :class:`FigureWriter`);
:func:`read_runs` reads a recording back and :func:`render_figure` draws Figure 4 maps
(:class:`Panel`, :class:`Route`); :func:`run_sweep` runs the Table I grid and
:func:`write_table_plot` plots it; :func:`provenance` says what produced a result.

With gymnasium installed (the ``gym`` extra), importing this package registers the
environment as ``hopnav/HopperGrid-v0`` (``gymnasium.make("hopnav/HopperGrid-v0",
scenario="b")``).
"""

from __future__ import annotations

import importlib
from typing import Any

from hopnav import __version__

#: public name -> module that defines it
_EXPORTS: dict[str, str] = {
    # the hopper
    "HopperModel": "hopper_sim.physics.model",
    "SlipParams": "hopper_sim.physics.model",
    "PerturbationParams": "hopper_sim.physics.model",
    "simulate_hop": "hopper_sim.physics.hop",
    "HopResult": "hopper_sim.physics.hop",
    "simulate_hops": "hopper_sim.physics.batch",
    "BatchHopResult": "hopper_sim.physics.batch",
    "TerrainField": "hopper_sim.physics.terrain",
    "sample_model_noise": "hopper_sim.physics.noise",
    "steady_gait": "hopper_sim.physics.gait",
    # the learned controller
    "LegAngleController": "hopper_sim.controller",
    "HopDecision": "hopper_sim.controller",
    "load_checkpoint": "hopper_sim.controller",
    "DEFAULT_CHECKPOINT": "hopper_sim.controller",
    # the environment and the loop
    "HopperGridEnv": "hopper_sim.navigation.environment",
    "EnvConfig": "hopper_sim.navigation.environment",
    "NavigationRunner": "hopper_sim.navigation.runner",
    "NavigationConfig": "hopper_sim.navigation.config",
    "default_config": "hopper_sim.navigation.config",
    "run_single": "hopper_sim.navigation.runner",
    # events and observers
    "Observer": "hopper_sim.navigation.events",
    "Observers": "hopper_sim.navigation.events",
    "RunStart": "hopper_sim.navigation.events",
    "HopEvent": "hopper_sim.navigation.events",
    "SynthesisEvent": "hopper_sim.navigation.events",
    "RunEnd": "hopper_sim.navigation.events",
    "RerunRecorder": "hopper_sim.viz.recording",
    "summarize_recording": "hopper_sim.viz.recording_reader",
    "read_runs": "hopper_sim.viz.recording_reader",
    "FigureWriter": "hopper_sim.viz.figures",
    "render_run_figure": "hopper_sim.viz.figures",
    # figures
    "Panel": "hopper_sim.viz.figures",
    "Route": "hopper_sim.viz.figures",
    "render_figure": "hopper_sim.viz.figures",
    "save_figure": "hopper_sim.viz.figure_files",
    "write_table_plot": "hopper_sim.viz.sweep_plot",
    # sweeps and provenance
    "SweepSpec": "hopper_sim.experiments.sweep_grid",
    "SweepResult": "hopper_sim.experiments.sweep_stats",
    "run_sweep": "hopper_sim.experiments.sweep",
    "write_outputs": "hopper_sim.experiments.sweep_files",
    "provenance": "hopper_sim.experiments.provenance",
    "scenario_digest": "hopper_sim.experiments.provenance",
    # errors
    "HopperSimError": "hopper_sim.errors",
}

__all__ = ["ENV_ID", "__version__", *_EXPORTS]

#: The Gymnasium id of :class:`HopperGridEnv`.
ENV_ID = "hopnav/HopperGrid-v0"


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'hopper_sim' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


def _register_gymnasium() -> None:
    try:
        import gymnasium
    except ImportError:
        return
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(
            id=ENV_ID,
            entry_point="hopper_sim.navigation.environment:HopperGridEnv",
            kwargs={"scenario": "a"},
            nondeterministic=False,
        )


_register_gymnasium()
