"""``hopnav scenario NAME_OR_PATH``: validate a scenario file and show what it describes.

Prints the scenario's settings and a text map of its grid (or, with ``--json``, the parsed
settings as JSON); ``--png FILE`` also draws the empty world as a figure (PNG, SVG or PDF by
the file's extension, titled with the formula and P_sat, with the region legend). A scenario
with a problem fails with exit code 2 and the message names the key and the line.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from hopnav.arguments import figure_file
from hopnav.errors import UsageError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "scenario",
        description=__doc__,
    )
    p.add_argument("scenario", help="shipped name (a, b, c, d) or path to a scenario TOML")
    p.add_argument("--png", help="also draw the world to this figure (.png, .svg or .pdf)")
    p.add_argument("--json", action="store_true", help="print the settings as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from planner.errors import ScenarioError
    from planner.scenario import ascii_map, load_scenario

    try:
        sc = load_scenario(args.scenario)
    except ScenarioError as err:
        raise UsageError(str(err)) from None
    if args.png:
        figure_file(args.png, "--png")
    if args.json:
        print(
            json.dumps(
                {
                    "name": sc.name,
                    "description": sc.description,
                    "world": dataclasses.asdict(sc.world),
                    "labels": list(sc.labels),
                    "formula": sc.formula,
                    "hazard": sc.hazard,
                    "goal": sc.goal,
                    "start": list(sc.start),
                    "start_cell": sc.start_cell,
                    "rewards": dict(sc.rewards),
                    "p_sat": sc.p_sat,
                    "reward_known": sc.reward_known,
                    "collect": sc.collect,
                    "runner": dataclasses.asdict(sc.runner),
                    "cells_per_label": {lab: int(sc.region_mask(lab).sum()) for lab in sc.labels},
                },
                indent=2,
            )
        )
    else:
        w = sc.world
        print(f"scenario {sc.name}: {sc.description}")
        print(f"world {w.width} x {w.height} m, {w.nx} x {w.ny} cells of {w.cell} m")
        print(f"formula {sc.formula}  (hazard {sc.hazard}, goal {sc.goal}, P_sat {sc.p_sat})")
        print(f"rewards {dict(sc.rewards)}  (known: {sc.reward_known}, paid {sc.collect})")
        print(f"runner {sc.runner}")
        print(ascii_map(sc))
    if args.png:
        from hopper_sim.experiments.provenance import provenance
        from hopper_sim.viz.figures import FigureError, render_run_figure

        Path(args.png).parent.mkdir(parents=True, exist_ok=True)
        try:
            render_run_figure(sc, [], args.png, metadata=provenance(sc))
        except FigureError as err:
            raise UsageError(str(err)) from None
    return 0
