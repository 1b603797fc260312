"""Landing accuracy of the controller over chained MuJoCo hops (the acceptance check).

    python benchmarks/bench_tracking.py [--hops 1000] [--seed 0] [--perturbed]

Commands random actions (N1 .. W2) hop after hop, each hop starting where the last ended,
stance thrust on; prints the landing-error percentiles per executed action type, the backups
used, the failures and the decision latency. ``--perturbed`` turns on the terrain force field
and the landing noise (their error distribution is what the GP has to learn). The baseline
row "model" is the error of the network's own predicted landing, i.e. how much of the landing
error the learned model explains.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from tqdm import tqdm

from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT, load_checkpoint
from hopper_sim.controller.controller import LegAngleController
from hopper_sim.controller.tracking import track_random_actions
from hopper_sim.physics.model import HopperModel
from hopper_sim.physics.terrain import TerrainField
from planner.imdp.grid import ACTIONS


def row(name: str, e: np.ndarray, extra: str = "") -> str:
    e = e[np.isfinite(e)]
    if len(e) == 0:
        return f"  {name:<8}{0:>6}"
    p = np.percentile(e, [50, 95, 100])
    return f"  {name:<8}{len(e):>6}{p[0]:>10.3f}{p[1]:>10.3f}{p[2]:>10.3f}{extra}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default=str(DEFAULT_CHECKPOINT))
    ap.add_argument("--hops", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--perturbed", action="store_true", help="terrain field and noise on")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = HopperModel.load()
    ckpt = load_checkpoint(args.checkpoint, expected_param_hash=model.param_hash())
    ctl = LegAngleController.from_checkpoint(ckpt)
    terrain = TerrainField.for_model(model, seed=args.seed) if args.perturbed else None
    t0 = time.perf_counter()
    with tqdm(total=args.hops, desc="hops", unit="hop") as bar:
        res = track_random_actions(
            ctl,
            model,
            args.hops,
            rng=np.random.default_rng(args.seed),
            nominal_speed=float(ckpt.metadata["nominal_speed"]),
            terrain=terrain,
            noise=args.perturbed,
            progress=bar.update,
        )
    wall = time.perf_counter() - t0
    mode = "perturbations and noise ON" if args.perturbed else "perturbations and noise off"
    print(f"{args.hops} chained hops, {mode}, seed {args.seed}, {wall:.1f} s")
    print(f"  {'action':<8}{'n':>6}{'median':>10}{'p95':>10}{'max':>10}  landing error [m]")
    for a, name in enumerate(ACTIONS):
        sel = res.executed == a
        print(row(name, res.error[sel], f"   (requested {int((res.requested == a).sum())})"))
    print(row("all", res.error))
    print(row("model", res.model_error, "   |actual - predicted landing|"))
    print(f"  backups used: {int(res.backup.sum())} of {args.hops} hops")
    print(f"  hop failures: {int((~res.ok).sum())}")
    print(f"  states outside the training box (clamped): {int((~res.in_range).sum())}")
    lat = 1e3 * res.latency
    print(
        f"  decision latency: median {np.median(lat):.2f} ms, p95 {np.percentile(lat, 95):.2f} ms"
    )


if __name__ == "__main__":
    main()
