"""Two sparse GPs for the x and y landing error, with k-means inducing points and warm refits.

Units: positions and errors in metres; variances in square metres.

Model, per axis ``d`` (independent, batched as one :class:`~planner.gp.sgpr.SparseGP`)::

    e_d ~ GP(c_d, s_d^2 RBF(lengthscales l_d)),   observed error = e_d(x) + noise, noise ~ N(0, n_d)

Priors (gpytorch priors on the hyperparameters, used as MAP penalties while fitting):

* lengthscales ``l``: Gamma(concentration 4, rate 2): mean 2 m, standard deviation 1 m;
* outputscale ``s^2``: Gamma(2, 2 / prior_std^2): mean ``prior_std^2``;
* noise variance ``n``: Gamma(2, 2 / noise_std^2): mean ``noise_std^2``, floor 1e-4 m^2.

With no data the model is its prior: mean ``c = 0`` and std ``prior_std`` everywhere, so the
intervals start wide. The default ``prior_std = 0.15`` m is about a third of the largest mean
error docs/design.md expects (0.3-0.5 m), so that ``beta * prior_std`` (about 0.74 m for the
15 x 15 world's ``beta = 4.9``) covers it.

Every :meth:`LandingErrorGP.fit` re-initialises the ``eta`` inducing points by k-means
(scikit-learn, seeded) on the departure positions and starts the optimiser from the previous
hyperparameters (warm start); :meth:`LandingErrorGP.reset` forgets both.
Fitting runs Adam (learning rate ``learning_rate``) on the negative bound plus the negative
log prior, divided by the number of data; inducing points are optimised too. The first fit
after construction or :meth:`LandingErrorGP.reset` runs ``cold_steps`` (30) steps, every
warm-started refit ``steps`` (15): between batches the hyperparameters move little.
Fitting and prediction run with ``num_threads`` torch threads (default 1: the matrices are
small, and extra threads only contend on a shared machine); the global setting is restored.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import gpytorch
import numpy as np
import torch
from sklearn.cluster import KMeans

from planner.errors import GPDataError
from planner.gp.sgpr import SparseGP, SparsePosterior
from planner.torch_threads import torch_threads

_DTYPE = torch.float64
_BATCH = torch.Size([2])


@dataclass(frozen=True)
class FitSettings:
    """Settings of the landing-error GPs (lengths in metres)."""

    num_inducing: int = 50
    steps: int = 15
    cold_steps: int = 30
    learning_rate: float = 0.05
    prior_std: float = 0.15
    lengthscale: float = 2.0
    noise_std: float = 0.1
    jitter: float = 1e-6
    num_threads: int | None = 1

    def __post_init__(self) -> None:
        for name in ("num_inducing", "steps", "cold_steps"):
            if int(getattr(self, name)) < (1 if name == "num_inducing" else 0):
                raise GPDataError(f"FitSettings.{name} out of range: {getattr(self, name)}")
        if self.num_threads is not None and int(self.num_threads) < 1:
            raise GPDataError(f"FitSettings.num_threads must be >= 1, got {self.num_threads}")
        for name in ("learning_rate", "prior_std", "lengthscale", "noise_std", "jitter"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value <= 0.0:
                raise GPDataError(f"FitSettings.{name} must be positive and finite, got {value}")


@dataclass(frozen=True)
class FitReport:
    """What one refit did: data size, inducing points, final loss and hyperparameters."""

    num_data: int
    num_inducing: int
    final_loss: float
    lengthscale: np.ndarray
    outputscale: np.ndarray
    noise: np.ndarray


def _validate(positions: np.ndarray, errors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pos = np.asarray(positions, dtype=np.float64)
    err = np.asarray(errors, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise GPDataError(f"positions must have shape (N, 2), got {pos.shape}")
    if err.shape != pos.shape:
        raise GPDataError(f"errors must have shape {pos.shape} like positions, got {err.shape}")
    for name, arr in (("positions", pos), ("errors", err)):
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        if bad.size:
            raise GPDataError(f"{name} has non-finite values in row {int(bad[0])}")
    return pos, err


class LandingErrorGP:
    """The x and y landing-error GPs; implements :class:`~planner.gp.protocol.ErrorPredictor`.

    Args:
        settings: model and optimiser settings (see the module docstring).
        seed: seed of the k-means initialisation of the inducing points.
    """

    def __init__(self, settings: FitSettings | None = None, *, seed: int = 0) -> None:
        self.settings = settings or FitSettings()
        self.seed = int(seed)
        self.reset()

    def reset(self) -> None:
        """Forget data and hyperparameters: back to the prior."""
        s = self.settings
        mean = gpytorch.means.ConstantMean(batch_shape=_BATCH)
        base = gpytorch.kernels.RBFKernel(
            ard_num_dims=2,
            batch_shape=_BATCH,
            lengthscale_prior=gpytorch.priors.GammaPrior(4.0, 2.0),
        )
        kernel = gpytorch.kernels.ScaleKernel(
            base,
            batch_shape=_BATCH,
            outputscale_prior=gpytorch.priors.GammaPrior(2.0, 2.0 / s.prior_std**2),
        )
        likelihood = gpytorch.likelihoods.GaussianLikelihood(
            batch_shape=_BATCH,
            noise_prior=gpytorch.priors.GammaPrior(2.0, 2.0 / s.noise_std**2),
            noise_constraint=gpytorch.constraints.GreaterThan(1e-4),
        )
        base.lengthscale = torch.full((2, 1, 2), s.lengthscale)
        kernel.outputscale = torch.full((2,), s.prior_std**2)
        likelihood.noise = torch.full((2, 1), s.noise_std**2)
        z0 = torch.zeros(2, 1, 2, dtype=_DTYPE)
        self.model = SparseGP(mean, kernel, likelihood, z0, jitter=s.jitter).to(_DTYPE)
        self._posterior: SparsePosterior = self.model.prior()
        self.num_data = 0
        self._warm = False

    def warm_up(self) -> None:
        """Pay torch's and gpytorch's one-time start-up costs (about 2 s on a loaded 2-core
        machine, measured) with a tiny fit, then return to the prior. Call it once before a
        timed loop; it changes no results (the model is :meth:`reset` afterwards)."""
        rng = np.random.default_rng(0)
        pos = rng.uniform(0.0, 1.0, size=(8, 2))
        with torch_threads(self.settings.num_threads):
            self._fit(pos, np.zeros_like(pos), None)
            self.predict(pos)
        self.reset()

    @property
    def posterior(self) -> SparsePosterior:
        return self._posterior

    def _init_inducing(self, pos: np.ndarray) -> torch.Tensor:
        distinct = np.unique(pos, axis=0)
        m = min(self.settings.num_inducing, distinct.shape[0])
        if m == distinct.shape[0]:
            centres = distinct
        else:
            km = KMeans(n_clusters=m, n_init=1, random_state=self.seed).fit(distinct)
            centres = km.cluster_centers_
        z = torch.as_tensor(centres, dtype=_DTYPE)
        return z.unsqueeze(0).expand(2, *z.shape).clone()

    def fit(
        self,
        positions: np.ndarray,
        errors: np.ndarray,
        *,
        on_step: Callable[[int, float], None] | None = None,
    ) -> FitReport:
        """Refit both GPs on all data: departure ``positions`` (N, 2), landing ``errors`` (N, 2).

        ``on_step(step, loss)`` is called after every optimiser step (progress, logging).
        With ``N = 0`` the model returns to its prior (hyperparameters kept).
        """
        pos, err = _validate(positions, errors)
        with torch_threads(self.settings.num_threads):
            return self._fit(pos, err, on_step)

    def _fit(
        self, pos: np.ndarray, err: np.ndarray, on_step: Callable[[int, float], None] | None
    ) -> FitReport:
        if pos.shape[0] == 0:
            self.num_data = 0
            self._posterior = self.model.prior()
            return self._report(0, float("nan"))
        self.model.inducing_points = torch.nn.Parameter(self._init_inducing(pos))
        x = torch.as_tensor(pos, dtype=_DTYPE)
        y = torch.as_tensor(err.T.copy(), dtype=_DTYPE)
        opt = torch.optim.Adam(self.model.parameters(), lr=self.settings.learning_rate)
        n = pos.shape[0]
        loss_value = float("nan")
        steps = self.settings.steps if self._warm else self.settings.cold_steps
        for step in range(steps):
            opt.zero_grad()
            loss = -(self.model.elbo(x, y).sum() + self.model.log_prior()) / n
            loss.backward()
            opt.step()
            loss_value = float(loss.detach())
            if on_step is not None:
                on_step(step, loss_value)
        self.num_data = n
        self._warm = True
        self._posterior = self.model.posterior(x, y)
        return self._report(n, loss_value)

    def _report(self, n: int, loss: float) -> FitReport:
        k = self.model.covar_module
        with torch.no_grad():
            return FitReport(
                num_data=n,
                num_inducing=int(self.model.inducing_points.shape[1]) if n else 0,
                final_loss=loss,
                lengthscale=k.base_kernel.lengthscale.reshape(2, 2).numpy().copy(),
                outputscale=k.outputscale.reshape(2).numpy().copy(),
                noise=self.model.likelihood.noise.reshape(2).numpy().copy(),
            )

    def predict(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and std of the error (metres), each ``(M, 2)`` (columns x, y)."""
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise GPDataError(f"points must have shape (M, 2), got {pts.shape}")
        if not np.isfinite(pts).all():
            raise GPDataError("points has non-finite values")
        with torch_threads(self.settings.num_threads):
            return self._posterior.predict(pts)

    def variation(self, half_width: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """See :meth:`planner.gp.sgpr.SparsePosterior.variation`."""
        return self._posterior.variation(half_width)
