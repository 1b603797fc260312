"""What the controller's landing error depends on: departure position, action, incoming
velocity (the measurement behind the landing-error model, :mod:`planner.gp.landing`).

Usage: python benchmarks/error_factors.py [--scenario a] [--states 600] [--runs 6] [--seed 0]

Departure states like the navigation loop's: velocities drawn from the departures of
``--runs`` navigation runs, positions uniform over the inner 11 x 11 m of the world. From
each state all eight actions are solved by the controller and hopped in MuJoCo (no landing
noise) twice: with the world's terrain field and without it. Prints, for the hops the
controller executes as requested (cost below the backup threshold):

* the controller's own error (terrain off) per action, and along/across the hop by the
  incoming heading relative to the action (forward, side, back);
* the terrain's part (on - off): its slope against the stance force at the departure, and
  its correlation between actions from the same state (per axis);
* the residual per action and axis after a constant plus the force's linear effect, and after
  adding the incoming velocity and the position in the cell as regressors, with its tails
  (quantiles in units of its std).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from hopper_sim.controller.simulator import nominal_energy
from hopper_sim.experiments.audit import collect_run_data
from hopper_sim.navigation.runner import NavigationRunner
from hopper_sim.physics.batch import simulate_hops
from planner.imdp.grid import ACTION_OFFSETS, ACTIONS
from planner.scenario import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="a")
    ap.add_argument("--states", type=int, default=600)
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    np.set_printoptions(precision=3, suppress=True, linewidth=120)
    runner = NavigationRunner(load_scenario(args.scenario))
    env, grid = runner.env, runner.grid
    t0 = time.perf_counter()
    vel_pool = np.vstack(
        [collect_run_data(runner, args.seed + k).velocities for k in range(args.runs)]
    )
    rng = np.random.default_rng(args.seed)
    n = args.states
    vel = vel_pool[rng.integers(len(vel_pool), size=n)]
    pos = rng.uniform(2.0, grid.nx - 2.0, size=(n, 2))
    target = grid.target_centres[grid.locate(pos)]  # (n, 8, 2)
    alpha, beta, cost = (np.empty((n, 8)) for _ in range(3))
    for k in range(n):
        sol, _, _ = env.controller.solve_all(pos[k], vel[k], target[k])
        alpha[k], beta[k], cost[k] = sol.alpha, sol.beta, sol.cost
    energy = nominal_energy(env.model, env.controller.steady.speed)
    land = {}
    for name, terrain in (("on", env.terrain), ("off", None)):
        res = simulate_hops(
            env.model, np.repeat(vel, 8, 0), alpha.ravel(), beta.ravel(),
            pos=np.repeat(pos, 8, 0), terrain=terrain, thrust=True, nominal_energy=energy,
        )  # fmt: skip
        land[name] = np.where(res.ok[:, None], res.next_pos, np.nan).reshape(n, 8, 2)
    print(
        f"{n} states from {len(vel_pool)} run departures, {16 * n} hops "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    ok = (cost <= env.controller.backup_threshold) & np.isfinite(land["on"]).all(-1)
    ok &= np.isfinite(land["off"]).all(-1)
    e_on, e_off = land["on"] - target, land["off"] - target
    e_terr = e_on - e_off
    unit = ACTION_OFFSETS / np.abs(ACTION_OFFSETS).sum(1, keepdims=True)
    psi = np.arctan2(vel[:, 1], vel[:, 0])
    rel = (np.arctan2(unit[:, 1], unit[:, 0])[None, :] - psi[:, None] + np.pi) % (2 * np.pi) - np.pi
    print("\ncontroller's own error (terrain off), per action: mean (x, y), std (x, y) [m]")
    for a in range(8):
        m = ok[:, a]
        print(f"  {ACTIONS[a]}: {e_off[m, a].mean(0)} {e_off[m, a].std(0)}  ({m.sum()} hops)")
    along = (e_off * unit[None]).sum(-1)
    cls = np.digitize(np.abs(rel), [np.pi / 4, 3 * np.pi / 4])
    print("along the hop by incoming heading relative to the action: mean, std [m]")
    for c, name in enumerate(("forward", "side", "back")):
        for length in (1, 2):
            m = ok & (cls == c) & (np.abs(ACTION_OFFSETS).sum(1) == length)[None, :]
            print(
                f"  {name:7s} {length}-cell: {along[m].mean():+.3f} {along[m].std():.3f} "
                f"({m.sum()})"
            )
    force = env.terrain.force(pos) if env.terrain is not None else np.zeros_like(pos)
    print("\nterrain's part (on - off) against the stance force at the departure: slope [mm/N]")
    for a in range(8):
        m = ok[:, a]
        slope = [np.polyfit(force[m, d], e_terr[m, a, d], 1)[0] * 1e3 for d in range(2)]
        print(f"  {ACTIONS[a]}: x {slope[0]:.2f}, y {slope[1]:.2f}; std {e_terr[m, a].std(0)} m")
    both = ok.all(axis=1)
    for d, axis in enumerate("xy"):
        corr = np.corrcoef(e_terr[both, :, d].T)
        coupled = np.abs(ACTION_OFFSETS[:, d]) <= 1
        cc = corr[np.ix_(coupled, coupled)][~np.eye(coupled.sum(), dtype=bool)]
        cu = corr[np.ix_(~coupled, np.ones(8, bool))].ravel()
        cu = cu[cu < 0.999]
        print(
            f"  axis {axis}: correlation between actions, among those moving <= 1 cell along "
            f"it: {cc.min():.2f} .. {cc.max():.2f} (mean {cc.mean():.2f}); of a two-cell hop "
            f"along it with the others: {cu.min():.2f} .. {cu.max():.2f}"
        )
    print("\nresidual per action and axis [m]: after constant + force, after adding velocity "
          "and in-cell offset; tails of the first (along the hop, quantiles / std)")  # fmt: skip
    off = pos - (np.floor(pos) + 0.5)
    for a in range(8):
        m = ok[:, a]
        base = np.column_stack([np.ones(m.sum()), force[m]])
        more = np.column_stack([base, vel[m], np.cos(rel[m, a]), np.sin(rel[m, a]), off[m]])
        res1, res2 = [], []
        for d in range(2):
            y = e_on[m, a, d]
            r1 = y - base @ np.linalg.lstsq(base, y, rcond=None)[0]
            r2 = y - more @ np.linalg.lstsq(more, y, rcond=None)[0]
            res1.append(r1.std())
            res2.append(r2.std())
            if ACTION_OFFSETS[a, d] != 0:
                q = np.quantile(
                    np.sign(ACTION_OFFSETS[a, d]) * r1 / r1.std(), [0.001, 0.01, 0.99, 0.999]
                )
        print(f"  {ACTIONS[a]}: {np.round(res1, 3)} -> {np.round(res2, 3)}; tails {np.round(q, 2)}")


if __name__ == "__main__":
    main()
