from __future__ import annotations

import numpy as np
import pytest
import torch

from hopper_sim.controller.errors import DatasetError
from hopper_sim.controller.hop_model import OUTPUT_NAMES
from hopper_sim.controller.training import TrainConfig, split_indices, train_hop_model

from .conftest import TINY_CONFIG


def test_trained_model_fits_held_out_hops(trained, standin_dataset):
    m = trained.metrics
    assert set(OUTPUT_NAMES) <= set(m)
    assert m["dx"]["rmse"] < 0.08 and m["dy"]["rmse"] < 0.08
    assert m["vz"]["rmse"] < 0.05
    for name in OUTPUT_NAMES:
        assert m[name]["p95"] >= 0.0
    assert m["feasibility"]["accuracy"] > 0.93
    assert trained.loss_history[-1] < 0.2 * trained.loss_history[0]
    assert len(np.intersect1d(trained.train_index, trained.test_index)) == 0
    assert len(trained.train_index) + len(trained.test_index) == len(standin_dataset)


def test_same_seed_same_weights(standin_dataset):
    cfg = TrainConfig(hidden=(16,), epochs=2, batch_size=512)
    a = train_hop_model(standin_dataset, cfg, seed=9)
    b = train_hop_model(standin_dataset, cfg, seed=9)
    c = train_hop_model(standin_dataset, cfg, seed=10)
    for (ka, va), (_, vb) in zip(
        a.net.state_dict().items(), b.net.state_dict().items(), strict=True
    ):
        assert torch.equal(va, vb), ka
    assert not torch.equal(a.net.trunk[0].weight, c.net.trunk[0].weight)


def test_split_and_degenerate_data_errors(standin_dataset):
    with pytest.raises(DatasetError, match="test_fraction"):
        split_indices(10, 1.5, np.random.default_rng(0))
    ds = standin_dataset
    no_ok = type(ds)(ds.inputs, ds.outputs * np.nan, ds.ok & False, ds.status, ds.metadata)
    with pytest.raises(DatasetError, match="successful"):
        train_hop_model(no_ok, TINY_CONFIG, seed=0)
