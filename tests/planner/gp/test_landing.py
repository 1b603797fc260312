from __future__ import annotations

import numpy as np
import pytest

from planner.errors import GPDataError
from planner.gp import ErrorPredictor, FitSettings, LandingErrorGP
from tests.planner.conftest import smooth_error


def test_prior_without_data_is_wide_and_centred():
    gp = LandingErrorGP(FitSettings(prior_std=0.4))
    assert isinstance(gp, ErrorPredictor)
    mean, std = gp.predict(np.array([[0.5, 0.5], [7.0, 3.0]]))
    np.testing.assert_allclose(mean, 0.0)
    np.testing.assert_allclose(std, 0.4, rtol=1e-6)
    np.testing.assert_allclose(gp.variation(np.array([0.1, 0.1]))[0], 0.0)


def test_fit_learns_the_error_field(fitted_gp):
    grid = np.random.default_rng(11).uniform(1.0, 14.0, size=(500, 2))
    mean, std = fitted_gp.predict(grid)
    assert np.abs(mean - smooth_error(grid)).mean() < 0.05
    assert std.max() < 0.15
    assert fitted_gp.num_data == 600
    assert fitted_gp.model.inducing_points.shape == (2, 50, 2)


def test_same_seed_same_fit(synthetic_data):
    pts = np.array([[1.0, 2.0], [10.0, 12.5]])
    out = []
    for _ in range(2):
        gp = LandingErrorGP(FitSettings(steps=5, cold_steps=5), seed=4)
        gp.fit(*synthetic_data)
        out.append(gp.predict(pts))
    np.testing.assert_array_equal(out[0][0], out[1][0])
    np.testing.assert_array_equal(out[0][1], out[1][1])


def test_refit_is_warm_started_and_reset_forgets(synthetic_data):
    gp = LandingErrorGP(FitSettings(steps=3, cold_steps=8))
    calls: list[int] = []
    first = gp.fit(*synthetic_data, on_step=lambda step, loss: calls.append(step))
    second = gp.fit(*synthetic_data, on_step=lambda step, loss: calls.append(step))
    assert calls == [*range(8), *range(3)]  # cold fit, then a warm refit
    assert not np.allclose(first.lengthscale, FitSettings().lengthscale)
    gp.settings = FitSettings(steps=0)
    third = gp.fit(*synthetic_data)
    np.testing.assert_allclose(third.lengthscale, second.lengthscale)
    np.testing.assert_allclose(third.outputscale, second.outputscale)
    gp.reset()
    assert gp.num_data == 0
    np.testing.assert_allclose(gp.predict(np.zeros((1, 2)))[1], FitSettings().prior_std)


def test_warm_up_leaves_the_prior():
    gp = LandingErrorGP()
    gp.warm_up()
    assert gp.num_data == 0
    np.testing.assert_allclose(gp.predict(np.ones((1, 2)))[1], FitSettings().prior_std)


def test_few_points_use_them_as_inducing_points():
    gp = LandingErrorGP()
    pos = np.array([[1.0, 1.0], [2.0, 1.5], [1.0, 1.0]])
    report = gp.fit(pos, np.full((3, 2), 0.1))
    assert report.num_inducing == 2
    assert np.isfinite(gp.predict(pos)[0]).all()


def test_empty_data_returns_to_prior():
    gp = LandingErrorGP()
    gp.fit(np.zeros((0, 2)), np.zeros((0, 2)))
    np.testing.assert_allclose(gp.predict(np.ones((1, 2)))[1], FitSettings().prior_std)


@pytest.mark.parametrize(
    ("pos", "err", "match"),
    [
        (np.zeros((3, 3)), np.zeros((3, 3)), r"positions must have shape \(N, 2\)"),
        (np.zeros((3, 2)), np.zeros((2, 2)), "errors must have shape"),
        (np.zeros((3, 2)), np.array([[0, 0], [0, np.nan], [0, 0]]), "errors .* row 1"),
    ],
)
def test_bad_data_is_rejected(pos, err, match):
    with pytest.raises(GPDataError, match=match):
        LandingErrorGP().fit(pos, err)


def test_bad_settings_are_rejected():
    with pytest.raises(GPDataError, match="prior_std"):
        FitSettings(prior_std=-1.0)
