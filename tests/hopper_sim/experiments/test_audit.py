"""A small interval soundness audit in MuJoCo, sampled as the loop samples (the full one:
benchmarks/audit_intervals.py)."""

import numpy as np
import pytest

from hopper_sim.experiments.audit import (
    audit_intervals,
    collect_run_data,
    excluded_landings,
    loop_allowed_actions,
    pool_velocities,
)
from hopper_sim.navigation.runner import NavigationRunner
from planner.gp import LandingErrorGP
from planner.learning import resynthesise
from planner.scenario import load_scenario


@pytest.fixture(scope="module")
def run():
    sc = load_scenario("a").with_runner(max_steps=30, batch_size=10)
    runner = NavigationRunner(sc)
    return runner, collect_run_data(runner, seed=2)


@pytest.mark.slow
def test_small_loop_like_audit_holds(run):
    runner, data = run
    assert len(data.positions) > 0 and data.errors.shape == data.positions.shape
    assert data.velocities.shape == (len(data.positions), 3)
    assert data.actions.shape == (len(data.positions),) and data.actions.max() < 8
    grid = runner.grid
    cells = np.unique(grid.locate(data.positions[:4]))[:2]
    pairs = np.array([[c, a] for c in cells for a in np.flatnonzero(grid.enabled[c])])
    samples, attempts = 30, 2
    res = audit_intervals(
        runner, data, pairs, samples=samples, attempts=attempts, rng=np.random.default_rng(1)
    )
    # bookkeeping: hops count for the pair of the action they executed, never beyond samples
    assert (res.executed <= samples).all() and (res.requests <= attempts * samples).all()
    np.testing.assert_array_equal(res.counts.sum(axis=1), res.executed)
    assert res.hops == res.executed.sum() + res.failures
    assert res.failures <= res.hops // 20
    assert res.decisions >= res.hops and res.decisions == res.requests.sum()
    assert res.full.sum() >= len(pairs) // 2  # most actions get executed from these states
    assert res.result is not None and res.result.num_triples >= int(res.full.sum())
    assert res.result.fraction >= 0.99, res.result.offenders[:3]
    # landings the intervals exclude are listed, not hidden by the margin
    ti = res.intervals
    for c, a, succ, k, n in excluded_landings(res, pairs):
        row = (ti.state == c) & (ti.action == a) & (ti.successor == succ)
        assert not (ti.upper[row] > 0).any() and 0 < k <= n
        p = int(np.flatnonzero((pairs[:, 0] == c) & (pairs[:, 1] == a))[0])
        assert res.counts[p, succ] == k and res.executed[p] == n


def test_audit_rejects_bad_pairs(run):
    runner, data = run
    grid = runner.grid
    corner = 0  # cell (0, 0): S1 (index 4) leaves the world
    with pytest.raises(ValueError, match="not enabled"):
        audit_intervals(runner, data, [[corner, 4]], samples=1, rng=np.random.default_rng(0))
    ok = int(np.flatnonzero(grid.enabled[corner])[0])
    with pytest.raises(ValueError, match="only once"):
        audit_intervals(
            runner, data, [[corner, ok], [corner, ok]], samples=1, rng=np.random.default_rng(0)
        )


def test_velocities_are_pooled_over_runs(run):
    runner, data = run
    pooled = pool_velocities(runner, data, [3])
    np.testing.assert_array_equal(pooled.positions, data.positions)
    np.testing.assert_array_equal(pooled.velocities[: len(data.velocities)], data.velocities)
    assert len(pooled.velocities) > len(data.velocities)


def test_loop_allowed_actions_follow_the_phase(run):
    runner, _ = run
    sc, grid = runner.scenario, runner.grid
    z = np.zeros((0, 2))
    res = resynthesise(
        LandingErrorGP(runner.gp_settings), grid, runner.automaton, z, z,
        reward=runner.env.reward_table, initial_cell=sc.start_cell,
        settings=runner.synthesis_settings,
    )  # fmt: skip
    allowed = loop_allowed_actions(res, grid, sc.p_sat)
    assert (allowed <= grid.enabled[: grid.n_cells]).all()
    for cell in range(grid.n_cells):
        ps = res.product.entry_state(cell)
        if res.satisfaction.values[ps] > sc.p_sat and res.goal.allowed[ps].any():
            want = res.goal.allowed[ps]  # goal reaching
        elif res.exploration.allowed[ps].any():
            want = res.exploration.allowed[ps]
        else:
            want = grid.enabled[cell]  # fallback: every enabled action
        np.testing.assert_array_equal(allowed[cell], want & grid.enabled[cell])
