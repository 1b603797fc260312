"""What a hop accepts and what counts as physical, shared by the single hop
(:mod:`hopper_sim.physics.hop`) and the batched one (:mod:`hopper_sim.physics.batch`).

Inputs: shapes, finite values, the touchdown elevation in (0, pi/2], a descending
interstitial state (vz <= 0), and the model's valid range (speeds the leg cannot sweep in
:data:`MIN_SWEEP_STEPS` steps, azimuth, noise, position). Results: times in order and
finite, finite energies, and a passive hop's energy conserved to
:data:`PASSIVE_ENERGY_TOLERANCE`.
"""

from __future__ import annotations

import numpy as np

from hopper_sim.errors import HopperSimError

#: Fewest integration steps in which the leg may sweep its rest length: it bounds the speeds
#: a hop accepts, ``|v_xy|, |v_z| <= l0 / (MIN_SWEEP_STEPS * dt)`` (50 m/s for the shipped
#: model, six times the controller's training box; beyond it a stance spans a few steps).
MIN_SWEEP_STEPS = 20
#: Largest landing noise |nu_x|, |nu_y| a hop accepts, in leg rest lengths (the model's
#: noise is truncated at 0.2 l0).
MAX_NOISE_LEGS = 1.0
#: Largest |x|, |y| of a hop's start [m].
MAX_POSITION = 1.0e6
#: Relative energy change allowed in a passive hop (no thrust, terrain force or noise): the
#: spring-mass stance conserves energy (RK4 drifts by about 1e-9).
PASSIVE_ENERGY_TOLERANCE = 1.0e-4


class HopInputError(HopperSimError, ValueError):
    """Invalid hop input (shape, non-finite value, angle or vertical velocity out of range)."""


def validate_inputs(
    pos: np.ndarray, vel: np.ndarray, alpha: np.ndarray, beta: np.ndarray, what: str = "hop"
) -> None:
    """Raise :class:`HopInputError` naming the offending input (and row, for batches)."""
    n = pos.shape[0]
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise HopInputError(f"{what}: pos must have shape (N, 2) or (2,), got {pos.shape}")
    if vel.shape != (n, 3):
        raise HopInputError(f"{what}: vel must have shape ({n}, 3) or (3,), got {vel.shape}")
    for name, arr in (("alpha", alpha), ("beta", beta)):
        if arr.shape != (n,):
            raise HopInputError(f"{what}: {name} must have shape ({n},), got {arr.shape}")
    for name, arr in (("pos", pos), ("vel", vel), ("alpha", alpha), ("beta", beta)):
        bad = ~np.isfinite(arr)
        if bad.any():
            row = int(np.argwhere(bad)[0][0])
            raise HopInputError(f"{what}: {name} is not finite at row {row}: {arr[row]}")
    bad = (alpha <= 0.0) | (alpha > np.pi / 2)
    if bad.any():
        row = int(np.argmax(bad))
        raise HopInputError(f"{what}: alpha must lie in (0, pi/2], row {row}: {alpha[row]}")
    bad = vel[:, 2] > 0.0
    if bad.any():
        row = int(np.argmax(bad))
        raise HopInputError(
            f"{what}: the interstitial state descends (vz <= 0), row {row}: vz = {vel[row, 2]}"
        )


def max_speed(params) -> float:
    """The largest horizontal and vertical speed [m/s] a hop accepts (:data:`MIN_SWEEP_STEPS`)."""
    return params.rest_length / (MIN_SWEEP_STEPS * params.timestep)


def validate_range(
    params, pos: np.ndarray, vel: np.ndarray, beta: np.ndarray, noise, what: str = "hop"
) -> None:
    """Raise :class:`HopInputError` for inputs outside the model's valid range: speeds
    beyond :func:`max_speed`, an azimuth outside [-pi, pi], noise beyond
    :data:`MAX_NOISE_LEGS` leg lengths, a start beyond :data:`MAX_POSITION`."""
    v_max = max_speed(params)
    checks = [
        ("|pos|", np.abs(pos).max(axis=1), MAX_POSITION, "m"),
        ("the horizontal speed", np.hypot(vel[:, 0], vel[:, 1]), v_max, "m/s"),
        ("|vz|", np.abs(vel[:, 2]), v_max, "m/s"),
        ("|beta|", np.abs(beta), np.pi, "rad"),
    ]
    if noise is not None:
        checks.append(
            ("|noise|", np.abs(noise).max(axis=1), MAX_NOISE_LEGS * params.rest_length, "m")
        )
    for name, value, limit, unit in checks:
        bad = ~(value <= limit)
        if bad.any():
            row = int(np.argmax(bad))
            raise HopInputError(
                f"{what}: {name} = {value[row]:.6g} {unit} at row {row} is outside the model's "
                f"valid range (at most {limit:.6g} {unit})"
            )


def implausible(
    touchdown_time: np.ndarray,
    liftoff_time: np.ndarray,
    flight_time: np.ndarray,
    energy_before: np.ndarray,
    energy_after: np.ndarray,
    passive: np.ndarray,
) -> np.ndarray:
    """Mask of hop results that are not physical: a time that is not finite, negative or out
    of order (touchdown <= liftoff, flight > 0), a non-finite energy, or a passive hop whose
    energy changed by more than :data:`PASSIVE_ENERGY_TOLERANCE`."""
    times_ok = (
        np.isfinite(touchdown_time)
        & np.isfinite(liftoff_time)
        & np.isfinite(flight_time)
        & (touchdown_time >= 0.0)
        & (liftoff_time >= touchdown_time)
        & (flight_time > 0.0)
    )
    energy_ok = np.isfinite(energy_after)
    drift = np.abs(energy_after - energy_before) > PASSIVE_ENERGY_TOLERANCE * np.abs(energy_before)
    return ~times_ok | ~energy_ok | (passive & drift)
