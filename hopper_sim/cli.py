"""The ``hopnav`` command line: one sub-command per module in :mod:`hopper_sim.commands`."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

COMMAND_MODULES: tuple[str, ...] = (
    "replay",
    "scenario",
    "hop",
    "train_controller",
    "run",
    "imdp",
    "automaton",
    "sweep",
    "figure",
)


def build_parser() -> argparse.ArgumentParser:
    import importlib

    parser = argparse.ArgumentParser(
        prog="hopnav",
        description="Multi-task navigation of a MuJoCo SLIP hopper (LTL + rewards + learning).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(f"hopper_sim.commands.{name}").register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
