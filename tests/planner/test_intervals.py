from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm, truncnorm

from planner.audit import audit_counts
from planner.errors import IntervalError
from planner.gp import GPConfig, LandingErrorGP
from planner.imdp.grid import GridWorld
from planner.intervals import (
    CellErrorBounds,
    ResidualNoise,
    TruncatedGaussianNoise,
    axis_intervals,
    cell_error_bounds,
    cell_sample_points,
    confidence_beta,
    transition_intervals,
)
from tests.planner.conftest import action_error

NX, NY, CELL = 15, 15, 1.0
GRID = GridWorld(NX, NY, CELL)
BOUNDS = {"samples_per_axis": 3, "delta": 0.01, "horizon": 100}  # the abstraction's options
NA = 8


def _row_sums(ti):
    key = ti.state * NA + ti.action
    n = (NX * NY) * NA
    return (
        np.bincount(key, ti.lower, minlength=n),
        np.bincount(key, ti.upper, minlength=n),
        np.bincount(key, minlength=n) > 0,
    )


def _bounds(lo, hi, nx=NX, ny=NY, residual=0.0):
    n = nx * ny
    return CellErrorBounds(
        np.full((n, NA, 2), lo, dtype=float),
        np.full((n, NA, 2), hi, dtype=float),
        np.full((NA, 2), residual, dtype=float),
        0.0,
        0.01,
        1,
    )


def test_truncated_gaussian_cdf_matches_scipy():
    noise = TruncatedGaussianNoise(sigma=0.1, bound=0.2)
    t = np.linspace(-0.5, 0.5, 101)
    np.testing.assert_allclose(noise.cdf(t), truncnorm(-2, 2, scale=0.1).cdf(t), atol=1e-12)
    draws = noise.sample(np.random.default_rng(0), 20000)
    assert np.abs(draws).max() <= 0.2
    assert noise.std == pytest.approx(truncnorm(-2, 2, scale=0.1).std(), rel=1e-12)
    assert abs(draws.std() - noise.std) < 3e-3


def test_residual_noise_is_the_convolution_with_the_truncated_residual():
    base = TruncatedGaussianNoise()
    w = ResidualNoise(base, 0.08)
    assert w.support == pytest.approx(0.2 + 3 * 0.08, abs=5e-4)
    rng = np.random.default_rng(1)
    r = truncnorm(-3, 3, scale=0.08).rvs(400_000, random_state=rng)
    draws = base.sample(rng, 400_000) + r
    t = np.linspace(-0.5, 0.5, 41)
    emp = (draws[:, None] <= t[None, :]).mean(axis=0)
    np.testing.assert_allclose(w.cdf(t), emp, atol=3e-3)
    # exactly 0 and 1 outside the support, symmetric, monotone
    assert w.cdf(np.array([-w.support - 1e-9]))[0] == 0.0
    assert w.cdf(np.array([w.support + 1e-9]))[0] == 1.0
    np.testing.assert_allclose(w.cdf(t) + w.cdf(-t), 1.0, atol=1e-12)
    assert (np.diff(w.cdf(np.linspace(-1, 1, 2001))) >= 0).all()
    np.testing.assert_allclose(ResidualNoise(base, 0.0).cdf(t), base.cdf(t), atol=1e-6)
    with pytest.raises(IntervalError, match="residual std"):
        ResidualNoise(base, -0.1)


def test_confidence_beta_is_the_union_bound_quantile():
    assert confidence_beta(0.05, 1) == pytest.approx(1.959964, abs=1e-6)
    assert confidence_beta(0.01, 100) > confidence_beta(0.01, 10)
    with pytest.raises(IntervalError, match="delta"):
        confidence_beta(1.5, 3)


def test_beta_is_set_by_the_run_horizon():
    b = cell_error_bounds(LandingErrorGP(), GRID, samples_per_axis=3, delta=0.01, horizon=100)
    # two axes, two-sided, one departure per hop: delta / (4 horizon) per tail
    assert b.beta == pytest.approx(norm.isf(0.01 / 400))
    assert b.lower.shape == b.upper.shape == (NX * NY, NA, 2)
    assert b.residual_std.shape == (NA, 2)
    with pytest.raises(IntervalError, match="horizon"):
        cell_error_bounds(LandingErrorGP(), GRID, **{**BOUNDS, "horizon": 0})


