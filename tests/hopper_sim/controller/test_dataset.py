from __future__ import annotations

import os

import numpy as np
import pytest

from hopper_sim.controller.dataset import (
    HopDataset,
    generate_dataset,
    load_dataset,
    save_dataset,
)
from hopper_sim.controller.errors import DatasetError
from hopper_sim.controller.hop_model import InputRanges

from .standin import failed, standin_hop


def test_generate_labels_failures_and_is_reproducible():
    ranges = InputRanges(speed=(2.0, 5.0))
    seen = []
    a = generate_dataset(
        standin_hop,
        900,
        seed=11,
        ranges=ranges,
        chunk=400,
        progress=seen.append,
        metadata={"param_hash": "abc"},
    )
    b = generate_dataset(standin_hop, 900, seed=11, ranges=ranges, chunk=300)
    c = generate_dataset(standin_hop, 900, seed=12, ranges=ranges)
    assert seen == [400, 400, 100]
    np.testing.assert_array_equal(a.inputs, b.inputs)
    np.testing.assert_array_equal(a.outputs, b.outputs)
    assert not np.array_equal(a.inputs, c.inputs)
    box = ranges.as_array()
    assert np.all((a.inputs >= box[:, 0]) & (a.inputs <= box[:, 1]))
    expected_fail = failed(a.inputs[:, 2], a.inputs[:, 3])
    assert expected_fail.any() and (~expected_fail).any()
    np.testing.assert_array_equal(a.ok, ~expected_fail)
    assert np.all(np.isnan(a.outputs[~a.ok]))
    assert set(a.status[~a.ok]) == {"no_touchdown"}
    assert a.metadata["param_hash"] == "abc" and a.metadata["seed"] == 11
    assert a.metadata["count"] == 900 and a.ranges == ranges
    # the heading is +x, so a straight-ahead hop moves along +x only
    straight = a.ok & (np.abs(a.inputs[:, 3]) < 0.05)
    assert np.all(np.abs(a.outputs[straight, 1]) < 0.05 * a.outputs[straight, 0])


def test_save_load_round_trip_is_atomic(tmp_path):
    ds = generate_dataset(standin_hop, 200, seed=1)
    path = save_dataset(ds, tmp_path / "sub" / "hops.npz")
    assert os.listdir(path.parent) == ["hops.npz"]
    back = load_dataset(path)
    np.testing.assert_array_equal(back.inputs, ds.inputs)
    np.testing.assert_array_equal(back.outputs, ds.outputs)
    np.testing.assert_array_equal(back.ok, ds.ok)
    assert back.metadata == ds.metadata


def test_load_rejects_bad_files(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(DatasetError, match=r"bad\.npz"):
        load_dataset(bad)
    partial = tmp_path / "partial.npz"
    np.savez(partial, inputs=np.zeros((2, 4)))
    with pytest.raises(DatasetError, match="missing array"):
        load_dataset(partial)


def test_dataset_validates_shapes():
    with pytest.raises(DatasetError, match="'outputs'"):
        HopDataset(np.zeros((3, 4)), np.zeros((3, 4)), np.ones(3, bool), np.array(["ok"] * 3))
    with pytest.raises(DatasetError, match="non-finite"):
        HopDataset(np.zeros((1, 4)), np.full((1, 5), np.nan), np.ones(1, bool), np.array(["ok"]))
