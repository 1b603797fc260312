"""v_des: the interstitial velocity of steady hopping for a nominal hop length.

Steady hopping is a fixed point of the hop map with the foot straight ahead (beta = 0): the
hopper starts at an interstitial state with velocity ``(s, 0, v_z)`` (heading frame), lands
its next interstitial state ``L`` metres ahead with the same velocity. Unknowns and
equations:

* ``total_speed`` given (the ideal SLIP conserves energy, so the interstitial speed
  ``V = |v|`` is fixed by the energy and ``s = sqrt(V^2 - v_z^2)``): unknowns
  ``(v_z, alpha)``, equations ``dx = L`` and ``v_z' = v_z`` (``s' = s`` then follows
  from energy conservation);
* ``total_speed=None`` (a hop map that sets the energy itself, e.g. with the stance thrust
  that restores the nominal energy): unknowns ``(s, v_z, alpha)``, equations ``dx = L``,
  ``s' = s``, ``v_z' = v_z``.

Solved by damped Newton iterations with central finite differences, each iteration one
batched call of the hop map. For the exact SLIP of ``notes/libraries.md`` (m = 80 kg,
l0 = 1 m, k = 20 kN/m) 1.5 m hops at V = 3.5 m/s have v_z = -0.681 m/s and alpha = 71.27 deg
(checked in the tests against the MuJoCo hop).

Choice for the navigation (``hopnav train-controller`` defaults): V_nom = 4.0 m/s and
v_des = the 2.0 m running gait at that speed (s = 3.776 m/s, v_z = -1.319 m/s,
alpha = 70.0 deg). Measured: at 3.5 m/s the hopper reaches 1-cell targets in every direction
but 2-cell targets beside or behind it miss by 0.4-0.5 m, so chained random actions drift
into steep bouncing and the backup replaces nearly every 2-cell request; at 4.0 m/s 2-cell
hops to the side become reachable. At 4.0 m/s there is no flat running gait of 1.5 m (only
steep bouncing ones), hence the 2.0 m gait.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hopper_sim.controller.dataset import BatchHopFn
from hopper_sim.controller.errors import SteadyStateError

NOMINAL_HOP_LENGTH = 1.5


@dataclass(frozen=True)
class SteadyState:
    """Steady gait: hop length [m], interstitial horizontal speed and vertical velocity
    [m/s], touchdown elevation alpha [rad], and the max-norm residual of the fixed point
    equations [m or m/s]."""

    hop_length: float
    speed: float
    vz: float
    alpha: float
    residual: float

    @property
    def velocity(self) -> np.ndarray:
        """v_des in the heading frame, ``(s, 0, v_z)``."""
        return np.array([self.speed, 0.0, self.vz])

    def as_dict(self) -> dict[str, float]:
        return {
            "hop_length": self.hop_length,
            "speed": self.speed,
            "vz": self.vz,
            "alpha": self.alpha,
            "residual": self.residual,
        }


def _unpack(p: np.ndarray, total_speed: float | None) -> tuple[np.ndarray, ...]:
    if total_speed is None:
        s, vz, alpha = p[:, 0], p[:, 1], p[:, 2]
    else:
        vz, alpha = p[:, 0], p[:, 1]
        s = np.sqrt(np.maximum(total_speed**2 - vz**2, 0.0))
    return s, vz, alpha


def _residuals(
    hop_fn: BatchHopFn, p: np.ndarray, hop_length: float, total_speed: float | None
) -> np.ndarray:
    """Fixed-point residuals per row of ``p``; NaN rows where the hop fails or the
    parameters leave the valid set (v_z <= 0, |v_z| <= V, 0 < alpha <= pi/2)."""
    s, vz, alpha = _unpack(p, total_speed)
    valid = (vz <= 0) & (alpha > 0) & (alpha <= np.pi / 2) & (s >= 0)
    if total_speed is not None:
        valid &= np.abs(vz) <= total_speed
    out = np.full((len(p), 2 if total_speed is not None else 3), np.nan)
    if not valid.any():
        return out
    s, vz, alpha = s[valid], vz[valid], alpha[valid]
    res = hop_fn(np.stack([s, np.zeros_like(s), vz], axis=1), alpha, np.zeros_like(alpha))
    ok = np.asarray(res.ok, dtype=bool)
    d = np.asarray(res.displacement)
    v = np.asarray(res.next_velocity)
    r = [d[:, 0] - hop_length, v[:, 2] - vz]
    if total_speed is None:
        r.insert(1, np.hypot(v[:, 0], v[:, 1]) - s)
    r = np.stack(r, axis=1)
    r[~ok] = np.nan
    out[valid] = r
    return out


def _scan(
    hop_fn: BatchHopFn, hop_length: float, total_speed: float | None, starts: int
) -> list[tuple[float, float, float]]:
    v = 4.0 if total_speed is None else total_speed
    vz, alpha = np.meshgrid(
        np.linspace(-0.9 * v, -0.05 * v, 24), np.linspace(1.0, 1.5, 26), indexing="ij"
    )
    vz, alpha = vz.ravel(), alpha.ravel()
    s = np.sqrt(v**2 - vz**2)
    p = np.stack([s, vz, alpha], axis=1)
    r = _residuals(hop_fn, p if total_speed is None else p[:, 1:], hop_length, total_speed)
    norm = np.where(np.all(np.isfinite(r), axis=1), np.abs(r).max(axis=1), np.inf)
    if not np.isfinite(norm).any():
        raise SteadyStateError(f"every hop of the initial scan failed (|v| = {v} m/s)")
    best = np.argsort(norm)[:starts]
    return [(float(s[i]), float(vz[i]), float(alpha[i])) for i in best if np.isfinite(norm[i])]


def steady_state(
    hop_fn: BatchHopFn,
    hop_length: float = NOMINAL_HOP_LENGTH,
    *,
    total_speed: float | None = None,
    guess: tuple[float, float, float] | None = None,
    tol: float = 1e-6,
    max_iter: int = 40,
    step: float = 1e-5,
    starts: int = 12,
) -> SteadyState:
    """Fixed point of ``hop_fn`` for ``hop_length`` metres per hop.

    ``guess`` is ``(s, v_z, alpha)``; with ``total_speed`` given its ``s`` is ignored.
    Raises :class:`SteadyStateError` if a hop near the iterate fails or the residual does
    not fall below ``tol`` within ``max_iter`` iterations.

    Without a guess, one batched call scans a grid (``v_z`` in [-0.9 V, -0.05 V] with
    ``V = total_speed`` or 4 m/s, alpha in [1.0, 1.5] rad, ``s = sqrt(V^2 - v_z^2)``), Newton
    starts from the ``starts`` points of least residual, and of the fixed points found the
    one with the largest horizontal speed is returned: a hop length has several fixed points
    at one energy (a flat running gait and steep bouncing ones); v_des is the running gait.
    """
    if guess is not None:
        return _newton(hop_fn, hop_length, total_speed, guess, tol, max_iter, step)
    found, errors = [], []
    for g in _scan(hop_fn, hop_length, total_speed, starts):
        try:
            found.append(_newton(hop_fn, hop_length, total_speed, g, tol, max_iter, step))
        except SteadyStateError as exc:
            errors.append(str(exc))
    if not found:
        raise SteadyStateError(f"no start of the scan converged: {'; '.join(errors)}")
    return max(found, key=lambda st: st.speed)


def _newton(
    hop_fn: BatchHopFn,
    hop_length: float,
    total_speed: float | None,
    guess: tuple[float, float, float],
    tol: float,
    max_iter: int,
    step: float,
) -> SteadyState:
    p = np.array(guess[1:] if total_speed is not None else guess, dtype=np.float64)
    n = p.size
    eye = np.eye(n) * step
    r = _residuals(hop_fn, p[None], hop_length, total_speed)[0]
    for it in range(max_iter + 1):
        if not np.all(np.isfinite(r)):
            raise SteadyStateError(f"hop failed at the fixed-point iterate {p.tolist()}")
        if np.max(np.abs(r)) < tol:
            break
        if it == max_iter:
            raise SteadyStateError(
                f"no fixed point within {max_iter} iterations (residual {np.abs(r).max():.3g})"
            )
        probes = np.concatenate([p + eye, p - eye])
        rp = _residuals(hop_fn, probes, hop_length, total_speed)
        jac = (rp[:n] - rp[n:]).T / (2 * step)
        if not np.all(np.isfinite(jac)):
            raise SteadyStateError(f"hop failed next to the fixed-point iterate {p.tolist()}")
        dp = np.linalg.lstsq(jac, -r, rcond=None)[0]
        lam = 1.0
        while lam > 1e-4:
            cand = p + lam * dp
            rc = _residuals(hop_fn, cand[None], hop_length, total_speed)[0]
            if np.all(np.isfinite(rc)) and np.max(np.abs(rc)) < np.max(np.abs(r)):
                p, r = cand, rc
                break
            lam /= 2
        else:
            raise SteadyStateError(
                f"Newton iteration stalled at {p.tolist()} with residual {np.abs(r).max():.3g}"
            )
    s, vz, alpha = (float(v[0]) for v in _unpack(p[None], total_speed))
    return SteadyState(float(hop_length), s, vz, alpha, float(np.max(np.abs(r))))
