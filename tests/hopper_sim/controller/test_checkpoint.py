from __future__ import annotations

import io
import os

import numpy as np
import pytest
import torch

from hopper_sim.controller.checkpoint import (
    CHECKPOINT_VERSION,
    DEFAULT_CHECKPOINT,
    MAX_WEIGHT,
    SEAL_KIND,
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
from planner._util.sealed import seal, unseal


@pytest.fixture()
def saved(tmp_path, trained):
    ckpt = HopModelCheckpoint(trained.net, "hash-1", {"seed": 5, "steady": {"speed": 3.0}})
    return save_checkpoint(ckpt, tmp_path / "c.pt"), trained.net


def _rewrite(path, **changes):
    """Change fields of the payload and seal it again (a valid digest over bad contents)."""
    payload = torch.load(io.BytesIO(unseal(path.read_bytes(), SEAL_KIND)), weights_only=True)
    for key, value in changes.items():
        if value is None:
            del payload[key]
        else:
            payload[key] = value
    buf = io.BytesIO()
    torch.save(payload, buf)
    path.write_bytes(seal(SEAL_KIND, buf.getvalue()))


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
    with pytest.raises(CheckpointCorruptError, match="not an intact checkpoint"):
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


def test_huge_finite_weight_is_refused(saved):
    # a flipped exponent bit turns a weight into about 1.36e38: finite, and it drove the robot
    # off the map; with a valid digest (a crafted file) the magnitude check still refuses it
    path, net = saved
    state = {k: v.clone() for k, v in net.state_dict().items()}
    state["trunk.2.weight"][3, 7] = 1.36e38
    _rewrite(path, state_dict=state)
    with pytest.raises(CheckpointCorruptError, match="plausible magnitude"):
        load_checkpoint(path)
    assert MAX_WEIGHT >= 1e3 * max(float(v.abs().max()) for v in net.state_dict().values())


def test_oversized_layers_are_refused_before_allocating(saved):
    path, _ = saved
    _rewrite(path, hidden=[10**9, 10**9])
    with pytest.raises(CheckpointCorruptError, match="layer widths"):
        load_checkpoint(path)


def test_unsealed_version_1_file_is_refused(saved, tmp_path):
    path, _ = saved
    raw = tmp_path / "v1.pt"
    raw.write_bytes(unseal(path.read_bytes(), SEAL_KIND))  # a bare torch.save zip
    with pytest.raises(CheckpointVersionError, match="version 1"):
        load_checkpoint(raw)


def test_every_single_bit_flip_is_detected(tmp_path):
    """100 random bit flips anywhere in the shipped checkpoint: each is CheckpointCorruptError
    (the header, the digest or the payload), never a silent load."""
    data = DEFAULT_CHECKPOINT.read_bytes()
    rng = np.random.default_rng(20240518)
    positions = rng.integers(0, len(data), size=100)
    positions[:3] = (0, len(data) // 2, len(data) - 1)  # first, middle and last byte too
    path = tmp_path / "flipped.pt"
    for pos, bit in zip(positions, rng.integers(0, 8, size=100), strict=True):
        flipped = bytearray(data)
        flipped[pos] ^= 1 << int(bit)
        path.write_bytes(bytes(flipped))
        with pytest.raises(CheckpointCorruptError):
            load_checkpoint(path)
    path.write_bytes(data)
    assert load_checkpoint(path).net is not None  # the intact bytes load
