"""Stance thrust that returns a hop's energy to its nominal value.

The actuator ``thrust`` of the MJCF pushes along the leg with force c * ldot (c: the per-hop
command [N s/m], ldot the leg's rate) while c * ldot > 0, so it only ever pushes: with c > 0
it acts in the extension half of the stance and adds the energy c * integral(ldot^2) dt; with
c < 0 it acts in the compression half and removes energy. The MuJoCo stance switches the
actuator at the first step boundary after ldot changes sign (where c ldot is near zero); against
an exact switch (``hopper_sim.physics.reference``) this costs about 1.7e-5 m in the next
interstitial
position at c = 300 N s/m (measured), and nothing when the thrust is off.

Law: the command is the c for which the hop's energy at the NEXT interstitial state (after
terrain work and the noise impulse) equals the nominal energy E_nom. It is found on the
simulated hop itself: first c_1 = (E_nom - E_before) / I_hat with
I_hat = ldot_td^2 * pi * sqrt(m / k) / 4 (the integral of ldot^2 over half a linear-spring
stance that starts at touchdown with leg rate ldot_td), then c_2 = c_1 + (E_nom - E_1) / I_hat,
then secant steps, at most ``max_runs`` simulated stances in all, stopping when
|E - E_nom| <= rtol * E_nom, and clipped to the actuator's ctrlrange. It is an idealised energy
regulator (it sees the hop's whole energy balance), as docs/design.md asks of the thrust: it keeps
the interstitial speed at its nominal value hop after hop.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import numpy as np

from hopper_sim.physics.model import SlipParams

T = TypeVar("T")

DEFAULT_MAX_RUNS = 8
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

    A command whose hop fails (e.g. removing so much energy that the flight no longer
    reaches l0) is replaced by the midpoint between it and the best command that worked
    (or 0), so the regulator settles for a feasible command; each hop ends with the feasible
    command of least energy error it tried, or with its first try's failure if none worked.

    Args:
        run: simulates the N hops with commands c (N,) and returns their energies after the
            hop (N,) (NaN where a hop failed) and an outcome object.
        energy_before, energy_nominal, integral: (N,) arrays [J, J, m^2/s].
        limit: the actuator's largest |c| [N s/m].

    Returns:
        The commands of the last run and that run's outcome.
    """
    target = np.asarray(energy_nominal, dtype=float)
    integral = np.asarray(integral, dtype=float)
    tol = rtol * np.abs(target)
    c = np.clip((target - energy_before) / integral, -limit, limit)
    energy, outcome = run(c)
    n = c.shape[0]
    # Best feasible command so far (least |E - E_nom|), and the two latest feasible points
    # (for the secant).
    c_best, err_best = np.full(n, np.nan), np.full(n, np.inf)
    c_a, e_a = np.full(n, np.nan), np.full(n, np.nan)
    c_b, e_b = np.full(n, np.nan), np.full(n, np.nan)
    for _ in range(max_runs - 1):
        feasible = np.isfinite(energy)
        err = target - energy
        better = feasible & (np.abs(err) < err_best)
        c_best = np.where(better, c, c_best)
        err_best = np.where(better, np.abs(err), err_best)
        c_a, e_a = np.where(feasible, c_b, c_a), np.where(feasible, e_b, e_a)
        c_b, e_b = np.where(feasible, c, c_b), np.where(feasible, energy, e_b)
        done = feasible & (np.abs(err) <= tol)
        if np.all(done):
            break
        de, dc = e_b - e_a, c_b - c_a
        secant = np.isfinite(de) & (np.abs(de) > 1e-12) & (np.abs(dc) > 0)
        step = np.where(secant, err * dc / np.where(secant, de, 1.0), err / integral)
        retreat = 0.5 * (c + np.where(np.isfinite(c_best), c_best, 0.0))
        c_new = np.where(done, c, np.where(feasible, np.clip(c + step, -limit, limit), retreat))
        if np.array_equal(c_new, c):
            break
        c = c_new
        energy, outcome = run(c)
    err = np.where(np.isfinite(energy), np.abs(target - energy), np.inf)
    worse = np.isfinite(c_best) & (err > err_best)
    if worse.any():
        c = np.where(worse, c_best, c)
        energy, outcome = run(c)
    return c, outcome
