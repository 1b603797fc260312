from __future__ import annotations

import pytest
import torch

from hopper_sim.controller.dataset import generate_dataset
from hopper_sim.controller.hop_model import InputRanges
from hopper_sim.controller.optimizer import CostWeights
from hopper_sim.controller.training import TrainConfig, train_hop_model

from .standin import standin_hop

# Small MLPs are overhead-bound: extra threads only contend on the shared 2-core machine.
torch.set_num_threads(1)

SMALL_RANGES = InputRanges(speed=(2.5, 4.5), vz=(-1.5, 0.0))
# The stand-in's vertical dynamics are not physical: no apex margin on it.
STANDIN_WEIGHTS = CostWeights(c5=0.0)
TINY_CONFIG = TrainConfig(hidden=(64, 64), epochs=40, batch_size=256, lr=5e-3)


@pytest.fixture(scope="session")
def standin_dataset():
    return generate_dataset(standin_hop, 6000, seed=3, ranges=SMALL_RANGES, chunk=2000)


@pytest.fixture(scope="session")
def trained(standin_dataset):
    return train_hop_model(standin_dataset, TINY_CONFIG, seed=5)
