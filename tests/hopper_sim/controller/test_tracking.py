"""100 chained MuJoCo hops with the shipped checkpoint (looser bounds than the 1,000-hop
benchmark, benchmarks/bench_tracking.py)."""

from __future__ import annotations

import numpy as np

from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT, load_checkpoint
from hopper_sim.controller.controller import LegAngleController
from hopper_sim.controller.tracking import track_random_actions
from hopper_sim.physics.model import HopperModel


def test_shipped_checkpoint_tracks_100_chained_hops():
    model = HopperModel.load()
    ckpt = load_checkpoint(DEFAULT_CHECKPOINT, expected_param_hash=model.param_hash())
    ctl = LegAngleController.from_checkpoint(ckpt)
    res = track_random_actions(
        ctl,
        model,
        100,
        rng=np.random.default_rng(1),
        nominal_speed=ckpt.metadata["nominal_speed"],
    )
    assert res.ok.all()
    assert np.median(res.error) < 0.08
    assert np.percentile(res.error, 95) < 0.25
    assert len(np.unique(res.executed)) == 8
