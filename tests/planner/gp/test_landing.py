from __future__ import annotations

import numpy as np
import pytest

from planner.errors import GPDataError
from planner.gp import ErrorPredictor, GPConfig, LandingErrorGP, TruncatedGaussianNoise
from tests.planner.conftest import action_error

SETTINGS = GPConfig(bias_std=0.3, field_std=0.15)


def _brute_force(settings: GPConfig, gp: LandingErrorGP, pos, err, act, pts, d: int):
    """The exact GP posterior of axis d at (pts, every action), from the full kernel matrix of
    the model as the module docstring writes it: e(x, a) = c_a + s_a u_a (o + f(x)) +
    s_a (1 - u_a) o_a + g_a(x)."""
    s = settings
    u = np.asarray(s.coupled, dtype=float)[:, d]
    sc = np.asarray(s.scale, dtype=float)[:, d]
    rho = s.field_correlation

    def cov(x1, a1, x2, a2):
        k = np.exp(-0.5 * ((x1[:, None, :] - x2[None, :, :]) ** 2).sum(-1) / s.lengthscale**2)
        same = a1[:, None] == a2[None, :]
        w1, w2 = (sc * u)[a1], (sc * u)[a2]
        shared = np.outer(w1, w2) * (rho * s.field_std**2 * k + s.offset_std**2)
        own_field = (sc[a1] ** 2 * s.field_std**2 * (1.0 - rho * u[a1]))[:, None] * k
        own_offset = (sc[a1] ** 2 * s.offset_std**2 * (1.0 - u[a1]))[:, None]
        return shared + (own_field + own_offset + s.bias_std**2) * same

    noise = gp.residual_std()[act, d] ** 2 + s.noise.std**2
    kxx = cov(pos, act, pos, act) + np.diag(noise)
    y = err[:, d] - s.bias[act, d]
    means, stds = [], []
    for a in range(s.n_actions):
        qa = np.full(len(pts), a)
        ks = cov(pts, qa, pos, act)
        prior = cov(pts[:1], qa[:1], pts[:1], qa[:1])[0, 0]
        means.append(s.bias[a, d] + ks @ np.linalg.solve(kxx, y))
        var = prior - (ks * np.linalg.solve(kxx, ks.T).T).sum(1)
        stds.append(np.sqrt(var))
    return np.stack(means, 1), np.stack(stds, 1)


def test_prior_without_data_is_wide_and_centred_on_the_bias():
    bias = np.zeros((8, 2))
    bias[3, 0] = -0.2
    gp = LandingErrorGP(GPConfig(bias_mean=bias, bias_std=0.4, field_std=0.3))
    assert isinstance(gp, ErrorPredictor)
    mean, std = gp.predict(np.array([[0.5, 0.5], [7.0, 3.0]]))
    assert mean.shape == std.shape == (2, 8, 2)
    np.testing.assert_allclose(mean, np.broadcast_to(bias, mean.shape))
    np.testing.assert_allclose(std, 0.5, rtol=1e-12)
    dmean, dstd = gp.variation(np.array([[0.5, 0.5]]), np.array([0.1, 0.1]))
    np.testing.assert_allclose(dmean, 0.0)
    assert dmean.shape == (1, 8, 2) and dstd.shape == (8, 2) and (dstd > 0).all()
    np.testing.assert_allclose(gp.residual_std(), 0.1)


@pytest.mark.parametrize("offset_std,scaled", [(0.0, False), (0.25, False), (0.25, True)])
def test_posterior_is_the_exact_gp_posterior(synthetic_data, offset_std, scaled):
    pos, err, act = (a[:120] for a in synthetic_data)
    scale = np.linspace(0.3, 1.0, 16).reshape(8, 2) if scaled else 1.0
    settings = GPConfig(bias_std=0.3, field_std=0.15, offset_std=offset_std, scale=scale)
    gp = LandingErrorGP(settings)
    gp.fit(pos, err, act)
    pts = np.random.default_rng(2).uniform(-2.0, 17.0, size=(9, 2))
    mean, std = gp.predict(pts)
    for d in range(2):
        m_ref, s_ref = _brute_force(settings, gp, pos, err, act, pts, d)
        np.testing.assert_allclose(mean[:, :, d], m_ref, atol=1e-9)
        np.testing.assert_allclose(std[:, :, d], s_ref, atol=1e-5)  # single precision


