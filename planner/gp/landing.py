"""Direction-aware model of the hopper's mean landing error: exact GP regression over the
departure position and the executed action, with a fixed, stated prior.

Units: positions and errors in metres. Actions are indices ``0 .. A-1`` (``N1 .. W2``,
:data:`planner.imdp.grid.ACTIONS`, ``A = 8``).

**Model**, per axis ``d`` (the two axes are independent), for a hop that departs from ``x``
and executes action ``a``::

    error_d = e_d(x, a) + nu_d + r_d
    e_d(x, a) = c_{a,d} + s_{a,d} [u_{a,d} (o_d + f_d(x)) + (1 - u_{a,d}) o_{a,d} + g_{a,d}(x)]

* ``c_{a,d} ~ N(bias_mean[a, d], bias_std^2)``: a constant per action (the controller's bias:
  measured undershoots of 0.07 m for one-cell and 0.18-0.2 m for two-cell hops; for MuJoCo
  the prior mean is simulated, :mod:`hopper_sim.controller.error_prior`);
* ``o_d ~ N(0, offset_std^2)``: the error of a force that is the same everywhere (the
  uniform part of the terrain force, e.g. a slope), shared by the coupled actions; an
  uncoupled action has its own ``o_{a,d}`` of the same std. It does not vary with the
  position, so hops anywhere teach it: this is what makes data far from a route count;
* ``f_d ~ GP(0, rho field_std^2 k)``, ``k(x, x') = exp(-|x - x'|^2 / (2 lengthscale^2))``:
  a field shared by the actions *coupled* on axis ``d`` (``u_{a,d} = 1``; by default those
  that move at most one cell along ``d``), the terrain's common effect;
* ``g_{a,d} ~ GP(0, (1 - rho u_{a,d}) field_std^2 k)``, independent per action: the part
  peculiar to the action (``rho = field_correlation``); an uncoupled action's position-
  dependent error is its own field alone;
* ``s_{a,d}`` (``scale``, in ``(0, 1]``, default 1): how strongly the terrain enters action
  ``a`` on axis ``d``, its sensitivity to a stance force relative to the largest one;
* ``nu_d``: the known landing noise (``noise``, truncated Gaussian), independent per hop;
* ``r_d ~ N(0, s_{a,d}^2)``: the residual, independent per hop (the error's dependence on the
  incoming velocity and on the position inside the cell, which the abstraction's state does
  not hold). ``s_{a,d}`` is estimated per action and axis (below).

So every action's position-dependent part has std ``s_{a,d} field_std`` and length scale
``lengthscale``, two coupled actions' parts at the same point correlate with ``rho``, and the
covariance of two hops' mean errors is (``w_a = s_a u_a``)
``w_a w_a' (rho field_std^2 k(x, x') + offset_std^2) + [a = a'] (s_a^2 (1 - rho u_a)
field_std^2 k(x, x') + s_a^2 (1 - u_a) offset_std^2 + bias_std^2)``; the
observation noise of a hop with action ``a`` is ``var(nu) + s_{a,d}^2``.

Where the numbers come from (``benchmarks/error_factors.py``: 600 loop-like departure states
of case (a), every action hopped in MuJoCo with and without the terrain field): the terrain's
effect on two actions from the same state correlates with 0.88-1.0 (mean 0.97) among the
actions that move at most one cell along the axis, but only -0.55 .. 0.5 between a two-cell
hop *along* the axis and any other action (a two-cell hop's landing is 3-4 times less
sensitive to a stance force along its direction); hence the coupling and ``rho = 0.95``.
For MuJoCo (:func:`hopper_sim.controller.error_prior.error_prior`) ``field_std`` is the terrain
amplitude times the largest sensitivity of a landing to a stance force (0.124 m; measured
stds of the terrain's effect 0.12-0.16 m for one-cell hops, 0.04-0.05 m along two-cell hops,
so the prior is conservative for the latter) and ``lengthscale`` the terrain's.

**Posterior.** Every :meth:`LandingErrorGP.fit` conditions the prior exactly on all data
(the most recent ``max_data`` hops if there are more): ``alpha = (K + S)^-1 y``,
``C = (K + S)^-1``, ``mean(x, a) = k_*^T alpha``, ``var(x, a) = k_** - k_*^T C k_*``. The
kernel hyperparameters are fixed (not fitted), so for fixed residual variances the posterior
variance can only shrink as data are added (conditioning on more data never increases a
Gaussian variance): one batch of hops cannot collapse the intervals of cells it did not
visit. Cost: ``O(n^3)`` per refit plus ``O(n^2 M)`` for ``M`` query points (all actions at
once, through the kernel's structure); no inducing points (see :mod:`planner.gp.sgpr` and
``benchmarks/gp_update.py`` for how far a sparse GP with 50 inducing points departs from
this posterior).

**Residual variances.** ``s_{a,d}^2 = max(v_{a,d} - var(nu), 0)`` with
``v_{a,d} = (m0 v0 + sum_i l_i^2) / (m0 + n_a)``: the leave-one-out residuals ``l_i`` of the
hops with action ``a`` (``l_i = alpha_i / C_ii``; their mean square exceeds the noise
variance by the leave-one-out posterior variance, so the estimate errs high), pooled with
``m0 = residual_count`` pseudo-hops at ``v0 = var(nu) + residual_std[a, d]^2``; two steps
of this fixed point from ``v0`` per fit. These are the only quantities estimated from the data
besides the posterior itself; they move smoothly with the data (pooled over the whole run,
per action), so they cannot collapse after one batch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from planner.errors import GPDataError
from planner.gp.data import check_hops, check_points
from planner.gp.dense import rbf, spd_inverse
from planner.gp.noise import TruncatedGaussianNoise

N_ACTIONS = 8
"""Number of grid actions (``N1, N2, E1, E2, S1, S2, W1, W2``)."""

_CHUNK = 2048  # query points per block in predict (bounds the memory to ~n * 2048 floats)


def _default_coupling() -> np.ndarray:
    from planner.imdp.grid import ACTION_OFFSETS

    return np.abs(ACTION_OFFSETS) <= 1


@dataclass(frozen=True)
class GPConfig:
    """The prior of :class:`LandingErrorGP` (see the module docstring; lengths in metres).

    ``bias_mean`` (prior mean of ``c_{a,d}``) and ``residual_std`` (prior guess of
    ``s_{a,d}``) are scalars or ``(n_actions, 2)`` tables, stored as nested tuples;
    ``coupled``: ``(n_actions, 2)`` booleans ``u_{a,d}`` (``None``: the actions that move at
    most one cell along the axis, for the 8 grid actions);
    ``scale``: ``(n_actions, 2)`` factors ``s_{a,d}`` in ``(0, 1]`` (or a scalar) on the std
    with which the terrain (offset and fields) enters action ``a`` on axis ``d``: the
    action's sensitivity to a stance force relative to the largest one (default 1);
    ``num_threads`` caps the BLAS threads of a fit or prediction (``None``: leave as is).
    """

    lengthscale: float = 2.0
    field_std: float = 0.125
    offset_std: float = 0.0
    field_correlation: float = 0.95
    bias_mean: float | tuple = 0.0
    bias_std: float = 0.2
    residual_std: float | tuple = 0.1
    residual_count: float = 10.0
    noise: TruncatedGaussianNoise = field(default_factory=TruncatedGaussianNoise)
    n_actions: int = N_ACTIONS
    coupled: tuple | None = None
    scale: float | tuple = 1.0
    max_data: int = 2000
    num_threads: int | None = 1

    def __post_init__(self) -> None:
        if int(self.n_actions) < 1 or int(self.max_data) < 1:
            raise GPDataError(
                f"GPConfig needs n_actions >= 1 and max_data >= 1, got {self.n_actions}, "
                f"{self.max_data}"
            )
        if self.num_threads is not None and int(self.num_threads) < 1:
            raise GPDataError(f"GPConfig.num_threads must be >= 1, got {self.num_threads}")
        value = float(self.lengthscale)
        if not np.isfinite(value) or value <= 0.0:
            raise GPDataError(f"GPConfig.lengthscale must be positive and finite, got {value}")
        for name in ("field_std", "offset_std", "bias_std", "residual_count"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value < 0.0:
                raise GPDataError(f"GPConfig.{name} must be finite and >= 0, got {value}")
        for name, nonneg in (("bias_mean", False), ("residual_std", True), ("scale", True)):
            raw = np.asarray(getattr(self, name), dtype=np.float64)
            try:
                table = np.broadcast_to(raw, (int(self.n_actions), 2))
            except ValueError as exc:
                raise GPDataError(
                    f"GPConfig.{name} must be a scalar or ({self.n_actions}, 2), got shape "
                    f"{raw.shape}"
                ) from exc
            if not np.isfinite(table).all() or (nonneg and (table < 0).any()):
                what = "finite and >= 0" if nonneg else "finite"
                raise GPDataError(f"GPConfig.{name} must be {what}")
            if name == "scale" and ((table <= 0.0) | (table > 1.0)).any():
                raise GPDataError("GPConfig.scale must lie in (0, 1]")
            object.__setattr__(self, name, tuple(tuple(float(v) for v in r) for r in table))
        if not 0.0 <= float(self.field_correlation) <= 1.0:
            raise GPDataError(
                f"GPConfig.field_correlation must lie in [0, 1], got {self.field_correlation}"
            )
        if self.coupled is None:
            if int(self.n_actions) != N_ACTIONS:
                raise GPDataError(f"GPConfig.coupled must be given for {self.n_actions} actions")
            mask = _default_coupling()
        else:
            mask = np.asarray(self.coupled, dtype=bool)
            if mask.shape != (int(self.n_actions), 2):
                raise GPDataError(
                    f"GPConfig.coupled must have shape ({self.n_actions}, 2), got {mask.shape}"
                )
        object.__setattr__(self, "coupled", tuple(tuple(bool(v) for v in r) for r in mask))

    @property
    def bias(self) -> np.ndarray:
        """``(n_actions, 2)`` prior mean of the error, metres."""
        return np.asarray(self.bias_mean, dtype=np.float64)

    @property
    def residual(self) -> np.ndarray:
        """``(n_actions, 2)`` prior guess of the residual std, metres."""
        return np.asarray(self.residual_std, dtype=np.float64)

    @property
    def coupling(self) -> np.ndarray:
        """``(n_actions, 2)`` weights ``s_{a,d} u_{a,d}`` of the shared terms (offset, field)."""
        return np.asarray(self.coupled, dtype=np.float64) * np.asarray(self.scale)

    @property
    def shared_weight(self) -> np.ndarray:
        """``(n_actions, 2)`` std with which the shared field enters each action, metres."""
        return self.field_std * np.sqrt(self.field_correlation) * self.coupling

    @property
    def own_var(self) -> np.ndarray:
        """``(n_actions, 2)`` prior variance of each action's own field ``g``, m^2."""
        u = np.asarray(self.coupled, dtype=np.float64)
        return (self.field_std * np.asarray(self.scale)) ** 2 * (1.0 - self.field_correlation * u)

    @property
    def own_offset_var(self) -> np.ndarray:
        """``(n_actions, 2)`` prior variance of an uncoupled action's own offset, m^2."""
        u = np.asarray(self.coupled, dtype=np.float64)
        return (self.offset_std * np.asarray(self.scale)) ** 2 * (1.0 - u)

    def shared_cov(self, k: np.ndarray) -> np.ndarray:
        """Covariance of the shared terms (offset and field) at kernel values ``k``, before
        the weights ``w_a w_a'`` (:attr:`coupling`), m^2."""
        return self.field_std**2 * self.field_correlation * k + self.offset_std**2

    def own_cov(self, k: np.ndarray, act: np.ndarray, d: int) -> np.ndarray:
        """Covariance of the terms of action ``act`` (last axis of ``k``) of its own on axis
        ``d`` (field, offset of an uncoupled action, bias), at kernel values ``k``, m^2:
        added where the two actions are the same."""
        return k * self.own_var[act, d] + (self.bias_std**2 + self.own_offset_var[act, d])

    def prior_var(self) -> np.ndarray:
        """``(n_actions, 2)`` prior variance of the mean error ``e_d(x, a)``, m^2."""
        terrain = (self.field_std**2 + self.offset_std**2) * np.asarray(self.scale) ** 2
        return terrain + self.bias_std**2

    def prior_std(self) -> float:
        """The largest prior std of the mean error ``e_d(x, a)`` over actions and axes, m."""
        return float(np.sqrt(self.prior_var().max()))


