from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import truncnorm

from planner.audit import audit_intervals
from planner.errors import IntervalError
from planner.gp import LandingErrorGP
from planner.imdp.grid import GridWorld
from planner.intervals import (
    CellErrorBounds,
    TruncatedGaussianNoise,
    cell_error_bounds,
    cell_sample_points,
    confidence_beta,
    transition_intervals,
)
from tests.planner.conftest import smooth_error

NX, NY, CELL = 15, 15, 1.0
GRID = GridWorld(NX, NY, CELL)


def _row_sums(ti):
    key = ti.state * 8 + ti.action
    n = (NX * NY) * 8
    return (
        np.bincount(key, ti.lower, minlength=n),
        np.bincount(key, ti.upper, minlength=n),
        np.bincount(key, minlength=n) > 0,
    )


def _bounds(lo, hi, nx=NX, ny=NY):
    n = nx * ny
    return CellErrorBounds(np.full((n, 2), lo), np.full((n, 2), hi), 0.0, 0.01, 1)


def test_truncated_gaussian_cdf_matches_scipy():
    noise = TruncatedGaussianNoise(sigma=0.1, bound=0.2)
    t = np.linspace(-0.5, 0.5, 101)
    np.testing.assert_allclose(noise.cdf(t), truncnorm(-2, 2, scale=0.1).cdf(t), atol=1e-12)
    draws = noise.sample(np.random.default_rng(0), 20000)
    assert np.abs(draws).max() <= 0.2
    assert abs(draws.std() - truncnorm(-2, 2, scale=0.1).std()) < 3e-3


def test_confidence_beta_is_the_union_bound_quantile():
    assert confidence_beta(0.05, 1) == pytest.approx(1.959964, abs=1e-6)
    assert confidence_beta(0.01, 100) > confidence_beta(0.01, 10)
    with pytest.raises(IntervalError, match="delta"):
        confidence_beta(1.5, 3)


def test_rows_cover_exactly_the_enabled_actions():
    ti = transition_intervals(_bounds(-0.1, 0.1), GRID)
    has = np.zeros((NX * NY, 8), dtype=bool)
    has[ti.state, ti.action] = True
    np.testing.assert_array_equal(has, GRID.enabled[: NX * NY])
    assert has[0].tolist() == [True, True, True, True, False, False, False, False]
    model = GRID.imdp_from_intervals(*ti.coo())
    assert model.n_states == NX * NY + 1


def test_exact_error_gives_exact_probabilities():
    noise = TruncatedGaussianNoise()
    b = _bounds(0.45, 0.45)
    b.lower[:, 1] = b.upper[:, 1] = 0.0
    ti = transition_intervals(b, GRID, noise)
    np.testing.assert_allclose(ti.lower, ti.upper)
    lo, _hi, enabled = _row_sums(ti)
    np.testing.assert_allclose(lo[enabled], 1.0, atol=1e-12)
    # cell (7, 7), E1: target centre (8.5, 7.5), shifted by 0.45 -> x in [8.75, 9.15]
    sel = (ti.state == 7 * NY + 7) & (ti.action == 2)
    got = dict(zip(ti.successor[sel].tolist(), ti.lower[sel].tolist(), strict=True))
    p9 = 1.0 - noise.cdf(np.array(9.0 - 8.95))
    assert got[9 * NY + 7] == pytest.approx(float(p9))
    assert got[8 * NY + 7] == pytest.approx(float(1.0 - p9))