def test_a_uniform_offset_is_learned_from_hops_far_away():
    # hops only in x < 4; the error is the controller's bias plus a uniform 0.3 m along x
    settings = GPConfig(field_std=0.1, offset_std=0.3, bias_std=0.05, residual_std=0.02)
    rng = np.random.default_rng(4)
    pos = rng.uniform([0.0, 0.0], [4.0, 15.0], size=(150, 2))
    act = rng.integers(0, 8, size=150)
    u = np.asarray(settings.coupled, dtype=float)
    err = np.column_stack([0.3 * np.ones(150), np.zeros(150)]) * u[act]
    err += rng.normal(0.0, 0.1, size=err.shape)
    gp = LandingErrorGP(settings)
    _, prior_std = gp.predict(np.array([[13.0, 7.0]]))
    gp.fit(pos, err, act)
    mean, std = gp.predict(np.array([[13.0, 7.0]]))  # 9 m (4.5 length scales) from any hop
    coupled_x = u[:, 0] == 1
    np.testing.assert_allclose(mean[0, coupled_x, 0], 0.3, atol=0.1)
    # what is left far away is the local field's prior (0.1) and the little still unknown
    assert (std[0, coupled_x, 0] < 0.14).all() and (prior_std[0, :, 0] > 0.3).all()


def test_direction_aware_model_recovers_a_field_that_differs_per_action():
    rng = np.random.default_rng(0)
    n = 1200
    pos = rng.uniform(0.0, 15.0, size=(n, 2))
    act = rng.integers(0, 8, size=n)
    err = action_error(pos, act) + rng.normal(0.0, 0.1, size=pos.shape)
    settings = GPConfig(bias_std=0.3, field_std=0.15, max_data=n)
    gp = LandingErrorGP(settings)
    gp.fit(pos, err, act)
    g = np.linspace(1.0, 14.0, 27)
    dense = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    mean, std = gp.predict(dense)
    truth = np.stack([action_error(dense, np.full(len(dense), a)) for a in range(8)], axis=1)
    # each action's posterior mean is within 0.05 m of its own field (RMS over the grid,
    # per axis), and nowhere further than 4 posterior stds
    rms = np.sqrt(((mean - truth) ** 2).mean(axis=0))
    assert (rms < 0.05).all(), rms
    assert (np.abs(mean - truth) < 4.0 * std).all()
    # the actions really differ: one field for all actions (the old position-only model)
    # is off by far more
    pooled = LandingErrorGP(settings)
    pooled.fit(pos, err, np.zeros(n, dtype=int))
    one = pooled.predict(dense)[0][:, :1, :]
    assert np.sqrt(((one - truth) ** 2).mean(axis=0)).max() > 0.15


def test_posterior_std_only_shrinks_as_data_are_added(synthetic_data):
    pos, err, act = synthetic_data
    # residual variances held at the prior guess (huge pseudo-count): the kernel is fixed
    gp = LandingErrorGP(GPConfig(residual_count=1e12))
    pts = np.random.default_rng(3).uniform(0.0, 15.0, size=(200, 2))
    last = gp.predict(pts)[1]
    for n in (50, 100, 200, 400, 600):
        gp.fit(pos[:n], err[:n], act[:n])
        std = gp.predict(pts)[1]
        assert (std <= last + 1e-12).all()
        last = std
    assert last.max() < SETTINGS.prior_std()


