"""Exact reference integration of the same SLIP hop (for tests and benchmarks).

Descent and flight use the closed forms of :mod:`hopper_sim.physics.slip`; the stance is integrated
by :func:`scipy.integrate.solve_ivp` (DOP853, rtol = atol = 1e-12) with terminal events at
liftoff (l = l0, lengthening) and at the ground (z = 0). The stance force is the one of
:mod:`hopper_sim.physics.slip` with a constant thrust command c acting while c ldot > 0 (the thrust
switch is resolved as an event as well, so the integration never steps across a kink).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from hopper_sim.physics import slip
from hopper_sim.physics.hop import MAX_STANCE_TIME
from hopper_sim.physics.model import SlipParams

RTOL = 1e-12
ATOL = 1e-12


@dataclass(frozen=True)
class ReferenceHop:
    """Outcome of the reference hop; ``status`` uses the names of :mod:`hopper_sim.physics.hop`."""

    status: str
    touchdown_time: float
    liftoff_time: float | None = None
    liftoff_pos: np.ndarray | None = None
    liftoff_vel: np.ndarray | None = None
    next_pos: np.ndarray | None = None
    next_vel: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def reference_hop(
    params: SlipParams,
    pos: np.ndarray,
    vel: np.ndarray,
    alpha: float,
    beta: float,
    *,
    force: np.ndarray | None = None,
    noise: np.ndarray | None = None,
    thrust_command: float = 0.0,
    max_stance_time: float = MAX_STANCE_TIME,
) -> ReferenceHop:
    """One hop with the same conventions as :func:`hopper_sim.physics.hop.simulate_hop`; ``force``
    is
    the (constant) horizontal terrain force of this stance [N]."""
    f_ext = np.zeros(2) if force is None else np.asarray(force, dtype=float)
    td = slip.touchdown(
        params,
        np.asarray(pos, float)[None],
        np.asarray(vel, float)[None],
        np.array([alpha], float),
        np.array([beta], float),
    )
    t_td = float(td.time[0])
    if not td.leg_rate[0] < 0.0:
        return ReferenceHop("no_touchdown", t_td)
    y0 = np.concatenate([td.com[0], td.vel[0]])
    status, y, t = _integrate_stance(
        params, td.foot[0], y0, f_ext, float(thrust_command), max_stance_time
    )
    if status != "ok":
        return ReferenceHop(status, t_td)
    p_lo, v_lo = y[None, :3], y[None, 3:]
    fl = slip.flight(params, p_lo, v_lo, None if noise is None else np.asarray(noise)[None])
    if not np.isfinite(fl.duration[0]):
        return ReferenceHop("no_touchdown", t_td, t_td + t, p_lo[0], v_lo[0])
    return ReferenceHop(
        "ok",
        t_td,
        t_td + t,
        p_lo[0],
        fl.liftoff_vel[0],
        fl.next_pos[0],
        fl.next_vel[0],
    )


def _integrate_stance(
    params: SlipParams,
    foot: np.ndarray,
    y: np.ndarray,
    f_ext: np.ndarray,
    c: float,
    max_stance_time: float,
) -> tuple[str, np.ndarray, float]:
    """``(status, state (6,) at liftoff, stance time)`` of the stance from ``y`` (CoM
    position and velocity at touchdown) on the foot ``foot``, with the terrain force
    ``f_ext`` and the thrust command ``c``; ``status`` is ``ok``, ``ground`` or
    ``no_liftoff``.

    The thrust phase (c > 0 acts while ldot > 0, c < 0 while ldot < 0; ldot < 0 at
    touchdown) is integrated apart from the rest, its end (ldot = 0) an event."""
    liftoff, ground, leg_rate = _stance_events(foot, params.rest_length)
    t = 0.0
    phases = (c < 0.0, c > 0.0)
    for phase, thrust_on in enumerate(phases):
        events = [liftoff, ground] + ([leg_rate] if phase == 0 else [])
        sol = solve_ivp(
            _stance_rhs(params, foot, f_ext, c if thrust_on else None),
            (t, max_stance_time),
            y,
            method="DOP853",
            rtol=RTOL,
            atol=ATOL,
            events=events,
        )
        y, t = sol.y[:, -1], float(sol.t[-1])
        if sol.status != 1:
            return "no_liftoff", y, t
        if sol.t_events[1].size:
            return "ground", y, t
        if sol.t_events[0].size:
            break
        if phase == 1:
            return "no_liftoff", y, t
    return "ok", y, t


def _stance_rhs(params: SlipParams, foot: np.ndarray, f_ext: np.ndarray, c: float | None):
    """``dy/dt`` of the stance, ``y = (CoM position, velocity)``: the push-only spring
    ``k max(l0 - l, 0)`` plus the thrust ``c ldot`` (none when ``c`` is ``None``) along the
    leg, the terrain force and gravity."""
    m, k, l0, g = params.mass, params.stiffness, params.rest_length, params.gravity

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        d = y[:3] - foot
        length = np.sqrt(d @ d)
        u = d / length
        ldot = u @ y[3:]
        f = k * max(l0 - length, 0.0) + (c * ldot if c is not None else 0.0)
        acc = f * u / m
        acc[:2] += f_ext / m
        acc[2] -= g
        return np.concatenate([y[3:], acc])

    return rhs


def _stance_events(foot: np.ndarray, l0: float):
    """The terminal events of a stance: liftoff (l = l0, lengthening), the CoM at the ground
    (z = 0, falling) and ``ldot = 0`` (the thrust switch)."""

    def liftoff(_t, y):
        d = y[:3] - foot
        return np.sqrt(d @ d) - l0

    liftoff.terminal, liftoff.direction = True, 1.0

    def ground(_t, y):
        return y[2]

    ground.terminal, ground.direction = True, -1.0

    def leg_rate(_t, y):
        d = y[:3] - foot
        return (d @ y[3:]) / np.sqrt(d @ d)

    leg_rate.terminal, leg_rate.direction = True, 0.0
    return liftoff, ground, leg_rate