def test_rows_cover_exactly_the_enabled_actions():
    ti = transition_intervals(_bounds(-0.1, 0.1), GRID)
    has = np.zeros((NX * NY, NA), dtype=bool)
    has[ti.state, ti.action] = True
    np.testing.assert_array_equal(has, GRID.enabled[: NX * NY])
    assert has[0].tolist() == [True, True, True, True, False, False, False, False]
    model = GRID.imdp_from_intervals(*ti.coo())
    assert model.n_states == NX * NY + 1


def test_exact_error_gives_exact_probabilities():
    noise = TruncatedGaussianNoise()
    b = _bounds(0.45, 0.45)
    b.lower[..., 1] = b.upper[..., 1] = 0.0
    ti = transition_intervals(b, GRID, noise)
    np.testing.assert_allclose(ti.lower, ti.upper, atol=1e-6)
    lo, _hi, enabled = _row_sums(ti)
    np.testing.assert_allclose(lo[enabled], 1.0, atol=1e-5)
    # cell (7, 7), E1: target centre (8.5, 7.5), shifted by 0.45 -> x in [8.75, 9.15]
    sel = (ti.state == 7 * NY + 7) & (ti.action == 2)
    got = dict(zip(ti.successor[sel].tolist(), ti.lower[sel].tolist(), strict=True))
    p9 = 1.0 - noise.cdf(np.array(9.0 - 8.95))
    assert got[9 * NY + 7] == pytest.approx(float(p9), abs=1e-6)
    assert got[8 * NY + 7] == pytest.approx(float(1.0 - p9), abs=1e-6)


def test_bounds_are_used_per_action_and_the_residual_widens_the_reach():
    b = _bounds(0.0, 0.0)
    b.lower[:, 3, 0] = b.upper[:, 3, 0] = -0.4  # E2 falls 0.4 m short
    b.residual_std[7, 0] = 0.12  # W2 varies more from hop to hop: support 0.56 m
    ti = transition_intervals(b, GRID)
    c = 7 * NY + 7

    def succ(a):
        sel = (ti.state == c) & (ti.action == a)
        return {int(s): (lo, hi) for s, lo, hi in zip(ti.successor[sel], ti.lower[sel],
                                                     ti.upper[sel], strict=True)}  # fmt: skip

    e2, e1, w2 = succ(3), succ(2), succ(7)
    assert set(e2) == {8 * NY + 7, 9 * NY + 7}  # short of the target, one cell back possible
    assert set(e1) == {8 * NY + 7}  # exactly on target: nu alone cannot leave the cell
    assert set(w2) == {4 * NY + 7, 5 * NY + 7, 6 * NY + 7}  # the residual reaches both sides
    assert w2[5 * NY + 7][0] < 1.0


