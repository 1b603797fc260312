"""Sparse GP regression (Titsias 2009), batched over independent outputs, in gpytorch's style.

A :class:`SparseGP` composes a gpytorch mean, kernel and Gaussian likelihood, each with
``batch_shape = (B,)`` (one batch member per output: here B = 2, the x and y landing errors),
plus ``m`` inducing points per output. Training maximises Titsias' collapsed evidence lower
bound, per output ``b`` (kernel ``K``, noise variance ``s2``, ``Q = K_xz K_zz^-1 K_zx``)::

    F_b = log N(y_b | mean_b, Q_xx + s2 I) - tr(K_xx - Q_xx) / (2 s2)

and :meth:`SparseGP.posterior` returns the optimal variational posterior (the "DTC" predictive
with the exact prior variance, which reverts to the prior away from the data)::

    mean(x) = c + k_xz w,              w = Sigma K_zx (y - c) / s2
    var(x)  = k(x, x) - k_xz (K_zz^-1 - Sigma) k_zx,     Sigma = (K_zz + K_zx K_xz / s2)^-1

All inputs and outputs are float64 torch tensors; positions and errors are in metres.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import gpytorch
import numpy as np
import torch
from torch import Tensor

from planner.errors import GPModelError

_STATIONARY_MONOTONE = (gpytorch.kernels.RBFKernel, gpytorch.kernels.MaternKernel)


def _check_kernel(covar_module: gpytorch.kernels.Kernel) -> None:
    """The cell bounds need ``k(0) - k(d)`` to grow with every ``|d_i|`` (see ``variation``)."""
    if not isinstance(covar_module, gpytorch.kernels.ScaleKernel) or not isinstance(
        covar_module.base_kernel, _STATIONARY_MONOTONE
    ):
        raise GPModelError(
            "covar_module must be ScaleKernel(RBFKernel | MaternKernel), got "
            f"{type(covar_module).__name__}"
        )


def rbf_sparse_gp(
    inducing_points: np.ndarray,
    *,
    num_outputs: int = 2,
    lengthscale: float = 2.0,
    outputscale: float = 0.15**2,
    noise: float = 0.1**2,
    jitter: float = 1e-6,
) -> SparseGP:
    """A :class:`SparseGP` with a constant mean (0), an RBF kernel of the given (fixed
    initial) hyperparameters and the ``(m, d)`` inducing points shared by all outputs, in
    float64 (the paper's model: 50 inducing points per GP)."""
    z = torch.as_tensor(np.asarray(inducing_points, dtype=np.float64))
    if z.dim() != 2:
        raise GPModelError(f"inducing_points must have shape (m, d), got {tuple(z.shape)}")
    batch = torch.Size([int(num_outputs)])
    base = gpytorch.kernels.RBFKernel(ard_num_dims=z.shape[1], batch_shape=batch)
    kernel = gpytorch.kernels.ScaleKernel(base, batch_shape=batch)
    likelihood = gpytorch.likelihoods.GaussianLikelihood(batch_shape=batch)
    base.lengthscale = torch.full((int(num_outputs), 1, z.shape[1]), float(lengthscale))
    kernel.outputscale = torch.full((int(num_outputs),), float(outputscale))
    likelihood.noise = torch.full((int(num_outputs), 1), float(noise))
    zb = z.unsqueeze(0).expand(int(num_outputs), *z.shape).clone()
    mean = gpytorch.means.ConstantMean(batch_shape=batch)
    return SparseGP(mean, kernel, likelihood, zb, jitter=jitter).to(torch.float64)


class SparseGP(gpytorch.Module):
    """Collapsed sparse GP over ``B`` independent outputs sharing the input locations.

    Args:
        mean_module: gpytorch mean with ``batch_shape (B,)``.
        covar_module: ``ScaleKernel`` over an ``RBFKernel`` or ``MaternKernel`` with
            ``batch_shape (B,)``; stationary, so ``k(x, x)`` is its outputscale.
        likelihood: ``GaussianLikelihood`` with ``batch_shape (B,)``.
        inducing_points: ``(B, m, d)`` initial inducing locations (learned).
        jitter: added to the diagonal of ``K_zz`` before factorising.
    """

    def __init__(
        self,
        mean_module: gpytorch.means.Mean,
        covar_module: gpytorch.kernels.Kernel,
        likelihood: gpytorch.likelihoods.GaussianLikelihood,
        inducing_points: Tensor,
        *,
        jitter: float = 1e-6,
    ) -> None:
        super().__init__()
        _check_kernel(covar_module)
        if inducing_points.dim() != 3:
            raise GPModelError(
                f"inducing_points must have shape (B, m, d), got {tuple(inducing_points.shape)}"
            )
        self.mean_module = mean_module
        self.covar_module = covar_module
        self.likelihood = likelihood
        self.inducing_points = torch.nn.Parameter(inducing_points.clone())
        self.jitter = jitter

    @property
    def num_outputs(self) -> int:
        return self.inducing_points.shape[0]

    def _factors(self, x: Tensor, y: Tensor) -> tuple[Tensor, ...]:
        b, m = self.num_outputs, self.inducing_points.shape[1]
        xb = x.unsqueeze(0).expand(b, *x.shape)
        z = self.inducing_points
        s2 = self.likelihood.noise.reshape(b, 1, 1)
        kzz = self.covar_module.forward(z, z)
        kzz = kzz + self.jitter * torch.eye(m, dtype=x.dtype)
        kzx = self.covar_module.forward(z, xb)
        chol = torch.linalg.cholesky(kzz)
        a = torch.linalg.solve_triangular(chol, kzx, upper=False) / s2.sqrt()
        bmat = torch.eye(m, dtype=x.dtype) + a @ a.transpose(-1, -2)
        chol_b = torch.linalg.cholesky(bmat)
        resid = y - self.mean_module(xb)
        c = torch.linalg.solve_triangular(chol_b, a @ resid.unsqueeze(-1), upper=False) / s2.sqrt()
        return kzz, chol, a, chol_b, resid, c, s2.reshape(b)

    def elbo(self, x: Tensor, y: Tensor) -> Tensor:
        """Titsias' bound ``F_b`` per output, shape ``(B,)``; ``x`` (n, d), ``y`` (B, n)."""
        n = x.shape[0]
        _, _, a, chol_b, resid, c, s2 = self._factors(x, y)
        c = c.squeeze(-1)
        # stationary kernel: k(x, x) is the outputscale
        kxx_trace = n * self.covar_module.outputscale.reshape(-1)
        log_det = 2.0 * torch.log(torch.diagonal(chol_b, dim1=-2, dim2=-1)).sum(-1)
        quad = (resid**2).sum(-1) / s2 - (c**2).sum(-1)
        log_lik = -0.5 * (n * np.log(2.0 * np.pi) + log_det + n * torch.log(s2) + quad)
        trace = kxx_trace / s2 - (a**2).sum((-1, -2))
        return log_lik - 0.5 * trace

    def log_prior(self) -> Tensor:
        """Sum of the log densities of all registered hyperparameter priors."""
        total = torch.zeros((), dtype=self.inducing_points.dtype)
        for _, module, prior, closure, _ in self.named_priors():
            total = total + prior.log_prob(closure(module)).sum()
        return total

    def posterior(self, x: Tensor, y: Tensor) -> SparsePosterior:
        """The optimal variational posterior given data ``x`` (n, d), ``y`` (B, n)."""
        with torch.no_grad():
            kzz, chol, _, chol_b, _, c, _ = self._factors(x, y)
            tmp = torch.linalg.solve_triangular(chol_b.transpose(-1, -2), c, upper=True)
            w = torch.linalg.solve_triangular(chol.transpose(-1, -2), tmp, upper=True).squeeze(-1)
            const = self.mean_module(self.inducing_points[:, :1, :]).reshape(-1)
            rkhs_sq = torch.einsum("bi,bij,bj->b", w, kzz, w).clamp_min(0.0)
        return SparsePosterior(
            covar_module=copy.deepcopy(self.covar_module),
            inducing_points=self.inducing_points.detach().clone(),
            weights=w,
            chol_zz=chol,
            chol_b=chol_b,
            mean_constant=const,
            mean_rkhs_norm=rkhs_sq.sqrt(),
        )

    def prior(self) -> SparsePosterior:
        """The prior as a posterior with no data (``w = 0``, ``var = k(x, x)``)."""
        with torch.no_grad():
            b, m = self.num_outputs, self.inducing_points.shape[1]
            eye = torch.eye(m, dtype=self.inducing_points.dtype).expand(b, m, m)
            kzz = self.covar_module.forward(self.inducing_points, self.inducing_points)
            chol = torch.linalg.cholesky(kzz + self.jitter * eye)
            const = self.mean_module(self.inducing_points[:, :1, :]).reshape(-1)
        return SparsePosterior(
            covar_module=copy.deepcopy(self.covar_module),
            inducing_points=self.inducing_points.detach().clone(),
            weights=torch.zeros(b, m, dtype=chol.dtype),
            chol_zz=chol,
            chol_b=eye.clone(),
            mean_constant=const,
            mean_rkhs_norm=torch.zeros(b, dtype=chol.dtype),
        )


@dataclass(frozen=True)
class SparsePosterior:
    """A fitted sparse-GP posterior over ``B`` outputs (see the module docstring)."""

    covar_module: gpytorch.kernels.Kernel
    inducing_points: Tensor
    weights: Tensor
    chol_zz: Tensor
    chol_b: Tensor
    mean_constant: Tensor
    mean_rkhs_norm: Tensor

    def predict(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and standard deviation of the latent function, each ``(M, B)``."""
        x = torch.as_tensor(np.asarray(points, dtype=np.float64))
        b = self.inducing_points.shape[0]
        with torch.no_grad():
            xb = x.unsqueeze(0).expand(b, *x.shape)
            kzx = self.covar_module.forward(self.inducing_points, xb)
            mean = self.mean_constant[:, None] + torch.einsum("bm,bmn->bn", self.weights, kzx)
            v = torch.linalg.solve_triangular(self.chol_zz, kzx, upper=False)
            u = torch.linalg.solve_triangular(self.chol_b, v, upper=False)
            prior_var = self.covar_module.outputscale.reshape(b, 1)
            var = prior_var - (v**2).sum(-2) + (u**2).sum(-2)
            var = torch.minimum(var.clamp_min(0.0), prior_var.expand_as(var))
        return mean.T.numpy().copy(), var.sqrt().T.numpy().copy()

    def increment_std(self, half_width: np.ndarray) -> np.ndarray:
        """``rho_b = sqrt(2 (k_b(0) - k_b(h)))`` for the displacement ``h = half_width``.

        For a stationary kernel whose ``k(0) - k(d)`` grows with every ``|d_i|`` (RBF, Matérn),
        ``rho`` bounds the prior standard deviation of ``f(x) - f(x')`` for all ``x, x'``
        with ``|x_i - x'_i| <= h_i``; shape ``(B,)``.
        """
        h = torch.as_tensor(np.asarray(half_width, dtype=np.float64)).reshape(1, 1, -1)
        b = self.inducing_points.shape[0]
        with torch.no_grad():
            zero = torch.zeros_like(h).expand(b, 1, h.shape[-1])
            k_h = self.covar_module.forward(zero, h.expand(b, 1, h.shape[-1])).reshape(b)
            k_0 = self.covar_module.outputscale.reshape(b)
            return torch.sqrt(2.0 * (k_0 - k_h).clamp_min(0.0)).numpy().copy()

    def variation(self, half_width: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds on the change of mean and std between points at most ``half_width`` apart.

        Mean: ``mean - c = sum_i w_i k(., z_i)`` lies in the kernel's RKHS with norm
        ``||w||_K = sqrt(w^T K_zz w)``, so by Cauchy-Schwarz ``|mean(x) - mean(x')| <=
        ||w||_K ||k(., x) - k(., x')||_H = ||w||_K rho``. Std: the posterior covariance is
        ``k - k_z A k_z`` with ``A = K_zz^-1 - Sigma`` positive semi-definite, so it is a kernel,
        the std is an L2 norm (``|s(x) - s(x')| <= sd(f(x) - f(x'))``) and the posterior
        variance of the increment is at most its prior variance ``rho^2``.
        """
        rho = self.increment_std(half_width)
        return self.mean_rkhs_norm.numpy() * rho, rho
