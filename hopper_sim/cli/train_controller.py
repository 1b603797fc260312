"""``hopnav train-controller``: simulate hops, train the hop model, save the checkpoint.

Reproduces the shipped controller checkpoint from a seed: samples interstitial states and
touchdown angles, simulates them in MuJoCo (stance thrust regulated to the nominal speed),
trains the MLP, computes the steady gait v_des and writes the checkpoint to ``--out``
(default ``runs/controller.pt``; ``hopnav run --checkpoint FILE`` uses it). The shipped
checkpoint is ``hopper_sim/data/controller.pt``, rebuilt with the defaults and
``--out hopper_sim/data/controller.pt`` in a source checkout.

A model whose held-out feasibility accuracy is below that of always answering the more common
class is not written (exit code 1) unless ``--allow-weak`` is given.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from hopnav.arguments import (
    input_file,
    int_range,
    non_negative_int,
    output_file,
    positive_float,
    positive_int,
)
from hopnav.errors import RunFailed, UsageError

#: Fewest hops to simulate: the held-out tenth must hold enough hops to measure the model.
MIN_SAMPLES = 100
#: Most hops to simulate (the dataset is held in memory: about 100 bytes per hop).
MAX_SAMPLES = 10_000_000
#: Most hidden layers and widest layer (as :mod:`hopper_sim.controller.checkpoint` reads).
MAX_LAYERS, MAX_WIDTH = 16, 4096
#: Most simulation or torch threads.
MAX_THREADS = 1024
DEFAULT_OUT = Path("runs") / "controller.pt"


def _widths(text: str) -> tuple[int, ...]:
    try:
        widths = tuple(int(h) for h in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated layer widths such as 128,128, got {text!r}"
        ) from None
    if not widths or min(widths) < 1:
        raise argparse.ArgumentTypeError(f"layer widths must be >= 1, got {text!r}")
    if len(widths) > MAX_LAYERS or max(widths) > MAX_WIDTH:
        raise argparse.ArgumentTypeError(
            f"at most {MAX_LAYERS} layers of at most {MAX_WIDTH} units, got {text!r}"
        )
    return widths


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "train-controller",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--samples",
        type=int_range(
            MIN_SAMPLES, MAX_SAMPLES, "a tenth of them is held out to measure the model"
        ),
        default=60_000,
        help="hops to simulate [60000]",
    )
    p.add_argument(
        "--seed", type=non_negative_int, default=0, help="seed of sampling, split and training"
    )
    p.add_argument("--data", type=Path, help="train on this saved dataset instead of simulating")
    p.add_argument("--save-data", type=Path, help="also save the simulated dataset (.npz)")
    p.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_OUT,
        help=f"checkpoint to write [{DEFAULT_OUT}] (the shipped one is not replaced unless named)",
    )
    p.add_argument("--epochs", type=positive_int, default=120, help="[120]")
    p.add_argument(
        "--hidden", type=_widths, default=(128, 128, 128), help="layer widths [128,128,128]"
    )
    p.add_argument(
        "--nominal-speed", type=positive_float, default=4.0, help="interstitial speed V_nom [m/s]"
    )
    p.add_argument(
        "--hop-length",
        type=positive_float,
        default=2.0,
        help="hop length of the steady gait v_des [m]",
    )
    threads = int_range(1, MAX_THREADS)
    p.add_argument("--nthread", type=threads, default=None, help="simulation threads")
    p.add_argument("--torch-threads", type=threads, default=1)
    p.add_argument(
        "--allow-weak",
        action="store_true",
        help="write the checkpoint even if its feasibility head is no better than chance",
    )
    p.set_defaults(func=run)


def _dataset(args: argparse.Namespace, hop_fn, param_hash: str):
    """The hops to train on: loaded from ``--data`` (refused unless simulated with these
    hopper parameters) or simulated (and saved to ``--save-data`` if given)."""
    from tqdm import tqdm

    from hopper_sim.controller.dataset import (
        Sampling,
        generate_dataset,
        load_dataset,
        save_dataset,
    )

    if args.data is not None:
        try:
            dataset = load_dataset(args.data)
        except ValueError as err:
            raise UsageError(f"--data {args.data}: {err}") from None
        if dataset.metadata.get("param_hash") != param_hash:
            raise UsageError(
                f"--data {args.data}: simulated with hopper parameters "
                f"{dataset.metadata.get('param_hash')}, the model has {param_hash}"
            )
        print(f"loaded {len(dataset)} hops from {args.data}")
        return dataset
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
        args.save_data.parent.mkdir(parents=True, exist_ok=True)
        print(f"saved dataset to {save_dataset(dataset, args.save_data)}")
    return dataset


def _train(args: argparse.Namespace, dataset, config):
    """The trained hop model (with a progress bar), its held-out errors printed."""
    from tqdm import tqdm

    from hopper_sim.controller.hop_model import OUTPUT_NAMES
    from hopper_sim.controller.training import train_hop_model

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
    return result


def _require_better_than_chance(args: argparse.Namespace, dataset, result) -> None:
    """Refuse (or, with ``--allow-weak``, warn about) a feasibility head whose held-out
    accuracy is below that of always answering the more common class."""
    f = result.metrics["feasibility"]
    held_out_ok = float(dataset.ok[result.test_index].mean())
    chance = max(held_out_ok, 1.0 - held_out_ok)
    if f["accuracy"] < chance:
        message = (
            f"the trained feasibility head is right on {f['accuracy']:.1%} of the "
            f"{len(result.test_index)} held-out hops, below the {chance:.1%} of always answering "
            "the more common class"
        )
        if not args.allow_weak:
            raise RunFailed(
                f"{message}; no checkpoint written (use more --samples or --epochs, or "
                "--allow-weak)"
            )
        print(f"hopnav train-controller: warning: {message}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    output_file(args.out, "--out", (".pt",))
    if args.save_data is not None:
        output_file(args.save_data, "--save-data", (".npz",))
    if args.data is not None:
        input_file(args.data, "--data")

    import torch

    from hopper_sim.controller.checkpoint import HopModelCheckpoint, save_checkpoint
    from hopper_sim.controller.simulator import simulator_hop_fn
    from hopper_sim.controller.steady import steady_state
    from hopper_sim.controller.training import TrainConfig
    from hopper_sim.experiments.provenance import provenance
    from hopper_sim.physics.model import HopperModel

    torch.set_num_threads(args.torch_threads)
    model = HopperModel.load()
    param_hash = model.param_hash()
    hop_fn = simulator_hop_fn(model, nominal_speed=args.nominal_speed, nthread=args.nthread)
    dataset = _dataset(args, hop_fn, param_hash)

    steady = steady_state(hop_fn, args.hop_length, total_speed=args.nominal_speed)
    print(
        f"steady gait: {steady.hop_length} m hops at |v| = {args.nominal_speed} m/s: "
        f"s = {steady.speed:.4f} m/s, v_z = {steady.vz:.4f} m/s, alpha = {steady.alpha:.4f} rad"
    )
    config = TrainConfig(hidden=args.hidden, epochs=args.epochs)
    result = _train(args, dataset, config)
    _require_better_than_chance(args, dataset, result)

    metadata = {
        "command": (
            f"hopnav train-controller --samples {len(dataset)} --seed {args.seed} "
            f"--epochs {args.epochs} --hidden {','.join(map(str, args.hidden))} "
            f"--nominal-speed {args.nominal_speed} --hop-length {args.hop_length}"
        ),
        "seed": args.seed,
        "nominal_speed": args.nominal_speed,
        "steady": steady.as_dict(),
        "metrics": result.metrics,
        "train_config": {**config.__dict__, "hidden": list(config.hidden)},
        "dataset": {k: v for k, v in dataset.metadata.items() if k != "ranges"},
        "samples": len(dataset),
        "provenance": provenance(None),
    }
    path = save_checkpoint(HopModelCheckpoint(result.net, param_hash, metadata), args.out)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")
    return 0