def test_rows_bracket_one_and_out_is_handled():
    rng = np.random.default_rng(3)
    lo = rng.uniform(-0.8, 0.2, size=(NX * NY, NA, 2))
    hi = lo + rng.uniform(0.0, 0.8, size=lo.shape)
    res = rng.uniform(0.0, 0.12, size=(NA, 2))
    ti = transition_intervals(CellErrorBounds(lo, hi, res, 0.0, 0.01, 1), GRID)
    assert (ti.lower <= ti.upper).all() and (ti.lower >= 0).all() and (ti.upper <= 1).all()
    slo, shi, enabled = _row_sums(ti)
    assert (slo[enabled] <= 1.0 + 1e-12).all() and (shi[enabled] >= 1.0 - 1e-12).all()
    out = ti.successor == NX * NY
    # E2 from the column next to the east border can leave the world; from the middle it cannot
    east = out & (ti.state // NY == NX - 3) & (ti.action == 3)
    assert east.any()
    assert not (out & (ti.state == 7 * NY + 7) & (ti.action == 0)).any()
    assert ti.num_states == NX * NY + 1


def test_axis_intervals_are_the_factors_of_the_product():
    rng = np.random.default_rng(8)
    lo = rng.uniform(-0.5, 0.1, size=(NX * NY, NA, 2))
    b = CellErrorBounds(lo, lo + 0.3, np.full((NA, 2), 0.05), 0.0, 0.01, 1)
    ax = axis_intervals(b, GRID)
    ti = transition_intervals(b, GRID)
    inside = ti.successor < NX * NY
    row = np.flatnonzero((ax.state == ti.state[inside][0]) & (ax.action == ti.action[inside][0]))
    assert row.size == 1
    i, j = divmod(int(ti.successor[inside][0]), NY)
    assert ti.lower[inside][0] == pytest.approx(ax.x_lower[row[0], i] * ax.y_lower[row[0], j])
    assert ti.upper[inside][0] == pytest.approx(ax.x_upper[row[0], i] * ax.y_upper[row[0], j])
    assert ax.inside_x.shape == (len(ax.state), 2)
    # with the mass that leaves the world along x, each axis's bounds bracket one
    leave_lo, leave_hi = 1.0 - ax.inside_x[:, 1], 1.0 - ax.inside_x[:, 0]
    assert (ax.x_lower.sum(1) + leave_lo <= 1 + 1e-12).all()
    assert (ax.x_upper.sum(1) + leave_hi >= 1 - 1e-12).all()


def test_axis_bins_add_the_outside_bin_and_bracket_one():
    rng = np.random.default_rng(9)
    lo = rng.uniform(-0.6, 0.2, size=(NX * NY, NA, 2))
    b = CellErrorBounds(lo, lo + 0.4, np.full((NA, 2), 0.07), 0.0, 0.01, 1)
    ax = axis_intervals(b, GRID)
    for d, (p_lo, p_hi, inside) in enumerate(
        ((ax.x_lower, ax.x_upper, ax.inside_x), (ax.y_lower, ax.y_upper, ax.inside_y))
    ):
        b_lo, b_hi = ax.bins(d)
        assert b_lo.shape == (len(ax.state), p_lo.shape[1] + 1)
        assert np.array_equal(b_lo[:, :-1], p_lo) and np.array_equal(b_hi[:, :-1], p_hi)
        assert b_lo[:, -1] == pytest.approx(1 - inside[:, 1], abs=1e-15)
        assert b_hi[:, -1] == pytest.approx(1 - inside[:, 0], abs=1e-15)
        assert (b_lo.sum(1) <= 1 + 1e-12).all() and (b_hi.sum(1) >= 1 - 1e-12).all()
        assert (b_hi[:, -1] > 0).any()  # hops that can leave the world
    with pytest.raises(IntervalError, match="axis"):
        ax.bins(2)


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
        assert p.min() >= lo - 1e-5 and p.max() <= hi + 1e-5
        assert p.min() == pytest.approx(lo, abs=1e-3) and p.max() == pytest.approx(hi, abs=1e-3)


def test_bad_bounds_are_rejected():
    with pytest.raises(IntervalError, match="shape"):
        transition_intervals(_bounds(0, 0, 3, 3), GRID)
    b = _bounds(0.0, 0.1)
    b.lower[17, 2, 1] = 0.5
    with pytest.raises(IntervalError, match="cell 17, action 2"):
        transition_intervals(b, GRID)
    b = _bounds(0.0, 0.1)
    b.residual_std[1, 0] = -1.0
    with pytest.raises(IntervalError, match="residual_std"):
        transition_intervals(b, GRID)
    with pytest.raises(IntervalError, match="sigma"):
        TruncatedGaussianNoise(sigma=0.0)


class _Predictor:
    """A stand-in landing-error model whose outputs a test can break."""

    n_actions = NA

    def __init__(self, mean_shape=None, std_value=0.1, residual=None, dstd=0.0):
        self.mean_shape, self.std_value, self.residual, self.dstd = (
            mean_shape, std_value, residual, dstd,
        )  # fmt: skip

    def predict(self, points):
        m = len(points)
        mean = np.zeros(self.mean_shape or (m, NA, 2))
        std = np.full((m, NA, 2), self.std_value)
        return mean, std

    def variation(self, points, half_width):
        return np.zeros((len(points), NA, 2)), np.full((NA, 2), self.dstd)

    def residual_std(self):
        return np.zeros((NA, 2)) if self.residual is None else self.residual


@pytest.mark.parametrize(
    ("predictor", "match"),
    [
        (_Predictor(mean_shape=(5, 2)), r"mean has shape \(5, 2\), expected \(2025, 8, 2\)"),
        (_Predictor(std_value=-0.01), r"std must be finite and >= 0: -0.01 at \(0, 0, 0\)"),
        (_Predictor(std_value=np.nan), "std must be finite"),
        (_Predictor(residual=np.zeros((8, 3))), r"residual std has shape \(8, 3\)"),
        (_Predictor(dstd=-1.0), "std variation must be finite and >= 0"),
    ],
)
def test_interval_step_rejects_a_broken_predictor(predictor, match):
    with pytest.raises(IntervalError, match=match):
        cell_error_bounds(predictor, GRID, **BOUNDS)


def test_prior_intervals_are_wide():
    ti = transition_intervals(cell_error_bounds(LandingErrorGP(), GRID, **BOUNDS), GRID)
    _, shi, enabled = _row_sums(ti)
    assert shi[enabled].min() > 2.0


def test_error_bounds_contain_the_true_field(fitted_gp):
    bounds = cell_error_bounds(fitted_gp, GRID, **{**BOUNDS, "samples_per_axis": 4})
    dense = cell_sample_points(GRID, 9)  # other points than the bounds' samples
    inside = []
    for a in range(NA):
        truth = action_error(dense.reshape(-1, 2), np.full(dense.shape[0] * 81, a))
        truth = truth.reshape(dense.shape)
        inside.append(
            (truth >= bounds.lower[:, None, a, :]) & (truth <= bounds.upper[:, None, a, :])
        )
    assert np.all(inside)
    width = bounds.upper - bounds.lower
    assert (
        width.mean() < 0.7 * (cell_error_bounds(LandingErrorGP(), GRID, **BOUNDS).upper * 2).mean()
    )


def test_empirical_frequencies_lie_in_the_intervals(fitted_gp):
    rng = np.random.default_rng(12)
    noise = TruncatedGaussianNoise()
    bounds = cell_error_bounds(fitted_gp, GRID, **BOUNDS)
    ti = transition_intervals(bounds, GRID, noise)
    state, action = np.nonzero(GRID.enabled[: NX * NY])
    pick = rng.choice(len(state), size=40, replace=False)
    n = 300
    counts = np.zeros((pick.size, NX * NY + 1), dtype=np.int64)
    for row, k in enumerate(pick):
        start = (np.array(divmod(int(state[k]), NY)) + rng.uniform(0, 1, (n, 2))) * CELL
        target = GRID.target_centres[state[k], action[k]]
        # the data's noise: N(0, 0.1^2) per axis, which the model splits into nu + residual
        err = action_error(start, np.full(n, action[k])) + rng.normal(0.0, 0.1, (n, 2))
        counts[row] = np.bincount(GRID.locate(target + err), minlength=NX * NY + 1)
    result = audit_counts(ti, state[pick], action[pick], counts)
    assert result.fraction >= 0.99
    assert result.num_triples >= 100  # 40 pairs, several successors each


def test_fitted_model_settings_shape_the_prior():
    wide = cell_error_bounds(LandingErrorGP(GPConfig(bias_std=0.5)), GRID, **BOUNDS)
    narrow = cell_error_bounds(LandingErrorGP(GPConfig(bias_std=0.05)), GRID, **BOUNDS)
    assert (wide.upper > narrow.upper).all() and (wide.lower < narrow.lower).all()
