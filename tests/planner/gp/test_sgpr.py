from __future__ import annotations

import gpytorch
import numpy as np
import pytest
import torch

from planner.errors import GPModelError
from planner.gp import LandingErrorGP, SparseGP


def _exact_setup(n: int = 25):
    gp = LandingErrorGP()
    rng = np.random.default_rng(1)
    x = torch.as_tensor(rng.uniform(0.0, 4.0, size=(n, 2)))
    y = torch.as_tensor(rng.normal(0.0, 0.3, size=(2, n)))
    model = gp.model
    model.inducing_points = torch.nn.Parameter(x.unsqueeze(0).expand(2, n, 2).clone())
    model.jitter = 1e-10
    xb = x.unsqueeze(0).expand(2, n, 2)
    noise = model.likelihood.noise.reshape(2, 1, 1)
    kxx = model.covar_module(xb).to_dense() + noise * torch.eye(n, dtype=x.dtype)
    mu = model.mean_module(xb)
    return model, x, y, xb, kxx, mu


def test_bound_is_exact_marginal_likelihood_when_inducing_points_are_the_data():
    model, x, y, _, kxx, mu = _exact_setup()
    exact = torch.distributions.MultivariateNormal(mu, kxx).log_prob(y)
    torch.testing.assert_close(model.elbo(x, y), exact, rtol=1e-6, atol=1e-6)


def test_posterior_is_exact_gp_posterior_when_inducing_points_are_the_data():
    model, x, y, xb, kxx, mu = _exact_setup()
    xs = torch.as_tensor(np.random.default_rng(2).uniform(-2.0, 6.0, size=(7, 2)))
    mean, std = model.posterior(x, y).predict(xs.numpy())
    ks = model.covar_module(xs.unsqueeze(0).expand(2, 7, 2), xb).to_dense()
    with torch.no_grad():
        exp_mean = mu[:, :1] + (ks @ torch.linalg.solve(kxx, (y - mu).unsqueeze(-1))).squeeze(-1)
        prior = model.covar_module.outputscale.reshape(2, 1)
        exp_var = prior - torch.einsum("bij,bji->bi", ks, torch.linalg.solve(kxx, ks.mT))
    np.testing.assert_allclose(mean, exp_mean.T.numpy(), atol=1e-5)
    np.testing.assert_allclose(std**2, exp_var.T.numpy(), atol=1e-6)


def test_posterior_reverts_to_prior_far_from_data(fitted_gp):
    _mean, std = fitted_gp.predict(np.array([[200.0, 200.0]]))
    prior_std = np.sqrt(fitted_gp.model.covar_module.outputscale.detach().numpy())
    np.testing.assert_allclose(std[0], prior_std, rtol=1e-6)


def test_variation_bounds_hold_on_random_pairs(fitted_gp):
    rng = np.random.default_rng(5)
    h = np.array([0.1, 0.1])
    a = rng.uniform(0.0, 15.0, size=(4000, 2))
    b = a + rng.uniform(-1.0, 1.0, size=a.shape) * h
    dmean, dstd = fitted_gp.variation(h)
    ma, sa = fitted_gp.predict(a)
    mb, sb = fitted_gp.predict(b)
    assert (np.abs(ma - mb) <= dmean + 1e-12).all()
    assert (np.abs(sa - sb) <= dstd + 1e-12).all()
    # and the bound is not vacuous: within a factor 20 of the largest observed change
    assert (dmean < 20 * np.abs(ma - mb).max(axis=0)).all()


def test_unsupported_kernel_is_rejected():
    batch = torch.Size([2])
    with pytest.raises(GPModelError, match="ScaleKernel"):
        SparseGP(
            gpytorch.means.ConstantMean(batch_shape=batch),
            gpytorch.kernels.LinearKernel(batch_shape=batch),
            gpytorch.likelihoods.GaussianLikelihood(batch_shape=batch),
            torch.zeros(2, 3, 2),
        )
