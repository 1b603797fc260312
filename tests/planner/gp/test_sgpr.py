from __future__ import annotations

import gpytorch
import numpy as np
import pytest
import torch

from planner.errors import GPModelError
from planner.gp import SparseGP, rbf_sparse_gp
from tests.planner.conftest import smooth_error


@pytest.fixture(scope="module")
def fitted_gp():
    """A sparse GP (50 inducing points on a grid) conditioned on noisy samples of a field."""
    rng = np.random.default_rng(7)
    pos = rng.uniform(0.0, 15.0, size=(600, 2))
    err = smooth_error(pos) + rng.normal(0.0, 0.1, size=pos.shape)
    g = np.linspace(0.5, 14.5, 7)
    z = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)[:50]
    model = rbf_sparse_gp(z, outputscale=0.3**2)
    x = torch.as_tensor(pos)
    return model.posterior(x, torch.as_tensor(err.T.copy())), model


def _exact_setup(n: int = 25):
    rng = np.random.default_rng(1)
    x = torch.as_tensor(rng.uniform(0.0, 4.0, size=(n, 2)))
    y = torch.as_tensor(rng.normal(0.0, 0.3, size=(2, n)))
    model = rbf_sparse_gp(x.numpy(), lengthscale=1.5, outputscale=0.2, noise=0.02, jitter=1e-10)
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
    post, model = fitted_gp
    _mean, std = post.predict(np.array([[200.0, 200.0]]))
    prior_std = np.sqrt(model.covar_module.outputscale.detach().numpy())
    np.testing.assert_allclose(std[0], prior_std, rtol=1e-6)


def test_variation_bounds_hold_on_random_pairs(fitted_gp):
    post, _ = fitted_gp
    rng = np.random.default_rng(5)
    h = np.array([0.1, 0.1])
    a = rng.uniform(0.0, 15.0, size=(4000, 2))
    b = a + rng.uniform(-1.0, 1.0, size=a.shape) * h
    dmean, dstd = post.variation(h)
    ma, sa = post.predict(a)
    mb, sb = post.predict(b)
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
