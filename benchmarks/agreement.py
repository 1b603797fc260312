"""Agreement of the MuJoCo hop with the exact reference (perturbations, noise, thrust off).

Draws random hops (interstitial speed 2-7 m/s in a random direction, vertical velocity -0.2 to
-3 m/s, alpha in [pi/4, pi/2], beta in [-pi/2, pi/2]) until the exact reference has completed
``--hops`` of them (default 200), simulates all draws with the batched MuJoCo path and the
completed ones also with the single-hop path, and prints the error table against the targets
(next interstitial position <= 1e-4 m, velocity <= 1e-4 m/s, energy change <= 1e-5 relative
per hop), plus how often MuJoCo and the reference agree on the hop's status.

    python benchmarks/agreement.py [--hops 200] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from hopper_sim.physics.batch import simulate_hops
from hopper_sim.physics.hop import simulate_hop
from hopper_sim.physics.model import HopperModel
from hopper_sim.physics.reference import reference_hop

TARGETS = {"position [m]": 1e-4, "velocity [m/s]": 1e-4, "energy change [rel]": 1e-5}


def draw(rng: np.random.Generator, n: int):
    speed = rng.uniform(2.0, 7.0, n)
    heading = rng.uniform(0.0, 2.0 * np.pi, n)
    vel = np.column_stack(
        [speed * np.cos(heading), speed * np.sin(heading), rng.uniform(-3.0, -0.2, n)]
    )
    return vel, rng.uniform(np.pi / 4, np.pi / 2, n), rng.uniform(-np.pi / 2, np.pi / 2, n)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hops", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    model = HopperModel.load()
    rng = np.random.default_rng(args.seed)

    vels, alphas, betas, refs = [], [], [], []
    completed = 0
    with tqdm(total=args.hops, desc="reference hops completed", unit="hop") as bar:
        while completed < args.hops:
            vel, alpha, beta = draw(rng, 1)
            ref = reference_hop(model.params, np.zeros(2), vel[0], alpha[0], beta[0])
            vels.append(vel[0])
            alphas.append(alpha[0])
            betas.append(beta[0])
            refs.append(ref)
            if ref.ok:
                completed += 1
                bar.update(1)
    vel, alpha, beta = np.array(vels), np.array(alphas), np.array(betas)
    ok_ref = np.array([r.ok for r in refs])
    batch = simulate_hops(model, vel, alpha, beta)
    status_ref = np.array([r.status for r in refs])
    status_sim = np.array([batch.status_name(i) for i in range(len(batch))])

    rows = {}
    idx = np.flatnonzero(ok_ref)
    ref_pos = np.array([refs[i].next_pos for i in idx])
    ref_vel = np.array([refs[i].next_vel for i in idx])
    single = [
        simulate_hop(model, np.zeros(2), vel[i], alpha[i], beta[i], record_path=False)
        for i in tqdm(idx, desc="single-hop path", unit="hop")
    ]
    for name, pos, v, e0, e1, ok in (
        (
            "batched",
            batch.next_pos[idx],
            batch.next_vel[idx],
            batch.energy_before[idx],
            batch.energy_after[idx],
            batch.ok[idx],
        ),
        (
            "single",
            np.array([s.next_pos if s.ok else [np.nan] * 2 for s in single]),
            np.array([s.next_vel if s.ok else [np.nan] * 3 for s in single]),
            np.array([s.energy_before for s in single]),
            np.array([s.energy_after if s.ok else np.nan for s in single]),
            np.array([s.ok for s in single]),
        ),
    ):
        rows[name] = (
            ok.sum(),
            np.abs(pos - ref_pos).max(axis=1),
            np.abs(v - ref_vel).max(axis=1),
            np.abs(e1 / e0 - 1.0),
        )

    print(f"model {model.param_hash()}  dt {model.params.timestep} s  seed {args.seed}")
    print(
        f"drawn {len(refs)} hops; the reference completed {ok_ref.sum()}; "
        f"MuJoCo status equals the reference's on {np.mean(status_sim == status_ref):.1%} "
        f"of all draws"
    )
    print(
        f"{'path':8s} {'quantity':22s} {'max':>10s} {'p99':>10s} {'median':>10s} "
        f"{'target':>8s} {'ratio':>7s}"
    )
    passed = True
    for name, (n_ok, ep, ev, ee) in rows.items():
        for (label, target), err in zip(TARGETS.items(), (ep, ev, ee), strict=True):
            mx = np.nanmax(err)
            passed &= bool(mx <= target) and n_ok == len(idx)
            print(
                f"{name:8s} {label:22s} {mx:10.2e} {np.nanquantile(err, 0.99):10.2e} "
                f"{np.nanmedian(err):10.2e} {target:8.0e} {mx / target:7.3f}"
            )
        print(f"{name:8s} completed {n_ok} of the {len(idx)} hops the reference completed")
    print("PASS" if passed else "FAIL")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
