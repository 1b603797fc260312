"""Stance thrust that returns a hop's energy to its nominal value.

The actuator ``thrust`` of the MJCF pushes along the leg with force c * ldot (c: the per-hop
command [N s/m], ldot the leg's rate) while c * ldot > 0, so it only ever pushes: with c > 0
it acts in the extension half of the stance and adds the energy c * integral(ldot^2) dt; with
c < 0 it acts in the compression half and removes energy.

Law: the command is the c for which the hop's energy at the NEXT interstitial state (after
terrain work and the noise impulse) equals the nominal energy E_nom. It is found on the
simulated hop itself: first c_1 = (E_nom - E_before) / I_hat with
I_hat = ldot_td^2 * pi * sqrt(m / k) / 4 (the integral of ldot^2 over half a linear-spring
stance that starts at touchdown with leg rate ldot_td), then c_2 = c_1 + (E_nom - E_1) / I_hat,
then secant steps, at most ``max_runs`` simulated stances in all, stopping when
|E - E_nom| <= rtol * E_nom, and clipped to the actuator's ctrlrange. It is an idealised energy
regulator (it sees the hop's whole energy balance), as DESIGN.md asks of the thrust: it keeps
the interstitial speed at its nominal value hop after hop.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import numpy as np

from hopper_sim.model import SlipParams

T = TypeVar("T")

DEFAULT_MAX_RUNS = 4
DEFAULT_RTOL = 1e-7


def integral_estimate(params: SlipParams, leg_rate_td: np.ndarray) -> np.ndarray:
    """I_hat = ldot_td^2 pi sqrt(m/k) / 4 [m^2/s], floored to stay positive."""
    half_period = np.pi * np.sqrt(params.mass / params.stiffness)
    return np.maximum(np.asarray(leg_rate_td) ** 2 * half_period / 2.0, 1e-6)


def regulate(
    run: Callable[[np.ndarray], tuple[np.ndarray, T]],
    energy_before: np.ndarray,
    energy_nominal: np.ndarray,
    integral: np.ndarray,
    limit: float,
    max_runs: int = DEFAULT_MAX_RUNS,
    rtol: float = DEFAULT_RTOL,
) -> tuple[np.ndarray, T]:
    """Find per-hop thrust commands c (N,) by the law of the module docstring.

    Args:
        run: simulates the N hops with commands c (N,) and returns their energies after the
            hop (N,) (NaN where a hop failed) and an outcome object.
        energy_before, energy_nominal, integral: (N,) arrays [J, J, m^2/s].
        limit: the actuator's largest |c| [N s/m].

    Returns:
        The commands of the last run and that run's outcome.
    """
    target = np.asarray(energy_nominal, dtype=float)
    c = np.clip((target - energy_before) / integral, -limit, limit)
    energy, outcome = run(c)
    c_prev, e_prev = None, None
    for _ in range(max_runs - 1):
        err = target - energy
        done = ~np.isfinite(energy) | (np.abs(err) <= rtol * np.abs(target))
        if np.all(done):
            break
        if c_prev is None:
            step = err / integral
        else:
            de = energy - e_prev
            dc = c - c_prev
            ok = np.isfinite(de) & (np.abs(de) > 1e-12) & (np.abs(dc) > 0)
            step = np.where(ok, err * dc / np.where(ok, de, 1.0), err / integral)
        c_new = np.where(done, c, np.clip(c + step, -limit, limit))
        if np.array_equal(c_new, c):
            break
        c_prev, e_prev = c, energy
        c = c_new
        energy, outcome = run(c)
    return c, outcome
