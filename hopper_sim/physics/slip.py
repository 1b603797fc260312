"""Closed-form pieces of the SLIP hop, vectorised over hops (leading axis N).

A hop starts at the interstitial state (CoM at height z = l0, descending; t = 0 there):

* descent (ballistic) to the touchdown height z_td = l0 sin(alpha) at time t_td;
* the foot lands at ``com + l0 (cos a cos(psi + b), cos a sin(psi + b), -sin a)`` where psi is
  the heading of the horizontal velocity at the interstitial state (psi = 0, i.e. +x, when the
  horizontal speed is zero) and (a, b) = (alpha, beta);
* stance (integrated by MuJoCo or by the reference) until the leg is back at l0, lengthening;
* flight (ballistic) to the next interstitial state z = l0, descending.

Stance dynamics, with u the unit vector from the foot to the CoM, l the leg length and
ldot = u . v its rate:

    m a = f u + F - m g e_z,   f = k max(l0 - l, 0) + f_thrust,

with F the horizontal terrain force (constant over a stance: evaluated where the foot stands)
and f_thrust = c ldot when c ldot > 0 (the thrust only ever pushes), else 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hopper_sim.physics.model import SlipParams


def heading(vel: np.ndarray) -> np.ndarray:
    """Heading psi [rad] of the horizontal velocity, (N,); 0 (+x) where it is zero."""
    vel = np.asarray(vel, dtype=float)
    return np.arctan2(vel[..., 1], vel[..., 0])  # atan2(0, 0) == 0: +x by convention


def time_to_height(z0: np.ndarray, vz: np.ndarray, h: np.ndarray, g: float) -> np.ndarray:
    """Time [s] for a ballistic CoM at height z0 with vertical speed vz to reach height h
    while descending: the larger root of z0 + vz t - g t^2 / 2 = h; NaN where the apex
    z0 + vz^2 / (2 g) is below h, or where both roots lie in the past (below h and already
    falling: it never comes back up to h)."""
    disc = np.asarray(vz) ** 2 + 2.0 * g * (np.asarray(z0) - np.asarray(h))
    with np.errstate(invalid="ignore"):
        root = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        t = (vz + root) / g
        return np.where(t >= 0.0, t, np.nan)


def ballistic(
    pos: np.ndarray, vel: np.ndarray, t: np.ndarray, g: float
) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity, (N, 3) each, after ballistic flight of duration t (N,)."""
    t = np.asarray(t, dtype=float)[..., None]
    grav = np.array([0.0, 0.0, -g])
    return pos + vel * t + 0.5 * grav * t * t, vel + grav * t


@dataclass(frozen=True)
class Touchdown:
    """Touchdown of N hops: time [s] since the interstitial state, CoM position and velocity
    (N, 3), foot position (N, 3) on the ground, leg rate ldot [m/s] (N,)."""

    time: np.ndarray
    com: np.ndarray
    vel: np.ndarray
    foot: np.ndarray
    leg_rate: np.ndarray


def touchdown(
    params: SlipParams, pos: np.ndarray, vel: np.ndarray, alpha: np.ndarray, beta: np.ndarray
) -> Touchdown:
    """Closed-form descent from interstitial states (pos (N, 2) at z = l0, vel (N, 3)) to
    touchdown with leg angles alpha (elevation) and beta (azimuth from the heading)."""
    l0, g = params.rest_length, params.gravity
    n = pos.shape[0]
    z_td = l0 * np.sin(alpha)
    t_td = time_to_height(np.full(n, l0), vel[:, 2], z_td, g)
    start = np.column_stack([pos, np.full(n, l0)])
    com, v = ballistic(start, vel, t_td, g)
    az = heading(vel) + beta
    ca = np.cos(alpha)
    leg = np.column_stack([ca * np.cos(az), ca * np.sin(az), -np.sin(alpha)])
    foot = com + l0 * leg
    foot[:, 2] = 0.0
    leg_rate = -np.einsum("ij,ij->i", leg, v)  # u = -leg
    return Touchdown(time=t_td, com=com, vel=v, foot=foot, leg_rate=leg_rate)


