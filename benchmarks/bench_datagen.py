"""Training-data generation rate (batched MuJoCo hops, thrust on) against a baseline of the
same hops one at a time through :func:`hopper_sim.physics.hop.simulate_hop`, in the same process.

    python benchmarks/bench_datagen.py [--samples 10000] [--baseline 300] [--nthread N]

Prints hops/s of both, their ratio, and the projected time for 100k hops.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from tqdm import tqdm

from hopper_sim.controller.dataset import Sampling, generate_dataset, sample_inputs
from hopper_sim.controller.hop_model import InputRanges
from hopper_sim.controller.simulator import nominal_energy, simulator_hop_fn
from hopper_sim.physics.hop import simulate_hop
from hopper_sim.physics.model import HopperModel


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=10_000)
    ap.add_argument("--baseline", type=int, default=300)
    ap.add_argument("--nthread", type=int, default=None)
    ap.add_argument("--nominal-speed", type=float, default=4.0)
    args = ap.parse_args()
    model = HopperModel.load()
    sampling = Sampling(shell_speed=args.nominal_speed)
    hop_fn = simulator_hop_fn(model, nominal_speed=args.nominal_speed, nthread=args.nthread)
    t0 = time.perf_counter()
    with tqdm(total=args.samples, desc="batched", unit="hop") as bar:
        ds = generate_dataset(
            hop_fn, args.samples, seed=0, sampling=sampling, chunk=2000, progress=bar.update
        )
    rate = args.samples / (time.perf_counter() - t0)

    x = sample_inputs(np.random.default_rng(0), args.baseline, InputRanges(), sampling)
    e_nom = nominal_energy(model, args.nominal_speed)
    data = model.make_data()
    t0 = time.perf_counter()
    for s, vz, a, b in tqdm(x, desc="one at a time", unit="hop"):
        simulate_hop(
            model,
            np.zeros(2),
            np.array([s, 0.0, vz]),
            a,
            b,
            thrust=True,
            nominal_energy=e_nom,
            record_path=False,
            data=data,
        )
    base = args.baseline / (time.perf_counter() - t0)
    print(f"batched simulate_hops : {rate:9.0f} hops/s ({ds.ok.mean():.1%} successful)")
    print(f"simulate_hop loop     : {base:9.0f} hops/s")
    print(f"ratio batched / loop  : {rate / base:9.1f}x")
    print(f"projected time for 100k hops: {1e5 / rate / 60:.1f} min (target <= 3 min)")


if __name__ == "__main__":
    main()
