"""Many hops at once, on all cores, through :class:`mujoco.batch.Batch`.

The same hop as :func:`hopper_sim.physics.hop.simulate_hop` (closed-form descent and flight, MuJoCo
RK4 stance from the exact touchdown state, liftoff resolved inside its step), vectorised over
N hops: the hops are packed K to a simulation (K copies of the hopper in one model, which
MuJoCo steps for little more than the cost of one), all stances advance together one step at
a time (``Batch.step`` on the simulations with a hop still in stance, on ``nthread``
threads), and each hop leaves at its own liftoff. Terrain
forces and noise are per hop; the thrust regulator (:mod:`hopper_sim.physics.thrust`) runs on the
whole batch, re-simulating only the hops whose command changed.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import mujoco.batch
import numpy as np

from hopper_sim.physics import slip
from hopper_sim.physics import thrust as thrust_law
from hopper_sim.physics.hop import MAX_STANCE_TIME, STATUS_CODES, STATUS_NAMES
from hopper_sim.physics.hop_checks import (
    HopInputError,
    implausible,
    validate_inputs,
    validate_range,
)
from hopper_sim.physics.model import HopperModel, ReplicatedModel
from hopper_sim.physics.terrain import ForceField

_OK = STATUS_CODES["ok"]
_NO_TOUCHDOWN = STATUS_CODES["no_touchdown"]
_NO_LIFTOFF = STATUS_CODES["no_liftoff"]
_GROUND = STATUS_CODES["ground"]
_UNSTABLE = STATUS_CODES["unstable"]
_NON_PHYSICAL = STATUS_CODES["non_physical"]

#: Hops stepped together in one MjData (copies of the hopper in one model, see
#: :meth:`HopperModel.replicated`): about 3.5x less CPU per hop-step than one per MjData.
DEFAULT_HOPS_PER_SIM = 16
#: A finished copy's foot is moved this far [m] above its CoM, inside the leg's dead band.
_INERT_HEIGHT = 1e4


@dataclass
class BatchHopResult:
    """Outcome of N hops. ``status`` holds integer codes into ``status_names``
    (0 = ``"ok"``). Rows of failed hops hold NaN in the fields the hop did not reach.
    Units as in :class:`hopper_sim.physics.hop.HopResult`; times count from the interstitial state.
    """

    ok: np.ndarray  # (N,) bool
    status: np.ndarray  # (N,) int
    next_pos: np.ndarray  # (N, 2)
    next_vel: np.ndarray  # (N, 3)
    touchdown_time: np.ndarray  # (N,)
    liftoff_time: np.ndarray  # (N,)
    flight_time: np.ndarray  # (N,) liftoff to next interstitial state
    foot: np.ndarray  # (N, 3)
    liftoff_pos: np.ndarray  # (N, 3)
    liftoff_vel: np.ndarray  # (N, 3) after the noise impulse
    energy_before: np.ndarray  # (N,)
    energy_after: np.ndarray  # (N,)
    terrain_force: np.ndarray  # (N, 2)
    thrust_command: np.ndarray  # (N,)
    status_names: tuple[str, ...] = STATUS_NAMES

    def status_name(self, i: int) -> str:
        """Name of hop i's status."""
        return self.status_names[int(self.status[i])]

    def __len__(self) -> int:
        return int(self.ok.shape[0])


@dataclass
class _StanceBatch:
    status: np.ndarray
    steps: np.ndarray
    com: np.ndarray
    vel: np.ndarray


@dataclass
class _Copies:
    """The K-copy simulations of one stance batch: which hop each copy holds and its state.

    Attributes:
        rows: ``(G, K)`` the hop row in each copy, -1 for an unused copy.
        active: ``(G, K)`` whether the copy is still in stance.
        foot: ``(G, K, 3)`` foot positions [m] (an inert copy's 10 km above its CoM).
        c: ``(G, K)`` thrust commands [N s/m].
    """

    rows: np.ndarray
    active: np.ndarray
    foot: np.ndarray
    c: np.ndarray


