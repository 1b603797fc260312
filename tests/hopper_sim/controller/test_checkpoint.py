from __future__ import annotations

import os

import numpy as np
import pytest
import torch

from hopper_sim.controller.checkpoint import (
    CHECKPOINT_VERSION,
    HopModelCheckpoint,
    load_checkpoint,
    save_checkpoint,
)
from hopper_sim.controller.errors import (
    CheckpointCorruptError,
    CheckpointError,
    CheckpointModelMismatchError,
    CheckpointVersionError,
)


@pytest.fixture()
def saved(tmp_path, trained):
    ckpt = HopModelCheckpoint(trained.net, "hash-1", {"seed": 5, "steady": {"speed": 3.0}})
    return save_checkpoint(ckpt, tmp_path / "c.pt"), trained.net


def _rewrite(path, **changes):
    payload = torch.load(path, weights_only=True)
    for key, value in changes.items():
        if value is None:
            del payload[key]
        else:
            payload[key] = value
    torch.save(payload, path)


def test_round_trip_predicts_identically(saved, standin_dataset):
    path, net = saved
    assert os.listdir(path.parent) == ["c.pt"]
    back = load_checkpoint(path, expected_param_hash="hash-1")
    assert back.param_hash == "hash-1" and back.metadata["seed"] == 5
    assert back.net.ranges == net.ranges and back.net.hidden == net.hidden
    x = standin_dataset.inputs[:50]
    np.testing.assert_array_equal(back.net.predict(x)[0], net.predict(x)[0])


def test_corrupt_file(saved):
    path, _ = saved
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointCorruptError, match="cannot be read"):
        load_checkpoint(path)


def test_wrong_version(saved):
    path, _ = saved
    _rewrite(path, version=CHECKPOINT_VERSION + 1)
    with pytest.raises(CheckpointVersionError, match=f"version {CHECKPOINT_VERSION + 1}"):
        load_checkpoint(path)


def test_parameter_mismatch(saved):
    path, _ = saved
    with pytest.raises(CheckpointModelMismatchError, match=r"hash-1.*hash-2"):
        load_checkpoint(path, expected_param_hash="hash-2")


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"state_dict": None}, "lacks the field 'state_dict'"),
        ({"format": "something-else"}, "format"),
        ({"hidden": [3, 3]}, "malformed"),
        ({"ranges": [[0.0, 1.0]]}, "malformed"),
        ({"metadata_json": "{not json"}, "malformed"),
    ],
)
def test_malformed_fields(saved, change, match):
    path, _ = saved
    _rewrite(path, **change)
    with pytest.raises(CheckpointCorruptError, match=match):
        load_checkpoint(path)


def test_non_finite_weights(saved):
    path, net = saved
    state = {k: v.clone() for k, v in net.state_dict().items()}
    state["trunk.0.weight"][0, 0] = float("nan")
    _rewrite(path, state_dict=state)
    with pytest.raises(CheckpointError, match="non-finite"):
        load_checkpoint(path)
