"""Endurance: 1,000 consecutive hops around a closed square route with the terrain force
field, landing noise and stance thrust all on.

Steering (a simple proportional rule built on exact SLIP facts, computed here):

* nominal gait: the steady hop with interstitial velocity (V_H, 0, V_Z); its touchdown angle
  alpha* is the fixed point of the pure-SLIP hop map (vz_next = vz), ``hopper_sim.physics.gait``;
* alpha = alpha* + K (vz - V_Z) with K = -(d vz_next / d vz) / (d vz_next / d alpha), the
  deadbeat gain of the linearised return map (which is unstable with alpha fixed);
* beta = clip(-K_BETA * e, -BETA_MAX, BETA_MAX), e the heading error towards the current
  corner (a hop turns the velocity by about -beta at this gait);
* the thrust regulates each hop's energy to the nominal gait's energy.

Prints failures (must be 0), the interstitial speed range against nominal (must stay within
+/-10 %), the horizontal speed range, the energy residual, thrust commands, laps, and the
landing shift caused by the terrain (the same hop with and without the field).

    python benchmarks/endurance.py [--hops 1000] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from hopper_sim.physics.gait import steady_gait
from hopper_sim.physics.hop import simulate_hop
from hopper_sim.physics.model import HopperModel
from hopper_sim.physics.noise import sample_model_noise
from hopper_sim.physics.terrain import TerrainField

# Nominal interstitial velocity [m/s]: 1.6 m hops with an apex of 1.46 m, so that a flight
# lasts long enough for the noise impulse (nu / t_flight) to stay moderate.
V_H, V_Z = 2.0, -3.0
SIDE = 8.0  # square route side [m]
SWITCH = 1.2  # switch to the next corner within this distance [m]
K_BETA, BETA_MAX = 0.6, 0.3


def deadbeat_gain(model: HopperModel, alpha0: float, h: float = 1e-4) -> float:
    speed2 = V_H**2 + V_Z**2

    def vz_next(vz: float, a: float) -> float:
        vel = [np.sqrt(speed2 - vz * vz), 0.0, vz]
        return simulate_hop(model, [0, 0], vel, a, 0.0, record_path=False).next_vel[2]

    d_vz = (vz_next(V_Z + h, alpha0) - vz_next(V_Z - h, alpha0)) / (2 * h)
    d_a = (vz_next(V_Z, alpha0 + h) - vz_next(V_Z, alpha0 - h)) / (2 * h)
    return -d_vz / d_a, d_vz


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hops", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    model = HopperModel.load()
    terrain = TerrainField.for_model(model, args.seed)
    rng = np.random.default_rng(args.seed)
    noise = sample_model_noise(model, rng, args.hops)
    alpha0 = steady_gait(model, V_H, V_Z).alpha
    gain, multiplier = deadbeat_gain(model, alpha0)
    e_nom = float(model.energy(model.params.rest_length, np.array([V_H, 0.0, V_Z])))
    speed_nom = float(np.hypot(V_H, V_Z))
    corners = np.array([[1.0, 1.0], [1.0 + SIDE, 1.0], [1.0 + SIDE, 1.0 + SIDE], [1.0, 1.0 + SIDE]])

    pos, vel = corners[0].copy(), np.array([V_H, 0.0, V_Z])
    target, laps = 1, 0
    speeds, hspeeds, residuals, commands, shifts = [], [], [], [], []
    failures: list[str] = []
    t0 = time.perf_counter()
    for k in tqdm(range(args.hops), desc="hops", unit="hop"):
        to_corner = corners[target] - pos
        if np.linalg.norm(to_corner) < SWITCH:
            target = (target + 1) % 4
            laps += target == 1
            to_corner = corners[target] - pos
        err = np.angle(
            np.exp(1j * (np.arctan2(to_corner[1], to_corner[0]) - np.arctan2(vel[1], vel[0])))
        )
        beta = float(np.clip(-K_BETA * err, -BETA_MAX, BETA_MAX))
        alpha = float(np.clip(alpha0 + gain * (vel[2] - V_Z), np.deg2rad(60), np.deg2rad(88)))
        hop = simulate_hop(
            model,
            pos,
            vel,
            alpha,
            beta,
            terrain=terrain,
            noise=noise[k],
            thrust=True,
            nominal_energy=e_nom,
            record_path=False,
        )
        if not hop.ok:
            failures.append(f"hop {k}: {hop.status}: {hop.message}")
            break
        if k % 10 == 0:  # landing shift caused by the terrain: the same hop without the field
            free = simulate_hop(
                model,
                pos,
                vel,
                alpha,
                beta,
                noise=noise[k],
                thrust=True,
                nominal_energy=e_nom,
                record_path=False,
            )
            if free.ok:
                shifts.append(np.linalg.norm(hop.next_pos - free.next_pos))
        pos, vel = hop.next_pos, hop.next_vel
        speeds.append(np.linalg.norm(vel))
        hspeeds.append(np.linalg.norm(vel[:2]))
        residuals.append(hop.energy_after / e_nom - 1.0)
        commands.append(hop.thrust_command)
    wall = time.perf_counter() - t0

    speeds, hspeeds = np.array(speeds), np.array(hspeeds)
    print(
        f"model {model.param_hash()}  terrain seed {args.seed}  amplitude "
        f"{terrain.amplitude:.0f} N  length scale {terrain.lengthscale:.1f} m"
    )
    print(
        f"nominal gait: v = ({V_H}, 0, {V_Z}) m/s, |v| = {speed_nom:.4f} m/s, "
        f"alpha* = {np.rad2deg(alpha0):.3f} deg, open-loop multiplier {multiplier:.3f}, "
        f"K = {gain:.4f} rad s/m"
    )
    nominal = simulate_hop(model, [0, 0], [V_H, 0, V_Z], alpha0, 0.0, record_path=False)
    print(
        f"nominal hop: {nominal.next_pos[0]:.3f} m, apex "
        f"{model.params.rest_length + V_Z**2 / (2 * model.params.gravity):.3f} m, "
        f"flight (liftoff to interstitial) {nominal.flight_time:.3f} s"
    )
    print(f"hops completed        {len(speeds)} / {args.hops}   failures {len(failures)}")
    for f in failures:
        print("  " + f)
    print(f"laps of the {SIDE:.0f} m square  {laps}")
    print(
        f"|v| / nominal         min {speeds.min() / speed_nom:.6f}"
        f"  max {speeds.max() / speed_nom:.6f}"
        f"  (within +/-10 %: {bool(np.all(np.abs(speeds / speed_nom - 1) <= 0.1))})"
    )
    print(
        f"|v_h| / nominal       min {hspeeds.min() / V_H:.4f}  max {hspeeds.max() / V_H:.4f}"
        f"  mean {hspeeds.mean() / V_H:.4f}"
    )
    print(f"energy residual       max |E/E_nom - 1| = {np.abs(residuals).max():.2e}")
    print(
        f"thrust command        min {min(commands):.1f}  max {max(commands):.1f}  "
        f"mean |c| {np.mean(np.abs(commands)):.1f} N s/m (limit {model.params.thrust_limit:.0f})"
    )
    if shifts:
        sh = np.array(shifts)
        print(
            f"terrain landing shift median {np.median(sh):.3f} m  p90 {np.quantile(sh, 0.9):.3f} m"
            f"  max {sh.max():.3f} m  ({sh.size} hops)"
        )
    print(f"wall time {wall:.1f} s ({len(speeds) / wall:.0f} hops/s, single-hop path)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