def leg_state(
    com: np.ndarray, vel: np.ndarray, foot: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leg length l (N,), unit vector u (N, 3) from foot to CoM, and rate ldot (N,)."""
    d = com - foot
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    u = d / length[:, None]
    return length, u, np.einsum("ij,ij->i", u, vel)


def stance_derivatives(
    params: SlipParams,
    com: np.ndarray,
    vel: np.ndarray,
    foot: np.ndarray,
    force: np.ndarray,
    thrust: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Acceleration and jerk, (N, 3) each, of the stance dynamics (module docstring) at a
    state with l <= l0. force: horizontal terrain force (N, 2) [N]; thrust: command c (N,)
    [N s/m]."""
    m, k, l0, g = params.mass, params.stiffness, params.rest_length, params.gravity
    length, u, ldot = leg_state(com, vel, foot)
    on = (thrust * ldot) > 0.0
    c = np.where(on, thrust, 0.0)
    f = k * np.maximum(l0 - length, 0.0) + c * ldot
    ext = np.zeros_like(com)
    ext[:, :2] = force
    ext[:, 2] = -m * g
    acc = (f[:, None] * u + ext) / m
    v2 = np.einsum("ij,ij->i", vel, vel)
    lddot = (v2 - ldot * ldot) / length + np.einsum("ij,ij->i", u, acc)
    udot = (vel - ldot[:, None] * u) / length[:, None]
    fdot = -k * ldot * (length < l0) + c * lddot
    jerk = (fdot[:, None] * u + f[:, None] * udot) / m
    return acc, jerk


def resolve_liftoff(
    params: SlipParams,
    com: np.ndarray,
    vel: np.ndarray,
    foot: np.ndarray,
    force: np.ndarray,
    thrust: np.ndarray,
    dt: float,
    iterations: int = 8,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Liftoff inside the step that follows a stance state (com, vel) with l < l0.

    Within that step (s in [0, dt]) the motion is expanded to third order,
    p(s) = p + v s + a s^2/2 + j s^3/6 with the exact stance acceleration a and jerk j, and
    |p(s) - foot| = l0 is solved by Newton's method from the linear estimate. The truncation
    error is of order snap * dt^4 / 24 (< 1e-9 m for dt = 1e-3 s at hop speeds <= 8 m/s).

    Returns:
        s (N,) [s], liftoff position and velocity (N, 3) each.
    """
    l0 = params.rest_length
    acc, jerk = stance_derivatives(params, com, vel, foot, force, thrust)
    length, _, ldot = leg_state(com, vel, foot)
    d0 = com - foot
    s = np.clip((l0 - length) / np.maximum(ldot, 1e-9), 0.0, dt)
    for _ in range(iterations):
        d = d0 + vel * s[:, None] + acc * (s * s / 2)[:, None] + jerk * (s**3 / 6)[:, None]
        v = vel + acc * s[:, None] + jerk * (s * s / 2)[:, None]
        resid = np.einsum("ij,ij->i", d, d) - l0 * l0
        slope = 2.0 * np.einsum("ij,ij->i", d, v)
        s = np.clip(s - resid / np.where(slope > 0, slope, np.inf), 0.0, dt)
    ss = s[:, None]
    p = com + vel * ss + acc * ss * ss / 2 + jerk * ss**3 / 6
    v = vel + acc * ss + jerk * ss * ss / 2
    return s, p, v


@dataclass(frozen=True)
class Flight:
    """Flight from liftoff to the next interstitial state: duration [s] (N,) (NaN where the
    apex is below l0), next position (N, 2), next velocity (N, 3) and the liftoff velocity
    after the noise impulse (N, 3)."""

    duration: np.ndarray
    next_pos: np.ndarray
    next_vel: np.ndarray
    liftoff_vel: np.ndarray


def flight(
    params: SlipParams, com_lo: np.ndarray, vel_lo: np.ndarray, noise: np.ndarray | None
) -> Flight:
    """Closed-form flight from liftoff to z = l0 descending, with the noise nu (N, 2) [m]
    applied as a horizontal liftoff impulse nu / t_flight, so that the next interstitial
    position moves by exactly nu (t_flight does not depend on horizontal motion)."""
    l0, g = params.rest_length, params.gravity
    t = time_to_height(com_lo[:, 2], vel_lo[:, 2], l0, g)
    v = vel_lo.copy()
    if noise is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            v[:, :2] += noise / t[:, None]
    p, vn = ballistic(com_lo, v, t, g)
    return Flight(duration=t, next_pos=p[:, :2], next_vel=vn, liftoff_vel=v)
