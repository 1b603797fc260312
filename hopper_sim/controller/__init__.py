"""Learned hop model and leg-angle controller.

Pipeline: :mod:`dataset` (simulated hops, failures labelled) -> :mod:`training`
(:class:`~hop_model.HopNet`) -> :mod:`checkpoint` (validated, atomic) -> :mod:`optimizer`
(batched leg-angle search) -> :mod:`controller` (world targets, backup switch); :mod:`steady`
computes the steady-hopping velocity ``v_des``.
"""

from hopper_sim.controller.checkpoint import (
    DEFAULT_CHECKPOINT,
    HopModelCheckpoint,
    load_checkpoint,
    save_checkpoint,
)
from hopper_sim.controller.controller import HopDecision, LegAngleController
from hopper_sim.controller.dataset import (
    HopDataset,
    HopSamples,
    Sampling,
    generate_dataset,
    load_dataset,
    save_dataset,
)
from hopper_sim.controller.hop_model import HopNet, InputRanges
from hopper_sim.controller.optimizer import CostWeights, LegAngleOptimizer, OptimizerConfig
from hopper_sim.controller.steady import SteadyState, steady_state
from hopper_sim.controller.training import TrainConfig, train_hop_model

__all__ = [
    "DEFAULT_CHECKPOINT",
    "CostWeights",
    "HopDataset",
    "HopDecision",
    "HopModelCheckpoint",
    "HopNet",
    "HopSamples",
    "InputRanges",
    "LegAngleController",
    "LegAngleOptimizer",
    "OptimizerConfig",
    "Sampling",
    "SteadyState",
    "TrainConfig",
    "generate_dataset",
    "load_checkpoint",
    "load_dataset",
    "save_checkpoint",
    "save_dataset",
    "steady_state",
    "train_hop_model",
]