@dataclass(frozen=True)
class FitReport:
    """What one fit did: the data used, hops per action, the residual std per action and axis
    (``(n_actions, 2)``, metres, beyond the noise nu) and the fixed hyperparameters."""

    num_data: int
    per_action: np.ndarray
    residual_std: np.ndarray
    lengthscale: float
    field_std: float
    field_correlation: float
    bias_std: float
    offset_std: float = 0.0


@dataclass(frozen=True)
class _Axis:
    """The posterior of one axis: ``alpha`` (n,), ``inv`` = C (n, n), noise per action."""

    alpha: np.ndarray
    inv: np.ndarray
    noise_var: np.ndarray
    rkhs_norm: float


class LandingErrorGP:
    """The direction-aware landing-error model; implements
    :class:`~planner.gp.protocol.ErrorPredictor` (see the module docstring).

    Args:
        settings: the prior (see :class:`GPConfig`).
    """

    def __init__(self, settings: GPConfig | None = None) -> None:
        self.settings = settings or GPConfig()
        self.reset()

    @property
    def n_actions(self) -> int:
        return int(self.settings.n_actions)

    def reset(self) -> None:
        """Forget all data: back to the prior."""
        s = self.settings
        self.num_data = 0
        self._x = np.zeros((0, 2))
        self._a = np.zeros(0, dtype=np.int64)
        self._noise_var = s.noise.std**2 + s.residual**2
        self._axes: tuple[_Axis, ...] = ()

    def _data_kernel(self, kx: np.ndarray, act: np.ndarray, d: int) -> np.ndarray:
        s = self.settings
        w = s.coupling[act, d]
        same = act[:, None] == act[None, :]
        return np.outer(w, w) * s.shared_cov(kx) + s.own_cov(kx, act, d) * same

    def fit(
        self,
        positions: np.ndarray,
        errors: np.ndarray,
        actions: np.ndarray,
        *,
        on_step: Callable[[int, float], None] | None = None,
    ) -> FitReport:
        """Condition on all data: departure ``positions`` (N, 2), landing ``errors`` (N, 2)
        relative to the executed action's target, executed ``actions`` (N,).

        ``on_step(pass, mean_residual_var)`` is called after each pass of the residual
        estimate. With ``N = 0`` the model returns to its prior.
        """
        pos, err, act = check_hops(positions, errors, actions, self.n_actions)
        with threadpool_limits(self.settings.num_threads, user_api="blas"):
            return self._fit(pos, err, act, on_step)

    def _fit(
        self,
        pos: np.ndarray,
        err: np.ndarray,
        act: np.ndarray,
        on_step: Callable[[int, float], None] | None,
    ) -> FitReport:
        s = self.settings
        self.reset()
        if pos.shape[0] > s.max_data:
            pos, err, act = pos[-s.max_data :], err[-s.max_data :], act[-s.max_data :]
        n = pos.shape[0]
        if n == 0:
            return self._report()
        order = np.argsort(act, kind="stable")
        pos, err, act = pos[order], err[order], act[order]
        kx = rbf(pos, pos, s.lengthscale)
        v0 = s.noise.std**2 + s.residual**2
        counts = np.bincount(act, minlength=self.n_actions)
        noise_var = v0.copy()
        axes = []
        for d in range(2):
            k = self._data_kernel(kx, act, d)
            y = err[:, d] - s.bias[act, d]
            for step in range(3):
                inv = spd_inverse(k + np.diag(noise_var[act, d]))
                alpha = inv @ y
                if step == 2:
                    break
                loo = alpha / np.diag(inv)
                sums = np.bincount(act, weights=loo**2, minlength=self.n_actions)
                pooled = (s.residual_count * v0[:, d] + sums) / (s.residual_count + counts)
                noise_var[:, d] = np.maximum(pooled, s.noise.std**2)
                if on_step is not None:
                    on_step(2 * d + step, float(noise_var[:, d].mean()))
            norm = float(np.sqrt(max(alpha @ k @ alpha, 0.0)))
            axes.append(_Axis(alpha, inv, noise_var[:, d].copy(), norm))
        self._x, self._a, self._axes = pos, act, tuple(axes)
        self._noise_var = noise_var
        self.num_data = n
        return self._report()

    def _report(self) -> FitReport:
        s = self.settings
        return FitReport(
            num_data=self.num_data,
            per_action=np.bincount(self._a, minlength=self.n_actions),
            residual_std=self.residual_std(),
            lengthscale=float(s.lengthscale),
            field_std=float(s.field_std),
            field_correlation=float(s.field_correlation),
            bias_std=float(s.bias_std),
            offset_std=float(s.offset_std),
        )

    def residual_std(self) -> np.ndarray:
        """``(n_actions, 2)`` std of the residual ``r`` beyond the noise nu, metres."""
        return np.sqrt(np.maximum(self._noise_var - self.settings.noise.std**2, 0.0))

    def _blocks(self) -> tuple[np.ndarray, np.ndarray]:
        a = np.arange(self.n_actions)
        return np.searchsorted(self._a, a), np.searchsorted(self._a, a, side="right")

    def predict(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and std of ``e(x, a)`` at ``points`` (M, 2) for every action:
        each ``(M, n_actions, 2)``, metres.

        The quadratic forms of the variance are computed in single precision (relative error
        about 1e-7 of the prior variance, i.e. below 1e-4 m of std), the rest in double.
        """
        pts = check_points(points)
        s = self.settings
        m, na = pts.shape[0], self.n_actions
        prior_var = s.prior_var()
        mean = np.broadcast_to(s.bias, (m, na, 2)).copy()
        var = np.broadcast_to(prior_var, (m, na, 2)).copy()
        if self.num_data == 0:
            return mean, np.sqrt(var)
        with threadpool_limits(s.num_threads, user_api="blas"):
            for lo in range(0, m, _CHUNK):
                sl_ = slice(lo, min(lo + _CHUNK, m))
                dmean, var[sl_] = self._predict_block(pts[sl_], prior_var)
                mean[sl_] += dmean
        return mean, np.sqrt(np.clip(var, 0.0, prior_var))

    def _predict_block(
        self, pts: np.ndarray, prior_var: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        s = self.settings
        ks = rbf(pts, self._x, s.lengthscale)  # (m, n)
        act = self._a
        starts, ends = self._blocks()
        present = np.flatnonzero(ends > starts)
        m = pts.shape[0]
        mean = np.zeros((m, self.n_actions, 2))
        var = np.zeros((m, self.n_actions, 2))
        for d, ax in enumerate(self._axes):
            # cross-covariance of (x, a) with datum i: w_a w_{a_i} shared + [a = a_i] own
            w = s.coupling[:, d]
            shared = s.shared_cov(ks) * w[act]
            own = s.own_cov(ks, act, d)  # column i: the own part for a = a_i
            g = (shared.astype(np.float32) @ ax.inv.astype(np.float32)).astype(np.float64)
            q_shared = (g * shared).sum(1)
            m_shared = shared @ ax.alpha
            cross = np.zeros((m, self.n_actions))
            quad = np.zeros((m, self.n_actions))
            m_own = np.zeros((m, self.n_actions))
            cross[:, present] = np.add.reduceat(g * own, starts[present], axis=1)
            m_own[:, present] = np.add.reduceat(own * ax.alpha, starts[present], axis=1)
            for a in present:
                b = slice(starts[a], ends[a])
                quad[:, a] = ((own[:, b] @ ax.inv[b, b]) * own[:, b]).sum(1)
            mean[:, :, d] = w[None, :] * m_shared[:, None] + m_own
            var[:, :, d] = prior_var[None, :, d] - (
                w[None, :] ** 2 * q_shared[:, None] + 2.0 * w[None, :] * cross + quad
            )
        return mean, var

    def variation(
        self, points: np.ndarray, half_width: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds on how much the mean and the std can change within ``half_width`` (2,)
        metres (per coordinate) of each of ``points`` (M, 2): ``dmean`` ``(M, n_actions, 2)``
        and ``dstd`` ``(n_actions, 2)``, metres.

        Mean: Taylor's theorem at the point ``p`` with ``|x_i - p_i| <= h_i``:
        ``|mean(x) - mean(p)| <= |grad mean(p)| . h + (1/2) H |h|^2``, the gradient exact and
        ``H`` a bound on the Frobenius norm of the Hessian everywhere: the mean (less its
        constant prior mean) lies in the kernel's RKHS with norm ``||alpha||_K =
        sqrt(alpha^T K alpha)``, and each second derivative is the RKHS inner product with a
        second derivative of the kernel, so ``|d_i d_j mean| <= ||alpha||_K
        sqrt(d_i^2 d_j^2 k(0))`` (Cauchy-Schwarz), ``= ||alpha||_K field_std sqrt(3) / l^2``
        for ``i = j`` and ``field_std / l^2`` otherwise (squared exponential kernel).
        Std: with ``rho = field_std sqrt(2 (1 - k(h)))``, the prior std of the increment
        ``e(x, a) - e(p, a)``, the posterior covariance is a kernel, so the std is an L2 norm
        and moves by at most the posterior std of the increment, at most ``rho``.
        """
        pts = check_points(points)
        h = np.asarray(half_width, dtype=np.float64).reshape(-1)
        if h.shape != (2,) or not np.isfinite(h).all() or (h < 0).any():
            raise GPDataError(f"half_width must be 2 finite values >= 0, got {half_width!r}")
        s = self.settings
        shape = (self.n_actions, 2)
        k_h = np.exp(-0.5 * float(h @ h) / s.lengthscale**2)
        dstd = np.full(shape, s.field_std * np.sqrt(2.0 * (1.0 - k_h)))
        m = pts.shape[0]
        if self.num_data == 0:
            return np.zeros((m, *shape)), dstd
        hess = s.field_std * np.sqrt(3.0 + 3.0 + 1.0 + 1.0) / s.lengthscale**2
        curvature = 0.5 * hess * float(h @ h)
        dmean = np.zeros((m, *shape))
        starts, ends = self._blocks()
        present = np.flatnonzero(ends > starts)
        with threadpool_limits(s.num_threads, user_api="blas"):
            for lo in range(0, m, _CHUNK):
                p = pts[lo : lo + _CHUNK]
                ks = rbf(p, self._x, s.lengthscale)
                slope = np.zeros((len(p), self.n_actions, 2))
                for j in range(2):
                    # d k / d p_j = -(p_j - x_ij) / l^2 k
                    grad = ks * ((self._x[None, :, j] - p[:, j, None]) / s.lengthscale**2)
                    for d, ax in enumerate(self._axes):
                        w = s.shared_weight[:, d]
                        g = np.outer(grad @ (w[self._a] * ax.alpha), w)
                        own = np.add.reduceat(grad * ax.alpha, starts[present], axis=1)
                        g[:, present] += s.own_var[present, d] * own
                        slope[:, :, d] += np.abs(g) * h[j]
                norms = np.array([ax.rkhs_norm for ax in self._axes])
                dmean[lo : lo + len(p)] = slope + curvature * norms[None, None, :]
        return dmean, dstd