def _load_copies(
    rep: ReplicatedModel,
    views: dict[str, np.ndarray],
    rows: np.ndarray,
    td: slip.Touchdown,
    force: np.ndarray,
    command: np.ndarray,
    g: int,
    k: int,
    rest_length: float,
) -> _Copies:
    """Place hop ``rows[j]`` in copy ``j % k`` of simulation ``j // k`` (touchdown state,
    foot, terrain force), the unused copies inert; returns what the loop tracks."""
    n = rows.size
    far = np.array([0.0, 0.0, _INERT_HEIGHT])
    slot_rows = np.full(g * k, -1)
    slot_rows[:n] = rows
    slot_rows = slot_rows.reshape(g, k)
    com0 = np.tile([0.0, 0.0, rest_length], (g * k, 1))
    vel0 = np.zeros((g * k, 3))
    foot = com0 + far
    f_ext = np.zeros((g * k, 2))
    c = np.zeros(g * k)
    com0[:n], vel0[:n], foot[:n] = td.com[rows], td.vel[rows], td.foot[rows]
    f_ext[:n], c[:n] = force[rows], command[rows]
    com0, vel0, foot = com0.reshape(g, k, 3), vel0.reshape(g, k, 3), foot.reshape(g, k, 3)
    views["qpos"][:, rep.qpos_adr] = com0
    views["qvel"][:, rep.dof_adr] = vel0
    views["mocap_pos"][:, rep.foot_mocap] = foot
    views["xfrc_applied"][:, rep.com_body, :2] = f_ext.reshape(g, k, 2)
    return _Copies(rows=slot_rows, active=slot_rows >= 0, foot=foot, c=c.reshape(g, k))


def _retire(
    rep: ReplicatedModel,
    views: dict[str, np.ndarray],
    copies: _Copies,
    out: _StanceBatch,
    step: int,
    s_abs: np.ndarray,
    ki: np.ndarray,
    status: np.ndarray,
    q0: np.ndarray,
    v0: np.ndarray,
    q1: np.ndarray,
) -> np.ndarray:
    """Record the copies ``(s_abs, ki)`` whose stance ended at ``step`` with ``status`` (the
    state before the step), and make them inert; returns their hop rows."""
    r = copies.rows[s_abs, ki]
    out.status[r] = status
    out.steps[r] = step
    out.com[r] = q0
    out.vel[r] = v0
    copies.active[s_abs, ki] = False
    here = np.where(np.isfinite(q1), q1, 0.0) + np.array([0.0, 0.0, _INERT_HEIGHT])
    copies.foot[s_abs, ki] = here
    views["mocap_pos"][s_abs, rep.foot_mocap[ki]] = here
    views["xfrc_applied"][s_abs, rep.com_body[ki], :] = 0.0
    views["ctrl"][s_abs, rep.thrust_actuator[ki]] = 0.0
    return r