def test_variation_bounds_hold_on_random_pairs(fitted_gp):
    rng = np.random.default_rng(5)
    h = np.array([0.1, 0.1])
    a = rng.uniform(0.0, 15.0, size=(3000, 2))
    b = a + rng.uniform(-1.0, 1.0, size=a.shape) * h
    dmean, dstd = fitted_gp.variation(a, h)
    ma, sa = fitted_gp.predict(a)
    mb, sb = fitted_gp.predict(b)
    assert (np.abs(ma - mb) <= dmean + 1e-9).all()
    assert (np.abs(sa - sb) <= dstd + 1e-6).all()
    # and the bounds are not vacuous: the mean's within a factor 3 of the largest change
    # seen at its point's corners, on average
    signs = ((1, 1), (1, -1), (-1, 1), (-1, -1))
    corners = [fitted_gp.predict(a + np.array(c) * h)[0] for c in signs]
    seen = np.max([np.abs(c - ma) for c in corners], axis=0)
    assert dmean.mean() < 3.0 * seen.mean()


def test_residual_std_is_estimated_per_action():
    rng = np.random.default_rng(4)
    n = 1600
    pos = rng.uniform(0.0, 15.0, size=(n, 2))
    act = rng.integers(0, 8, size=n)
    true_res = np.where(np.arange(8) % 2 == 1, 0.12, 0.03)[:, None] * np.ones((1, 2))
    nu = TruncatedGaussianNoise().sample(rng, (n, 2))
    err = action_error(pos, act) + nu + rng.normal(0.0, 1.0, size=(n, 2)) * true_res[act]
    gp = LandingErrorGP(SETTINGS)
    report = gp.fit(pos, err, act)
    est = gp.residual_std()
    np.testing.assert_array_equal(report.residual_std, est)
    np.testing.assert_array_equal(report.per_action, np.bincount(act, minlength=8))
    long = np.arange(8) % 2 == 1
    assert (np.abs(est[long] - 0.12) < 0.03).all(), est
    assert (est[~long] < 0.07).all(), est


def test_old_data_beyond_max_data_are_dropped(synthetic_data):
    pos, err, act = synthetic_data
    gp = LandingErrorGP(GPConfig(max_data=100))
    assert gp.fit(pos, err, act).num_data == 100
    ref = LandingErrorGP(GPConfig(max_data=100))
    ref.fit(pos[-100:], err[-100:], act[-100:])
    pts = np.array([[3.0, 4.0], [12.0, 1.0]])
    np.testing.assert_allclose(gp.predict(pts)[0], ref.predict(pts)[0])


def test_empty_data_returns_to_prior(synthetic_data):
    gp = LandingErrorGP()
    gp.fit(*synthetic_data)
    gp.fit(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, dtype=int))
    assert gp.num_data == 0
    np.testing.assert_allclose(gp.predict(np.ones((1, 2)))[1], GPConfig().prior_std())


@pytest.mark.parametrize(
    ("pos", "err", "act", "match"),
    [
        (np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(3, int), r"positions must have shape"),
        (np.zeros((3, 2)), np.zeros((2, 2)), np.zeros(3, int), "errors must have shape"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(2, int), r"actions must have shape \(3,\)"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.array([0, 8, 1]), "row 1"),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.array([0.0, 1.5, 1]), "integers"),
        (np.zeros((3, 2)), np.array([[0, 0], [0, np.nan], [0, 0]]), np.zeros(3, int), "row 1"),
    ],
)
def test_bad_data_is_rejected(pos, err, act, match):
    with pytest.raises(GPDataError, match=match):
        LandingErrorGP().fit(pos, err, act)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"lengthscale": 0.0}, "lengthscale"),
        ({"bias_std": -1.0}, "bias_std"),
        ({"field_correlation": 1.5}, "field_correlation"),
        ({"residual_std": np.ones((3, 2))}, "residual_std"),
        ({"bias_mean": np.full((8, 2), np.nan)}, "bias_mean"),
        ({"coupled": np.ones((8, 3), bool)}, "coupled"),
        ({"scale": 0.0}, "scale"),
        ({"scale": np.full((8, 2), 1.5)}, "scale"),
        ({"offset_std": -0.1}, "offset_std"),
    ],
)
def test_bad_settings_are_rejected(kwargs, match):
    with pytest.raises(GPDataError, match=match):
        GPConfig(**kwargs)
