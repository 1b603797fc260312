from __future__ import annotations

import pytest

from hopper_sim.cli import main
from hopper_sim.controller.checkpoint import load_checkpoint
from hopper_sim.controller.dataset import load_dataset
from hopper_sim.controller.errors import CheckpointModelMismatchError
from hopper_sim.physics.model import HopperModel


@pytest.mark.slow
def test_train_controller_small_run(tmp_path, capsys):
    out, data = tmp_path / "c.pt", tmp_path / "d.npz"
    args = ["train-controller", "--samples", "200", "--epochs", "2", "--hidden", "16"]
    args += ["--seed", "4", "--out", str(out), "--save-data", str(data), "--nthread", "1"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "hops/s" in text and "RMSE" in text and "steady gait" in text
    model = HopperModel.load()
    ckpt = load_checkpoint(out, expected_param_hash=model.param_hash())
    assert ckpt.metadata["seed"] == 4 and ckpt.metadata["samples"] == 200
    assert set(ckpt.metadata["steady"]) >= {"speed", "vz", "alpha"}
    ds = load_dataset(data)
    assert len(ds) == 200 and ds.metadata["param_hash"] == model.param_hash()
    # a model with other physics refuses this checkpoint
    other = HopperModel.load({"stiffness": 25000.0})
    with pytest.raises(CheckpointModelMismatchError):
        load_checkpoint(out, expected_param_hash=other.param_hash())
    # retraining from the saved data reproduces the same weights
    out2 = tmp_path / "c2.pt"
    args2 = ["train-controller", "--data", str(data), "--epochs", "2", "--hidden", "16"]
    assert main([*args2, "--seed", "4", "--out", str(out2)]) == 0
    a, b = ckpt.net.state_dict(), load_checkpoint(out2).net.state_dict()
    assert all((a[k] == b[k]).all() for k in a)
