"""A small interval soundness audit in MuJoCo (the full one: benchmarks/audit_intervals.py)."""

import numpy as np

from hopper_sim.audit import audit_intervals, collect_run_data
from hopper_sim.runner import NavigationRunner
from planner.scenario import load_scenario


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
    assert res.counts.sum() + res.failures == res.hops
    assert res.failures <= res.hops // 20
    assert res.result.num_triples >= len(pairs)
    assert res.result.fraction >= 0.95, res.result.offenders[:3]
