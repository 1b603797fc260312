"""A small interval soundness audit in MuJoCo (the full one: benchmarks/audit_intervals.py)."""

import numpy as np
import pytest

from hopper_sim.audit import audit_intervals, clopper_pearson, collect_run_data
from hopper_sim.runner import NavigationRunner
from planner.scenario import load_scenario


def test_clopper_pearson_matches_known_values():
    lo, hi = clopper_pearson(np.array([0, 10, 20]), np.array([20, 20, 20]), 0.95)
    assert lo[0] == 0.0 and hi[2] == 1.0
    assert hi[0] == pytest.approx(1 - 0.025 ** (1 / 20))  # exact for k = 0
    assert lo[1] == pytest.approx(0.2720, abs=1e-4) and hi[1] == pytest.approx(0.7280, abs=1e-4)


def test_small_audit_holds():
    sc = load_scenario("a").with_runner(max_steps=30, batch_size=10)
    runner = NavigationRunner(sc)
    data = collect_run_data(runner, seed=2)
    assert len(data.positions) > 0 and data.errors.shape == data.positions.shape
    grid = runner.grid
    cells = grid.locate(data.positions[:3])
    pairs = np.array([[c, a] for c in cells for a in (2, 3)])  # E1, E2 from visited cells
    pairs = pairs[grid.enabled[pairs[:, 0], pairs[:, 1]]]
    res = audit_intervals(runner.env, data, pairs, samples=40, rng=np.random.default_rng(1))
    assert res.hops == 40 * len(pairs)
    # per pair, the landing frequencies over its successors sum to one
    for c, a in pairs:
        sel = (res.state == c) & (res.action == a)
        assert res.freq[sel].sum() == pytest.approx(1.0)
    assert res.failures <= res.hops // 20
    assert res.fraction_passed >= 0.95
