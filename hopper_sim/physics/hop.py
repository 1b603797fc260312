"""One hop of the MuJoCo SLIP, interstitial state to interstitial state.

Time is measured from the interstitial state (t = 0 there). The descent to touchdown and the
flight after liftoff are ballistic and computed in closed form (:mod:`hopper_sim.physics.slip`);
MuJoCo (RK4) integrates the stance from the exact touchdown state, with the foot (a mocap
body) placed at the closed-form touchdown point and the push-only spring tendon ``leg``.
Liftoff (leg back at l0, lengthening) is resolved inside the MuJoCo step in which it happens
(:func:`hopper_sim.physics.slip.resolve_liftoff`), so no event falls on a step boundary.

Perturbations: the terrain force F(foot) is constant over a stance (it is evaluated where the
foot stands) and is applied to the CoM through ``xfrc_applied``, exactly; it acts only in
stance. The noise nu is a horizontal liftoff impulse nu / t_flight, which moves the next
interstitial position by exactly nu. The stance thrust is :mod:`hopper_sim.physics.thrust`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from hopper_sim.errors import HopperSimError
from hopper_sim.physics import slip
from hopper_sim.physics import thrust as thrust_law
from hopper_sim.physics.hop_checks import (
    HopInputError,
    implausible,
    validate_inputs,
    validate_range,
)
from hopper_sim.physics.hop_checks import max_speed as max_speed  # re-exported
from hopper_sim.physics.model import HopperModel
from hopper_sim.physics.terrain import ForceField

#: Status names; index = the integer code used by the batched path.
STATUS_NAMES: tuple[str, ...] = (
    "ok",
    "no_touchdown",
    "no_liftoff",
    "ground",
    "unstable",
    "non_physical",
)
STATUS_CODES: dict[str, int] = {name: i for i, name in enumerate(STATUS_NAMES)}

#: Longest stance [s] before a hop fails with ``no_liftoff`` (a linear-spring stance of the
#: default model lasts about 0.2 s).
MAX_STANCE_TIME = 2.0
#: Samples of each ballistic phase in ``HopResult.com_path``.
PATH_SAMPLES = 16


class HopFailure(HopperSimError):
    """A hop failed; ``reason`` is one of :data:`STATUS_NAMES` other than ``"ok"``:

    * ``no_touchdown``: the leg would not be compressed at touchdown, or the flight after
      liftoff peaks below l0 so there is no next interstitial state (no next touchdown);
    * ``no_liftoff``: the leg did not return to l0 within :data:`MAX_STANCE_TIME`;
    * ``ground``: the CoM reached the ground (z <= 0) in stance;
    * ``unstable``: the integration produced a non-finite state or a MuJoCo warning;
    * ``non_physical``: the result is not physical (times out of order or negative, or a
      passive hop whose energy changed; :func:`hopper_sim.physics.hop_checks.implausible`).
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(f"{reason}: {message}")
        self.reason = reason
        self.message = message