def test_rows_bracket_one_and_out_is_handled():
    rng = np.random.default_rng(3)
    lo = rng.uniform(-0.8, 0.2, size=(NX * NY, 2))
    hi = lo + rng.uniform(0.0, 0.8, size=lo.shape)
    ti = transition_intervals(CellErrorBounds(lo, hi, 0.0, 0.01, 1), GRID)
    assert (ti.lower <= ti.upper).all() and (ti.lower >= 0).all() and (ti.upper <= 1).all()
    slo, shi, enabled = _row_sums(ti)
    assert (slo[enabled] <= 1.0 + 1e-12).all() and (shi[enabled] >= 1.0 - 1e-12).all()
    out = ti.successor == NX * NY
    # E2 from the column next to the east border can leave the world; from the middle it cannot
    east = out & (ti.state // NY == NX - 3) & (ti.action == 3)
    assert east.any()
    assert not (out & (ti.state == 7 * NY + 7) & (ti.action == 0)).any()
    assert ti.num_states == NX * NY + 1


def test_per_axis_bounds_are_min_and_max_over_the_error_interval():
    noise = TruncatedGaussianNoise()
    e_lo, e_hi = -0.3, 0.25
    ti = transition_intervals(_bounds(e_lo, e_hi, 5, 5), GridWorld(5, 5, CELL), noise)
    sel = (ti.state == 2 * 5 + 2) & (ti.action == 0)  # N1 from (2, 2): target (2, 3)
    es = np.linspace(e_lo, e_hi, 401)
    ex, ey = np.meshgrid(es, es, indexing="ij")
    for succ, lo, hi in zip(ti.successor[sel], ti.lower[sel], ti.upper[sel], strict=True):
        if succ == 25:
            continue
        ci, cj = divmod(int(succ), 5)
        px = noise.cdf(ci + 1 - 2.5 - ex) - noise.cdf(ci - 2.5 - ex)
        py = noise.cdf(cj + 1 - 3.5 - ey) - noise.cdf(cj - 3.5 - ey)
        p = px * py
        assert p.min() >= lo - 1e-12 and p.max() <= hi + 1e-12
        assert p.min() == pytest.approx(lo, abs=1e-3) and p.max() == pytest.approx(hi, abs=1e-3)


def test_bad_bounds_are_rejected():
    with pytest.raises(IntervalError, match="shape"):
        transition_intervals(_bounds(0, 0, 3, 3), GRID)
    b = _bounds(0.0, 0.1)
    b.lower[17, 1] = 0.5
    with pytest.raises(IntervalError, match="cell 17"):
        transition_intervals(b, GRID)
    with pytest.raises(IntervalError, match="sigma"):
        TruncatedGaussianNoise(sigma=0.0)


def test_prior_intervals_are_wide():
    ti = transition_intervals(cell_error_bounds(LandingErrorGP(), GRID), GRID)
    _, shi, enabled = _row_sums(ti)
    assert shi[enabled].min() > 2.0


def test_error_bounds_contain_the_true_field(fitted_gp):
    bounds = cell_error_bounds(fitted_gp, GRID, samples_per_axis=4)
    dense = cell_sample_points(GRID, 9)  # other points than the bounds' samples
    truth = smooth_error(dense.reshape(-1, 2)).reshape(dense.shape)
    inside = (truth >= bounds.lower[:, None, :]) & (truth <= bounds.upper[:, None, :])
    assert inside.all(axis=(1, 2)).mean() >= 0.99
    assert (bounds.upper - bounds.lower).mean() < 0.8  # learned: narrower than the prior


def test_empirical_frequencies_lie_in_the_intervals(fitted_gp):
    rng = np.random.default_rng(12)
    noise = TruncatedGaussianNoise()
    bounds = cell_error_bounds(fitted_gp, GRID)
    ti = transition_intervals(bounds, GRID, noise)
    state, action = np.nonzero(GRID.enabled[: NX * NY])
    pick = rng.choice(len(state), size=40, replace=False)
    n = 300
    counts = np.zeros((pick.size, NX * NY + 1), dtype=np.int64)
    for row, k in enumerate(pick):
        start = (np.array(divmod(int(state[k]), NY)) + rng.uniform(0, 1, (n, 2))) * CELL
        target = GRID.target_centres[state[k], action[k]]
        land = target + smooth_error(start) + noise.sample(rng, (n, 2))
        counts[row] = np.bincount(GRID.locate(land), minlength=NX * NY + 1)
    result = audit_intervals(ti, state[pick], action[pick], counts)
    assert result.fraction >= 0.99
    assert result.num_triples >= 100  # 40 pairs, several successors each
    # nothing lands where the upper bound is 0 (or where no interval is listed)
    assert all(o.upper > 0 for o in result.offenders)
