"""Hops per second: the batched path (``simulate_hops`` on ``mujoco.batch``, all threads)
against a plain per-step Python loop (``simulate_hop``: one ``mj_step`` call per step) on
the same hops, and the ratio (targets: >= 1,000 hops/s batched on 2 cores, >= 5x the loop).

Hops: pure SLIP (no terrain, noise or thrust) near the steady gaits, interstitial speed
2.5-4 m/s in random directions, vz -3 to -1.2 m/s, alpha 68-76 deg, beta within +/-0.3 rad.

The batched path packs ``--hops-per-sim`` hops into one MjData (copies of the hopper in one
model); ``--hops-per-sim 1`` measures one MjData per hop. Both wall-clock rates and rates per
CPU-second are printed: on a shared machine the first measure the load, the second the work.

    python benchmarks/bench_hops.py [--hops 2000] [--nthread 0 (all CPUs)] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from hopper_sim.physics.batch import DEFAULT_HOPS_PER_SIM, simulate_hops
from hopper_sim.physics.hop import simulate_hop
from hopper_sim.physics.model import HopperModel


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hops", type=int, default=2000)
    ap.add_argument("--nthread", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--hops-per-sim", type=int, default=DEFAULT_HOPS_PER_SIM)
    args = ap.parse_args()
    nthread = args.nthread or os.cpu_count() or 1
    model = HopperModel.load()
    rng = np.random.default_rng(args.seed)
    n = args.hops
    speed = rng.uniform(2.5, 4.0, n)
    heading = rng.uniform(0.0, 2.0 * np.pi, n)
    vel = np.column_stack(
        [speed * np.cos(heading), speed * np.sin(heading), rng.uniform(-3.0, -1.2, n)]
    )
    alpha = np.deg2rad(rng.uniform(68.0, 76.0, n))
    beta = rng.uniform(-0.3, 0.3, n)

    data = model.make_data()
    batch_times, loop_times, batch_cpu, loop_cpu = [], [], [], []
    for _ in range(args.repeat):  # interleaved, so both see the same machine load
        t, c = time.perf_counter(), time.process_time()
        res = simulate_hops(
            model, vel, alpha, beta, nthread=nthread, hops_per_sim=args.hops_per_sim
        )
        batch_times.append(time.perf_counter() - t)
        batch_cpu.append(time.process_time() - c)
        t, c = time.perf_counter(), time.process_time()
        loop = [
            simulate_hop(
                model, np.zeros(2), vel[i], alpha[i], beta[i], record_path=False, data=data
            )
            for i in range(n)
        ]
        loop_times.append(time.perf_counter() - t)
        loop_cpu.append(time.process_time() - c)
    same = all(
        (one.ok == res.ok[i]) and (not one.ok or np.array_equal(one.next_pos, res.next_pos[i]))
        for i, one in enumerate(loop)
    )
    stance_steps = np.nanmean((res.liftoff_time - res.touchdown_time) / model.params.timestep)
    batch_rate = n / min(batch_times)
    loop_rate = n / min(loop_times)
    print(
        f"model {model.param_hash()}  dt {model.params.timestep} s  RK4  cpus {os.cpu_count()}"
        f"  nthread {nthread}  hops per MjData {args.hops_per_sim}"
    )
    print(
        f"hops {n} ({res.ok.mean():.1%} complete), mean stance {stance_steps:.0f} steps;"
        f" batched results equal the loop's: {same}"
    )
    print(
        f"batched (mujoco.batch)   {batch_rate:9.0f} hops/s   "
        f"({batch_rate * stance_steps / 1e6:.2f} M steps/s)"
    )
    print(
        f"per-step Python loop     {loop_rate:9.0f} hops/s   "
        f"({loop_rate * stance_steps / 1e6:.2f} M steps/s)"
    )
    print(
        f"ratio batched / loop     {batch_rate / loop_rate:9.2f}x   (wall clock, best of "
        f"{args.repeat})"
    )
    # On a shared machine the wall clock measures the load; CPU time (all threads) measures
    # the work. With nthread threads on nthread free cores the batched rate would be
    # nthread * hops per CPU-second.
    batch_cpu_rate = n / min(batch_cpu)
    loop_cpu_rate = n / min(loop_cpu)
    print(
        f"per CPU-second: batched {batch_cpu_rate:.0f} hops, loop {loop_cpu_rate:.0f} hops;"
        f" on {nthread} free cores: batched {nthread * batch_cpu_rate:.0f} hops/s, ratio "
        f"{nthread * batch_cpu_rate / loop_cpu_rate:.2f}x"
    )
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus")
    return 0


if __name__ == "__main__":
    sys.exit(main())
