"""``hopnav config``: print the configuration tree of a run, every key with its value.

Without ``--scenario`` the shipped defaults; with it, the scenario's (its ``[runner]`` table
and ``p_sat`` applied); ``--set KEY=VALUE`` changes as on ``hopnav run`` and ``hopnav sweep``.
A key is the dotted path shown (``planner.switching.c``) or any unique dotted tail of it
(``switching.c``, ``c``). ``gp.*`` keys change the landing-error prior that the runner derives
from the scene; ``(prior)`` marks the ones left as derived. ``--json`` prints one JSON object.
"""

from __future__ import annotations

import argparse
import json

from hopnav.arguments import add_set_argument, run_config
from hopnav.errors import UsageError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("config", description=__doc__)
    p.add_argument("--scenario", help="shipped name (a, b, c, d) or TOML path [none: defaults]")
    add_set_argument(p)
    p.add_argument("--json", action="store_true", help="print the keys and values as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hopper_sim.navigation.config import describe
    from planner.errors import PlannerError
    from planner.scenario import load_scenario

    sc = None
    if args.scenario is not None:
        try:
            sc = load_scenario(args.scenario)
        except PlannerError as err:
            raise UsageError(str(err)) from None
    config = run_config(sc, args.set, {})
    if args.json:
        print(json.dumps(config.leaves(), indent=2))
        return 0
    rows = describe(config)
    width = max(len(k) for k, _ in rows)
    for key, text in rows:
        print(f"{key.ljust(width)} = {text}")
    return 0
