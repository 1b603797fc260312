from __future__ import annotations

import numpy as np
import pytest

from hopper_sim.controller.errors import InputShapeError
from hopper_sim.controller.optimizer import CostWeights, LegAngleOptimizer, OptimizerConfig

from .conftest import STANDIN_WEIGHTS as W
from .standin import failed, standin_hop


def _hop(speed, vz, alpha, beta):
    n = len(alpha)
    vel = np.tile([speed, 0.0, vz], (n, 1))
    return standin_hop(vel, alpha, beta)


@pytest.mark.parametrize("method", ["newton", "adam"])
def test_reaches_targets_through_the_true_map(trained, method):
    cfg = OptimizerConfig(method=method, steps=5 if method == "newton" else 15)
    opt = LegAngleOptimizer(trained.net, W, cfg)
    targets = np.array([[1.0, 0.0], [2.0, 0.0], [1.0, 0.6], [1.5, -0.8], [0.7, 0.0]])
    v_des = np.tile([3.5, 0.0, -0.6], (len(targets), 1))
    sol = opt.solve(3.5, -0.6, targets, v_des)
    lo, hi = trained.net.ranges.alpha, trained.net.ranges.beta
    assert np.all((sol.alpha >= lo[0]) & (sol.alpha <= lo[1]))
    assert np.all((sol.beta >= hi[0]) & (sol.beta <= hi[1]))
    res = _hop(3.5, -0.6, sol.alpha, sol.beta)
    assert res.ok.all()
    err = np.linalg.norm(res.displacement - targets, axis=1)
    assert np.all(err < 0.12), err
    # the solver's own prediction is close to its target (optimisation error only)
    assert np.all(np.linalg.norm(sol.displacement - targets, axis=1) < 0.03)
    assert np.all(sol.cost < 0.2)


def test_refinement_improves_on_the_grid(trained):
    targets = np.array([[1.23, 0.17], [1.81, -0.31]])
    v_des = np.tile([3.5, 0.0, -0.6], (2, 1))
    coarse = LegAngleOptimizer(trained.net, W, OptimizerConfig(steps=0)).solve(
        3.5, -0.6, targets, v_des
    )
    fine = LegAngleOptimizer(trained.net, W).solve(3.5, -0.6, targets, v_des)
    assert np.all(fine.cost <= coarse.cost + 1e-6)
    assert fine.cost.sum() < coarse.cost.sum()


def test_avoids_the_infeasible_region(trained):
    # 2 m at 60 degrees to the left needs alpha < 0.95 and beta > 1.0: the failure region.
    # Without the feasibility term the optimiser goes there; with it, it stays out.
    target = np.array([[1.0, 1.73]])
    v_des = np.array([[3.5, 0.0, -0.6]])
    free = CostWeights(c4=0.0, c5=0.0)
    sol_free = LegAngleOptimizer(trained.net, weights=free).solve(3.5, -0.6, target, v_des)
    sol = LegAngleOptimizer(trained.net, W).solve(3.5, -0.6, target, v_des)
    assert failed(sol_free.alpha, sol_free.beta).all()
    assert not failed(sol.alpha, sol.beta).any()
    assert sol.p_ok[0] > 0.9
    assert _hop(3.5, -0.6, sol.alpha, sol.beta).ok.all()


def test_is_deterministic_and_validates(trained):
    opt = LegAngleOptimizer(trained.net, W)
    t = np.array([[1.0, 0.2]])
    v = np.array([[3.5, 0.0, -0.6]])
    a, b = opt.solve(3.5, -0.6, t, v), opt.solve(3.5, -0.6, t, v)
    assert a.alpha[0] == b.alpha[0] and a.beta[0] == b.beta[0]
    with pytest.raises(InputShapeError, match=r"\(K, 2\)"):
        opt.solve(3.5, -0.6, np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(InputShapeError, match="finite"):
        opt.solve(float("nan"), -0.6, t, v)
    with pytest.raises(InputShapeError, match="method"):
        OptimizerConfig(method="bfgs")


def test_apex_margin_steepens_the_next_descent(trained):
    # stand-in: v_z' = -0.7 + 0.3 (v_z + 0.7) - 0.5 (alpha - 1.2); a short hop has a large
    # alpha and a steep next descent already, so ask for a long one (small alpha)
    target = np.array([[1.9, 0.0]])
    v_des = np.array([[3.5, 0.0, -0.6]])
    plain = LegAngleOptimizer(trained.net, W).solve(3.5, -0.6, target, v_des)
    # with two angles and a 2-D landing target there is no freedom left: the margin changes
    # the solution only when it outweighs the landing error (here 0.5 m/s of v_z' per
    # 2.6 m of reach per radian of alpha)
    weak = CostWeights(c5=1.0, vz_min=0.75)
    strong = CostWeights(c5=10.0, vz_min=0.75)
    same = LegAngleOptimizer(trained.net, weak).solve(3.5, -0.6, target, v_des)
    steep = LegAngleOptimizer(trained.net, strong).solve(3.5, -0.6, target, v_des)
    assert plain.velocity[0, 2] > -0.7
    assert same.velocity[0, 2] == pytest.approx(plain.velocity[0, 2], abs=0.01)
    assert steep.velocity[0, 2] < plain.velocity[0, 2] - 0.05
    assert np.linalg.norm(steep.displacement - target) > np.linalg.norm(plain.displacement - target)
