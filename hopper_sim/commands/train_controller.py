"""``hopnav train-controller``: simulate hops, train the hop model, save the checkpoint."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "train-controller",
        help="generate hop data with MuJoCo, train the hop MLP, write the controller checkpoint",
        description=(
            "Reproduces the shipped controller checkpoint from a seed: samples interstitial "
            "states and touchdown angles, simulates them (stance thrust regulated to the "
            "nominal speed), trains the MLP, computes the steady gait v_des, saves."
        ),
    )
    p.add_argument("--samples", type=int, default=60_000, help="hops to simulate")
    p.add_argument("--seed", type=int, default=0, help="seed of sampling, split and training")
    p.add_argument("--data", type=Path, help="train on this saved dataset instead of simulating")
    p.add_argument("--save-data", type=Path, help="also save the simulated dataset (.npz)")
    p.add_argument("--out", type=Path, default=DEFAULT_CHECKPOINT, help="checkpoint path")
    p.add_argument("--epochs", type=int, default=120)
    p.add_argument("--hidden", type=str, default="128,128,128", help="layer widths")
    p.add_argument(
        "--nominal-speed", type=float, default=4.0, help="interstitial speed V_nom [m/s]"
    )
    p.add_argument(
        "--hop-length", type=float, default=2.0, help="hop length of the steady gait v_des [m]"
    )
    p.add_argument("--nthread", type=int, default=None, help="simulation threads")
    p.add_argument("--torch-threads", type=int, default=1)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import torch
    from tqdm import tqdm

    from hopper_sim.controller.checkpoint import HopModelCheckpoint, save_checkpoint
    from hopper_sim.controller.dataset import (
        Sampling,
        generate_dataset,
        load_dataset,
        save_dataset,
    )
    from hopper_sim.controller.hop_model import OUTPUT_NAMES
    from hopper_sim.controller.simulator import simulator_hop_fn
    from hopper_sim.controller.steady import steady_state
    from hopper_sim.controller.training import TrainConfig, train_hop_model
    from hopper_sim.model import HopperModel

    torch.set_num_threads(args.torch_threads)
    model = HopperModel.load()
    param_hash = model.param_hash()
    hop_fn = simulator_hop_fn(model, nominal_speed=args.nominal_speed, nthread=args.nthread)
    if args.data is not None:
        dataset = load_dataset(args.data)
        if dataset.metadata.get("param_hash") != param_hash:
            print(
                f"error: {args.data} was simulated with parameters "
                f"{dataset.metadata.get('param_hash')}, the model has {param_hash}"
            )
            return 2
        print(f"loaded {len(dataset)} hops from {args.data}")
    else:
        t0 = time.perf_counter()
        with tqdm(total=args.samples, desc="simulating hops", unit="hop") as bar:
            dataset = generate_dataset(
                hop_fn,
                args.samples,
                seed=args.seed,
                sampling=Sampling(shell_speed=args.nominal_speed),
                chunk=2000,
                metadata={"param_hash": param_hash, "nominal_speed": args.nominal_speed},
                progress=bar.update,
            )
        dt = time.perf_counter() - t0
        print(
            f"simulated {len(dataset)} hops in {dt:.1f} s ({len(dataset) / dt:.0f} hops/s), "
            f"{dataset.ok.mean():.1%} successful"
        )
        if args.save_data is not None:
            print(f"saved dataset to {save_dataset(dataset, args.save_data)}")

    steady = steady_state(hop_fn, args.hop_length, total_speed=args.nominal_speed)
    print(
        f"steady gait: {steady.hop_length} m hops at |v| = {args.nominal_speed} m/s: "
        f"s = {steady.speed:.4f} m/s, v_z = {steady.vz:.4f} m/s, alpha = {steady.alpha:.4f} rad"
    )
    config = TrainConfig(hidden=tuple(int(h) for h in args.hidden.split(",")), epochs=args.epochs)
    t0 = time.perf_counter()
    with tqdm(total=config.epochs, desc="training", unit="epoch") as bar:

        def progress(epoch: int, loss: float) -> None:
            bar.set_postfix(loss=f"{loss:.4g}")
            bar.update(1)

        result = train_hop_model(dataset, config, seed=args.seed, progress=progress)
    print(f"trained in {time.perf_counter() - t0:.1f} s; held-out errors:")
    print(f"  {'output':<8}{'RMSE':>10}{'p95':>10}")
    for name in OUTPUT_NAMES:
        m = result.metrics[name]
        print(f"  {name:<8}{m['rmse']:>10.4f}{m['p95']:>10.4f}")
    f = result.metrics["feasibility"]
    print(f"  feasibility accuracy {f['accuracy']:.4f}, failed hops called ok ", end="")
    print(f"{f['false_ok_rate']:.4f}")

    metadata = {
        "command": (
            f"hopnav train-controller --samples {len(dataset)} --seed {args.seed} "
            f"--epochs {args.epochs} --hidden {args.hidden} "
            f"--nominal-speed {args.nominal_speed} --hop-length {args.hop_length}"
        ),
        "seed": args.seed,
        "nominal_speed": args.nominal_speed,
        "steady": steady.as_dict(),
        "metrics": result.metrics,
        "train_config": {**config.__dict__, "hidden": list(config.hidden)},
        "dataset": {k: v for k, v in dataset.metadata.items() if k != "ranges"},
        "samples": len(dataset),
    }
    path = save_checkpoint(HopModelCheckpoint(result.net, param_hash, metadata), args.out)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")
    return 0