def _run_stances(
    model: HopperModel,
    rows: np.ndarray,
    td: slip.Touchdown,
    force: np.ndarray,
    command: np.ndarray,
    out: _StanceBatch,
    progress: Callable[[int], None] | None,
    nthread: int,
    hops_per_sim: int,
) -> None:
    """Integrate the stances of hops ``rows`` into ``out``.

    Hop ``rows[j]`` runs in copy ``j % K`` of simulation ``j // K`` of a
    :class:`mujoco.batch.Batch` over the K-copy model (:meth:`HopperModel.replicated`). A
    simulation steps while any of its copies is in stance; a copy that has finished is made
    inert (foot moved 10 km above it, so its push-only leg is slack; no terrain force or
    thrust) so that it cannot disturb its neighbours.
    """
    p = model.params
    l0sq = p.rest_length**2
    n = rows.size
    k = max(1, min(int(hops_per_sim), n))
    rep = model.replicated(k)
    g = -(-n // k)
    batch = mujoco.batch.Batch(rep.model, g, nthread)
    views = {name: batch.bind(name) for name in ("qpos", "qvel", "mocap_pos", "xfrc_applied")}
    views["ctrl"] = batch.bind("ctrl")
    batch.reset()
    copies = _load_copies(rep, views, rows, td, force, command, g, k, p.rest_length)
    qpos, qvel, ctrl = views["qpos"], views["qvel"], views["ctrl"]
    active, foot, c = copies.active, copies.foot, copies.c
    use_thrust = bool(np.any(c != 0.0))

    sims = np.arange(g)  # simulations with a copy still in stance
    max_steps = math.ceil(MAX_STANCE_TIME / p.timestep)
    for step in range(max_steps):
        if sims.size == 0:
            break
        q0 = qpos[sims][:, rep.qpos_adr]
        v0 = qvel[sims][:, rep.dof_adr]
        if use_thrust:
            ldot = np.einsum("skj,skj->sk", q0 - foot[sims], v0)  # its sign only
            on = active[sims] & (c[sims] * ldot > 0.0)
            ctrl[sims[:, None], rep.thrust_actuator] = np.where(on, c[sims], 0.0)
        batch.step(None if sims.size == g else sims, 1)
        q1 = qpos[sims][:, rep.qpos_adr]
        d1 = q1 - foot[sims]
        warned = batch.warning[sims][:, :, 1].sum(axis=1) > 0
        bad = ~np.all(np.isfinite(q1), axis=2) | warned[:, None]
        ground = ~bad & (q1[..., 2] <= 0.0)
        lifted = ~bad & ~ground & (np.einsum("skj,skj->sk", d1, d1) >= l0sq)
        finished = active[sims] & (bad | ground | lifted)
        if finished.any():
            si, ki = np.nonzero(finished)
            status = np.select([bad[si, ki], ground[si, ki]], [_UNSTABLE, _GROUND], _OK)
            r = _retire(
                rep, views, copies, out, step, sims[si], ki, status,
                q0[si, ki], v0[si, ki], q1[si, ki],
            )  # fmt: skip
            if progress is not None:
                progress(int(r.size))
            sims = sims[active[sims].any(axis=1)]
    if active.any():
        r = copies.rows[active]
        out.status[r] = _NO_LIFTOFF
        if progress is not None:
            progress(int(r.size))


def _as_batch_inputs(vel, alpha, beta, pos, noise):
    vel = np.asarray(vel, dtype=float)
    if vel.ndim != 2:
        raise HopInputError(f"simulate_hops: vel must have shape (N, 3), got {vel.shape}")
    n = vel.shape[0]
    pos = np.zeros((n, 2)) if pos is None else np.asarray(pos, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    validate_inputs(pos, vel, alpha, beta, what="simulate_hops")
    if noise is not None:
        noise = np.asarray(noise, dtype=float)
        if noise.shape != (n, 2) or not np.all(np.isfinite(noise)):
            raise HopInputError(f"simulate_hops: noise must be finite (N, 2), got {noise.shape}")
    return vel, alpha, beta, pos, noise


def simulate_hops(
    model: HopperModel,
    vel: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    *,
    pos: np.ndarray | None = None,
    terrain: ForceField | None = None,
    noise: np.ndarray | None = None,
    thrust: bool = False,
    nominal_energy: np.ndarray | float | None = None,
    thrust_command: np.ndarray | None = None,
    nthread: int | None = None,
    progress: Callable[[int], None] | None = None,
    hops_per_sim: int = DEFAULT_HOPS_PER_SIM,
) -> BatchHopResult:
    """Simulate N independent hops (conventions of :func:`hopper_sim.physics.hop.simulate_hop`).

    Args:
        vel: interstitial velocities (N, 3) [m/s], vz <= 0.
        alpha, beta: touchdown angles (N,) [rad]; beta relative to each hop's heading
            (heading 0, +x, when the horizontal speed is zero).
        pos: interstitial positions (N, 2) [m] (default 0; matters only with ``terrain``).
        terrain: force field evaluated at each hop's foot, or None.
        noise: per-hop nu (N, 2) [m], or None.
        thrust: regulate each hop's energy to ``nominal_energy`` ((N,) or scalar [J];
            default each hop's starting energy).
        thrust_command: fixed thrust commands (N,) [N s/m] instead of the regulator.
        nthread: worker threads (default: all CPUs).
        progress: called with the number of hops that just finished their stance (per
            pass of the thrust regulator), e.g. ``tqdm.update``.
        hops_per_sim: hops stepped together in one MjData (copies of the hopper in one
            model); 1 gives one MjData per hop.

    Returns:
        A :class:`BatchHopResult`.

    Raises:
        HopInputError: malformed input (names the argument and row).
    """
    vel, alpha, beta, pos, noise = _as_batch_inputs(vel, alpha, beta, pos, noise)
    p = model.params
    validate_range(p, pos, vel, beta, noise, what="simulate_hops")
    n = vel.shape[0]
    td = slip.touchdown(p, pos, vel, alpha, beta)
    force = np.zeros((n, 2)) if terrain is None else terrain.force(td.foot[:, :2])
    e_before = model.energy(p.rest_length, vel)
    nthread = int(nthread) if nthread else (os.cpu_count() or 1)
    stance = _StanceBatch(
        status=np.full(n, _NO_TOUCHDOWN),
        steps=np.zeros(n, dtype=int),
        com=np.full((n, 3), np.nan),
        vel=np.full((n, 3), np.nan),
    )
    compressing = td.leg_rate < 0.0
    last_c: np.ndarray | None = None

    def run(c: np.ndarray) -> tuple[np.ndarray, BatchHopResult]:
        nonlocal last_c
        rows = np.flatnonzero(compressing if last_c is None else compressing & (c != last_c))
        last_c = c.copy()
        if rows.size:
            _run_stances(model, rows, td, force, c, stance, progress, nthread, hops_per_sim)
        res = _finish(model, td, force, noise, c, e_before, stance)
        return res.energy_after, res

    if thrust_command is not None:
        c = np.broadcast_to(np.asarray(thrust_command, dtype=float), (n,)).copy()
        return run(c)[1]
    if not thrust:
        return run(np.zeros(n))[1]
    e_nom = e_before if nominal_energy is None else np.broadcast_to(nominal_energy, (n,))
    _, res = thrust_law.regulate(
        run, e_before, e_nom, thrust_law.integral_estimate(p, td.leg_rate), p.thrust_limit
    )
    return res


def _finish(
    model: HopperModel,
    td: slip.Touchdown,
    force: np.ndarray,
    noise: np.ndarray | None,
    c: np.ndarray,
    e_before: np.ndarray,
    stance: _StanceBatch,
) -> BatchHopResult:
    """Liftoff resolution and closed-form flight for the hops whose stance ended in liftoff."""
    p = model.params
    n = td.time.shape[0]
    status = stance.status.copy()
    lift = np.flatnonzero(status == _OK)
    liftoff_time = np.full(n, np.nan)
    liftoff_pos = np.full((n, 3), np.nan)
    liftoff_vel = np.full((n, 3), np.nan)
    flight_time = np.full(n, np.nan)
    next_pos = np.full((n, 2), np.nan)
    next_vel = np.full((n, 3), np.nan)
    if lift.size:
        s, p_lo, v_lo = slip.resolve_liftoff(
            p, stance.com[lift], stance.vel[lift], td.foot[lift], force[lift], c[lift], p.timestep
        )
        fl = slip.flight(p, p_lo, v_lo, None if noise is None else noise[lift])
        liftoff_time[lift] = td.time[lift] + stance.steps[lift] * p.timestep + s
        liftoff_pos[lift] = p_lo
        liftoff_vel[lift] = fl.liftoff_vel
        low = ~np.isfinite(fl.duration)
        status[lift[low]] = _NO_TOUCHDOWN
        good = lift[~low]
        flight_time[good] = fl.duration[~low]
        next_pos[good] = fl.next_pos[~low]
        next_vel[good] = fl.next_vel[~low]
    energy_after = np.where(status == _OK, model.energy(p.rest_length, next_vel), np.nan)
    passive = (c == 0.0) & ~np.any(force != 0.0, axis=1)
    if noise is not None:
        passive &= ~np.any(noise != 0.0, axis=1)
    ok = status == _OK
    wrong = ok & implausible(td.time, liftoff_time, flight_time, e_before, energy_after, passive)
    status[wrong] = _NON_PHYSICAL
    energy_after[wrong] = np.nan
    return BatchHopResult(
        ok=status == _OK,
        status=status,
        next_pos=next_pos,
        next_vel=next_vel,
        touchdown_time=td.time.copy(),
        liftoff_time=liftoff_time,
        flight_time=flight_time,
        foot=td.foot.copy(),
        liftoff_pos=liftoff_pos,
        liftoff_vel=liftoff_vel,
        energy_before=e_before,
        energy_after=energy_after,
        terrain_force=force,
        thrust_command=c.copy(),
    )
