"""Steady hopping gaits of the pure SLIP (no perturbations, noise or thrust).

A steady gait with interstitial velocity (v_h, 0, v_z) is a fixed point of the hop map with
beta = 0: the touchdown angle alpha* for which the next interstitial vertical velocity equals
v_z (energy is conserved, so the horizontal speed then repeats too). The hop map is scanned
over alpha with the batched simulator and the forward-hopping root with the largest alpha is
refined by Brent's method on the single-hop simulator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from hopper_sim.errors import HopperSimError
from hopper_sim.physics.batch import simulate_hops
from hopper_sim.physics.hop import simulate_hop
from hopper_sim.physics.model import HopperModel


class GaitError(HopperSimError, ValueError):
    """No steady gait exists for the requested interstitial velocity or hop length."""


@dataclass(frozen=True)
class SteadyGait:
    """A steady gait: interstitial velocity (speed_h, 0, vz) [m/s], touchdown angle alpha
    [rad] (beta = 0), hop length [m], stance and flight (liftoff to interstitial) times [s],
    apex height [m]."""

    speed_h: float
    vz: float
    alpha: float
    hop_length: float
    stance_time: float
    flight_time: float
    apex: float


def steady_gait(
    model: HopperModel, speed_h: float, vz: float, alpha_range: tuple[float, float] = (0.9, 1.55)
) -> SteadyGait:
    """The steady gait with interstitial velocity (speed_h, 0, vz); alpha within
    ``alpha_range`` [rad]. Raises :class:`GaitError` when there is none."""
    if not (speed_h > 0.0 and vz < 0.0):
        raise GaitError(f"need speed_h > 0 and vz < 0, got {speed_h}, {vz}")
    vel = np.array([speed_h, 0.0, vz])
    alphas = np.linspace(alpha_range[0], alpha_range[1], 66)
    scan = simulate_hops(model, np.tile(vel, (alphas.size, 1)), alphas, np.zeros(alphas.size))
    resid = scan.next_vel[:, 2] - vz
    forward = scan.next_pos[:, 0] > 0.0
    good = scan.ok[:-1] & scan.ok[1:] & forward[:-1] & forward[1:]
    sign_change = good & (np.sign(resid[:-1]) != np.sign(resid[1:]))
    idx = np.flatnonzero(sign_change)
    if idx.size == 0:
        raise GaitError(f"no steady gait at v_h = {speed_h} m/s, vz = {vz} m/s in {alpha_range}")
    i = idx[-1]

    def g(a: float) -> float:
        hop = simulate_hop(model, np.zeros(2), vel, a, 0.0, record_path=False)
        return hop.next_vel[2] - vz if hop.ok else np.nan

    alpha = brentq(g, alphas[i], alphas[i + 1], xtol=1e-13)
    hop = simulate_hop(model, np.zeros(2), vel, alpha, 0.0, record_path=False).raise_for_status()
    p = model.params
    return SteadyGait(
        speed_h=float(speed_h),
        vz=float(vz),
        alpha=float(alpha),
        hop_length=float(hop.next_pos[0]),
        stance_time=float(hop.liftoff_time - hop.touchdown_time),
        flight_time=float(hop.flight_time),
        apex=float(p.rest_length + vz * vz / (2.0 * p.gravity)),
    )


def gait_for_hop_length(
    model: HopperModel, hop_length: float, speed: float, shares: int = 17
) -> SteadyGait:
    """The steady gait of total interstitial speed ``speed`` [m/s] whose hops are
    ``hop_length`` [m] long. The share s = |vz| / speed is scanned on ``shares`` points of
    [0.05, 0.95]; the first bracket of the steady hop length around ``hop_length`` is refined
    by Brent's method. Raises :class:`GaitError` when the length is out of reach."""

    def gait(share: float) -> SteadyGait | None:
        vz = -share * speed
        try:
            return steady_gait(model, float(np.sqrt(speed**2 - vz**2)), vz)
        except GaitError:
            return None

    grid = np.linspace(0.05, 0.95, shares)
    lengths = np.array([np.nan if (g := gait(s)) is None else g.hop_length for s in grid])
    d = lengths - hop_length
    ok = np.isfinite(d[:-1]) & np.isfinite(d[1:]) & (np.sign(d[:-1]) != np.sign(d[1:]))
    if not ok.any():
        raise GaitError(
            f"hop length {hop_length} m out of reach at {speed} m/s "
            f"(steady lengths {np.nanmin(lengths):.3f}..{np.nanmax(lengths):.3f} m)"
        )
    i = int(np.flatnonzero(ok)[0])

    def residual(share: float) -> float:
        g = gait(share)
        return np.nan if g is None else g.hop_length - hop_length

    share = brentq(residual, grid[i], grid[i + 1], xtol=1e-12)
    result = gait(share)
    if result is None:
        raise GaitError(f"steady gait lost at share {share} for {hop_length} m at {speed} m/s")
    return result
