from __future__ import annotations

import numpy as np
import pytest

from hopper_sim.controller.checkpoint import HopModelCheckpoint
from hopper_sim.controller.controller import LegAngleController
from hopper_sim.controller.errors import ActionError, CheckpointCorruptError, InputShapeError
from hopper_sim.controller.hop_model import rotate_xy
from hopper_sim.controller.steady import steady_state

from .conftest import STANDIN_WEIGHTS
from .standin import standin_hop

# N1, N2, E1, E2, S1, S2, W1, W2 (docs/design.md order)
OFFSETS = np.array([[0, 1], [0, 2], [1, 0], [2, 0], [0, -1], [0, -2], [-1, 0], [-2, 0]], float)


@pytest.fixture(scope="module")
def controller(trained):
    return LegAngleController(trained.net, steady_state(standin_hop, 1.5), weights=STANDIN_WEIGHTS)


def _hop(vel, d):
    return standin_hop(vel[None], np.array([d.alpha]), np.array([d.beta]))


def test_chained_hops_track_targets(controller):
    """100 chained hops through the true stand-in map: each starts where the last ended."""
    rng = np.random.default_rng(0)
    pos, vel = np.array([0.5, 0.5]), controller.steady.velocity.copy()
    errors, backups = [], 0
    for _ in range(100):
        req = int(rng.integers(8))
        targets = pos + OFFSETS
        d = controller.decide(pos, vel, range(8), targets, req)
        res = _hop(vel, d)
        assert res.ok[0]
        new = pos + res.displacement[0]
        errors.append(np.linalg.norm(new - targets[d.executed]))
        backups += d.backup_used
        if not d.backup_used:
            assert d.executed == req
        pos, vel = new, res.next_velocity[0]
    errors = np.array(errors)
    assert np.median(errors) < 0.08 and np.percentile(errors, 95) < 0.15
    # the stand-in cannot turn by 90 degrees or more in one hop, so backups must occur
    assert 0 < backups < 100


def test_decision_is_in_world_frame_and_rotation_equivariant(controller):
    pos = np.array([3.5, 4.5])
    vel = controller.steady.velocity
    targets = pos + OFFSETS
    d = controller.decide(pos, vel, range(8), targets, 2)  # E1 while heading east
    assert d.executed == 2 and not d.backup_used
    assert np.linalg.norm(d.predicted_landing - targets[2]) < 0.05
    # the same situation rotated by 90 degrees: heading north, command N1
    rot = rotate_xy(vel, np.pi / 2)
    targets_r = pos + rotate_xy(OFFSETS, np.pi / 2)
    d_r = controller.decide(pos, rot, range(8), targets_r, 2)
    assert d_r.executed == 2
    assert d_r.alpha == pytest.approx(d.alpha, abs=1e-4)
    assert d_r.beta == pytest.approx(d.beta, abs=1e-4)
    np.testing.assert_allclose(
        d_r.predicted_landing - pos, rotate_xy(d.predicted_landing - pos, np.pi / 2), atol=1e-4
    )


def test_backup_switch(controller):
    pos, vel = np.array([5.5, 5.5]), controller.steady.velocity  # heading +x
    targets = pos + OFFSETS
    # W2 (straight back) is out of reach: the backup executes the cheapest allowed action
    d = controller.decide(pos, vel, [7, 1, 3], targets[[7, 1, 3]], 7)
    assert d.requested == 7 and d.backup_used
    assert d.costs[0] > controller.backup_threshold
    assert d.executed == 3 and d.cost == pytest.approx(d.costs.min())
    # a reachable request is kept even if another action is cheaper
    d2 = controller.decide(pos, vel, [2, 3], targets[[2, 3]], 2)
    assert d2.executed == 2 and not d2.backup_used
    # if nothing is cheaper, the requested action is executed despite its cost
    d3 = controller.decide(pos, vel, [7], targets[[7]], 7)
    assert d3.executed == 7 and not d3.backup_used and d3.cost > controller.backup_threshold


def test_errors(controller, trained):
    pos, vel = np.zeros(2), controller.steady.velocity
    with pytest.raises(ActionError, match="not among"):
        controller.decide(pos, vel, [0, 1], OFFSETS[:2], 5)
    with pytest.raises(ActionError, match="2 actions but 3 targets"):
        controller.decide(pos, vel, [0, 1], OFFSETS[:3], 0)
    with pytest.raises(InputShapeError, match="heading"):
        controller.decide(pos, np.array([0.0, 0.0, -1.0]), [0], OFFSETS[:1], 0)
    with pytest.raises(CheckpointCorruptError, match="steady"):
        LegAngleController.from_checkpoint(HopModelCheckpoint(trained.net, "h", {}))