@dataclass
class HopResult:
    """Outcome of one hop. Times [s] count from the interstitial state; positions [m],
    velocities [m/s], energies [J] (m |v|^2/2 + m g z at the interstitial states).

    On failure ``ok`` is False, ``status`` names the reason, ``message`` explains it, and the
    fields the hop did not reach are None.
    """

    ok: bool
    status: str
    message: str
    pos: np.ndarray
    vel: np.ndarray
    alpha: float
    beta: float
    energy_before: float
    touchdown_time: float
    touchdown_pos: np.ndarray
    touchdown_vel: np.ndarray
    foot: np.ndarray
    terrain_force: np.ndarray
    thrust_command: float
    noise: np.ndarray
    liftoff_time: float | None = None
    liftoff_pos: np.ndarray | None = None
    liftoff_vel: np.ndarray | None = None
    flight_time: float | None = None
    next_pos: np.ndarray | None = None
    next_vel: np.ndarray | None = None
    energy_after: float | None = None
    com_path: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    com_path_time: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def raise_for_status(self) -> HopResult:
        """Return self if the hop succeeded, else raise :class:`HopFailure`."""
        if not self.ok:
            raise HopFailure(self.status, self.message)
        return self

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (lists for vectors, None for what the hop did not reach)."""

        def vec(a: np.ndarray | None) -> list[float] | None:
            return None if a is None else [float(x) for x in a]

        def num(x: float | None) -> float | None:
            return None if x is None else float(x)

        return {
            "ok": bool(self.ok),
            "status": self.status,
            "message": self.message,
            "pos": vec(self.pos),
            "vel": vec(self.vel),
            "alpha": float(self.alpha),
            "beta": float(self.beta),
            "next_pos": vec(self.next_pos),
            "next_vel": vec(self.next_vel),
            "touchdown_time": num(self.touchdown_time),
            "liftoff_time": num(self.liftoff_time),
            "flight_time": num(self.flight_time),
            "foot": vec(self.foot),
            "touchdown_pos": vec(self.touchdown_pos),
            "touchdown_vel": vec(self.touchdown_vel),
            "liftoff_pos": vec(self.liftoff_pos),
            "liftoff_vel": vec(self.liftoff_vel),
            "energy_before": num(self.energy_before),
            "energy_after": num(self.energy_after),
            "terrain_force": vec(self.terrain_force),
            "noise": vec(self.noise),
            "thrust_command": float(self.thrust_command),
        }


def _as_hop_inputs(pos, vel, alpha, beta, noise):
    pos = np.atleast_2d(np.asarray(pos, dtype=float))
    vel = np.atleast_2d(np.asarray(vel, dtype=float))
    alpha = np.atleast_1d(np.asarray(alpha, dtype=float))
    beta = np.atleast_1d(np.asarray(beta, dtype=float))
    validate_inputs(pos, vel, alpha, beta)
    if pos.shape[0] != 1:
        raise HopInputError(f"simulate_hop takes one hop; pos has shape {pos.shape}")
    nu = np.zeros((1, 2)) if noise is None else np.atleast_2d(np.asarray(noise, dtype=float))
    if nu.shape != (1, 2) or not np.all(np.isfinite(nu)):
        raise HopInputError(f"noise must be a finite (2,) array, got {noise!r}")
    return pos, vel, alpha, beta, nu


@dataclass
class _Stance:
    status: str
    message: str
    steps: int
    com: np.ndarray | None = None  # last state with l < l0
    vel: np.ndarray | None = None
    path: list[tuple[float, float, float]] | None = None


def _run_stance(
    hm: HopperModel,
    data: mujoco.MjData,
    td: slip.Touchdown,
    force: np.ndarray,
    c: float,
    record: bool,
) -> _Stance:
    """Plain per-step Python loop over mj_step for one stance."""
    m = hm.model
    p = hm.params
    l0 = p.rest_length
    qa, da = hm.qpos_adr, hm.dof_adr
    mujoco.mj_resetData(m, data)
    data.qpos[qa] = td.com[0]
    data.qvel[da] = td.vel[0]
    data.mocap_pos[hm.foot_mocap] = td.foot[0]
    data.xfrc_applied[hm.com_body, :2] = force
    fx, fy, fz = (float(v) for v in td.foot[0])
    path = [tuple(td.com[0])] if record else None
    max_steps = math.ceil(MAX_STANCE_TIME / p.timestep)
    qpos, qvel, ctrl = data.qpos, data.qvel, data.ctrl
    act = hm.thrust_actuator
    ix, iy, iz = (int(i) for i in qa)
    jx, jy, jz = (int(i) for i in da)
    for n in range(max_steps):
        x, y, z = qpos[ix], qpos[iy], qpos[iz]
        vx, vy, vz = qvel[jx], qvel[jy], qvel[jz]
        if c != 0.0:
            length = math.sqrt((x - fx) ** 2 + (y - fy) ** 2 + (z - fz) ** 2)
            ldot = ((x - fx) * vx + (y - fy) * vy + (z - fz) * vz) / length
            ctrl[act] = c if c * ldot > 0.0 else 0.0
        mujoco.mj_step(m, data)
        nx, ny, nz = qpos[ix], qpos[iy], qpos[iz]
        if not (math.isfinite(nx) and math.isfinite(ny) and math.isfinite(nz)) or (
            data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0
        ):
            return _Stance("unstable", f"non-finite state after stance step {n + 1}", n + 1)
        if nz <= 0.0:
            return _Stance("ground", f"CoM reached the ground {n + 1} steps into stance", n + 1)
        if record:
            path.append((nx, ny, nz))
        if (nx - fx) ** 2 + (ny - fy) ** 2 + (nz - fz) ** 2 >= l0 * l0:
            if record:
                path.pop()
            return _Stance(
                "ok",
                "",
                n,
                com=np.array([[x, y, z]], dtype=float),
                vel=np.array([[vx, vy, vz]], dtype=float),
                path=path,
            )
    return _Stance("no_liftoff", f"leg not back at l0 after {MAX_STANCE_TIME} s of stance", n + 1)


def _record_descent(
    result: HopResult, p, pos: np.ndarray, vel: np.ndarray, td: slip.Touchdown
) -> np.ndarray:
    """Sample the ballistic descent into ``result.com_path`` (and its times); returns it."""
    ts = np.linspace(0.0, td.time[0], PATH_SAMPLES)
    start = np.array([[pos[0, 0], pos[0, 1], p.rest_length]])
    descent, _ = slip.ballistic(
        np.repeat(start, ts.size, 0), np.repeat(vel, ts.size, 0), ts, p.gravity
    )
    result.com_path, result.com_path_time = descent, ts
    return descent


def _record_whole_path(
    result: HopResult,
    p,
    descent: np.ndarray,
    st: _Stance,
    td: slip.Touchdown,
    p_lo: np.ndarray,
    fl,
    t_lo: float,
) -> None:
    """``result.com_path`` (and its times): the descent, the stance steps, the flight."""
    t_stance = td.time[0] + p.timestep * np.arange(len(st.path))
    ts = np.linspace(0.0, fl.duration[0], PATH_SAMPLES)
    fpos, _ = slip.ballistic(
        np.repeat(p_lo, ts.size, 0), np.repeat(fl.liftoff_vel, ts.size, 0), ts, p.gravity
    )
    result.com_path = np.concatenate([descent[:-1], np.asarray(st.path), fpos])
    result.com_path_time = np.concatenate([result.com_path_time[:-1], t_stance, t_lo + ts])


def _hop_with_command(
    hm: HopperModel,
    data: mujoco.MjData,
    pos: np.ndarray,
    vel: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    td: slip.Touchdown,
    force: np.ndarray,
    nu: np.ndarray,
    c: float,
    record: bool,
) -> HopResult:
    p = hm.params
    g = p.gravity
    e_before = float(hm.energy(p.rest_length, vel[0]))
    result = HopResult(
        ok=False,
        status="",
        message="",
        pos=pos[0].copy(),
        vel=vel[0].copy(),
        alpha=float(alpha[0]),
        beta=float(beta[0]),
        energy_before=e_before,
        touchdown_time=float(td.time[0]),
        touchdown_pos=td.com[0].copy(),
        touchdown_vel=td.vel[0].copy(),
        foot=td.foot[0].copy(),
        terrain_force=np.asarray(force, dtype=float).reshape(2).copy(),
        thrust_command=float(c),
        noise=nu[0].copy(),
    )
    descent = _record_descent(result, p, pos, vel, td) if record else None
    if not td.leg_rate[0] < 0.0:
        result.status = "no_touchdown"
        result.message = f"the leg is not compressed at touchdown (ldot = {td.leg_rate[0]:.4g} m/s)"
        return result
    st = _run_stance(hm, data, td, result.terrain_force, float(c), record)
    if st.status != "ok":
        result.status, result.message = st.status, st.message
        return result
    s, p_lo, v_lo = slip.resolve_liftoff(
        p, st.com, st.vel, td.foot, result.terrain_force[None], np.array([c]), p.timestep
    )
    t_lo = float(td.time[0] + st.steps * p.timestep + s[0])
    fl = slip.flight(p, p_lo, v_lo, nu)
    result.liftoff_time = t_lo
    result.liftoff_pos = p_lo[0]
    result.liftoff_vel = v_lo[0]
    if not np.isfinite(fl.duration[0]):
        apex = p_lo[0, 2] + max(v_lo[0, 2], 0.0) ** 2 / (2 * g)
        result.status = "no_touchdown"
        result.message = (
            f"the flight after liftoff peaks at z = {apex:.4f} m, below l0 = {p.rest_length} m: "
            "no next interstitial state"
        )
        return result
    result.ok, result.status = True, "ok"
    result.flight_time = float(fl.duration[0])
    result.liftoff_vel = fl.liftoff_vel[0]
    result.next_pos = fl.next_pos[0]
    result.next_vel = fl.next_vel[0]
    result.energy_after = float(hm.energy(p.rest_length, fl.next_vel[0]))
    passive = c == 0.0 and not np.any(result.terrain_force) and not np.any(nu)
    if implausible(
        *(np.array([x]) for x in (td.time[0], t_lo, result.flight_time, e_before)),
        np.array([result.energy_after]),
        np.array([passive]),
    )[0]:
        result.ok, result.status = False, "non_physical"
        result.message = (
            f"not a physical hop: touchdown at {td.time[0]:.6g} s, liftoff at {t_lo:.6g} s, "
            f"flight {result.flight_time:.6g} s, energy {e_before:.6g} -> "
            f"{result.energy_after:.6g} J"
        )
        return result
    if record:
        _record_whole_path(result, p, descent, st, td, p_lo, fl, t_lo)
    return result


def simulate_hop(
    model: HopperModel,
    pos: np.ndarray,
    vel: np.ndarray,
    alpha: float,
    beta: float,
    *,
    terrain: ForceField | None = None,
    noise: np.ndarray | None = None,
    thrust: bool = False,
    nominal_energy: float | None = None,
    thrust_command: float | None = None,
    record_path: bool = True,
    data: mujoco.MjData | None = None,
) -> HopResult:
    """Simulate one hop from the interstitial state (pos (2,) [m] at z = l0, vel (3,) [m/s],
    vz <= 0) with touchdown angles alpha (elevation, (0, pi/2]) and beta (azimuth relative to
    the heading of the horizontal velocity; heading 0 (+x) when that velocity is zero).

    Args:
        terrain: horizontal force field acting on the CoM in stance, or None.
        noise: nu (2,) [m], realised as the liftoff impulse nu / t_flight, or None.
        thrust: regulate the hop's energy to ``nominal_energy`` (default: the energy at the
            hop's start) with the stance thrust (:mod:`hopper_sim.physics.thrust`).
        thrust_command: a fixed thrust command c [N s/m] instead of the regulator.
        record_path: fill ``com_path`` / ``com_path_time`` (for logging).
        data: an MjData of ``model`` to reuse.

    Returns:
        The :class:`HopResult`; a failed hop has ``ok`` False (``raise_for_status`` raises).

    Raises:
        HopInputError: malformed input.
    """
    pos, vel, alpha_a, beta_a, nu = _as_hop_inputs(pos, vel, alpha, beta, noise)
    p = model.params
    validate_range(p, pos, vel, beta_a, nu)
    data = data if data is not None else model.make_data()
    td = slip.touchdown(p, pos, vel, alpha_a, beta_a)
    force = np.zeros(2) if terrain is None else terrain.force(td.foot[:, :2])[0]

    def run(c: float, record: bool) -> HopResult:
        return _hop_with_command(model, data, pos, vel, alpha_a, beta_a, td, force, nu, c, record)

    if thrust_command is not None:
        return run(float(thrust_command), record_path)
    if not thrust:
        return run(0.0, record_path)
    e_before = model.energy(p.rest_length, vel)
    e_nom = e_before if nominal_energy is None else np.array([float(nominal_energy)])

    def run_array(c: np.ndarray) -> tuple[np.ndarray, HopResult]:
        r = run(float(c[0]), False)
        return np.array([r.energy_after if r.ok else np.nan]), r

    c, last = thrust_law.regulate(
        run_array,
        e_before,
        e_nom,
        thrust_law.integral_estimate(p, td.leg_rate),
        p.thrust_limit,
    )
    return run(float(c[0]), True) if record_path else last
