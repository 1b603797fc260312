"""``hopnav imdp``: solve an interval MDP file, or convert it to another format.

``hopnav imdp solve FILE [--format prism|drn|bmdp] [--target LABEL] [--avoid LABEL]
[--optimistic] [--minimize] [--tolerance T] [--uncertified] [--json]`` prints, per state,
the value and its certified bracket ``lower upper`` (the maximal probability of
``(!avoid) U target``; worst case unless ``--optimistic``): the solver stops when every
bracket is narrower than the tolerance. ``--uncertified`` stops on the residual instead
(faster, no error bound; ``upper`` is then the trivial 1).

``hopnav imdp check FILE --ltl FORMULA [--format F] [--optimistic] [--tolerance T] [--json]``
prints, per state, the maximal probability that a run from there satisfies the LTL
formula (over the file's labels; worst case unless ``--optimistic``) with its certified
bracket, through the project's automaton translation, product and exact game solution
(:func:`planner.imdp.check.check_ltl`). JSON: ``{"initial": [...], "values": [...],
"lower": [...], "upper": [...], "automaton_states": n}`` (``initial``: the values at the
file's initial states). A formula that does not parse, or names a proposition that is not
a label of the file, is an error (exit 2).

``hopnav imdp export FILE --out PATH [--format F] [--to F] [--target LABEL]`` writes the
model in another format (``--target`` names bmdp-tool's terminal states).

``hopnav imdp export --scenario NAME --out PATH [--to F]`` writes a scenario's MT-PIMDP: the
grid abstraction with the transition intervals of the landing-error GP prior (no data yet, as
at the start of a run; noise parameters from the MJCF), times the automaton of the scenario's
formula, with the labels ``accept`` (robustly accepting end components) and ``fail``
(failure states) added, so that Storm, PRISM or bmdp-tool can check it
(``--target accept`` for bmdp-tool's terminal states).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from planner.errors import PlannerError
from planner.imdp import Problem, ReachAvoid, Specification, ValueIteration, solve
from planner.imdp.io import FORMATS, TERMINAL, guess_format, read_model, write_model


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("imdp", help="solve or convert interval MDP files")
    sub = p.add_subparsers(dest="imdp_command", metavar="ACTION", required=True)

    s = sub.add_parser("solve", help="robust reachability values of a model file")
    s.add_argument("file")
    s.add_argument("--format", choices=FORMATS, help="default: from the file suffix")
    s.add_argument("--target", action="append", help="target label (repeatable)")
    s.add_argument("--avoid", action="append", help="label to avoid (repeatable)")
    s.add_argument("--optimistic", action="store_true", help="best case instead of worst")
    s.add_argument("--minimize", action="store_true", help="minimise instead of maximise")
    s.add_argument("--tolerance", type=float, default=1e-8)
    s.add_argument(
        "--uncertified",
        action="store_true",
        help="stop on the residual (no error bound) instead of the certified bracket",
    )
    s.add_argument("--json", action="store_true", help="print a JSON object")
    s.set_defaults(func=run_solve)

    c = sub.add_parser("check", help="robust satisfaction of an LTL formula on a model file")
    c.add_argument("file")
    c.add_argument("--ltl", required=True, help="LTL formula over the file's labels")
    c.add_argument("--format", choices=FORMATS, help="default: from the file suffix")
    c.add_argument("--optimistic", action="store_true", help="best case instead of worst")
    c.add_argument("--tolerance", type=float, default=1e-8)
    c.add_argument("--json", action="store_true", help="print a JSON object")
    c.set_defaults(func=run_check)

    e = sub.add_parser("export", help="write a model file, or a scenario's product, in a format")
    src = e.add_mutually_exclusive_group(required=True)
    src.add_argument("file", nargs="?", help="model file to convert")
    src.add_argument("--scenario", help="shipped scenario name or TOML path: export its product")
    e.add_argument("--out", required=True)
    e.add_argument("--format", choices=FORMATS, help="input format (default: suffix)")
    e.add_argument("--to", choices=FORMATS, help="output format (default: suffix)")
    e.add_argument("--target", action="append", help="bmdp: labels of the terminal states")
    e.set_defaults(func=run_export)


def run_solve(args: argparse.Namespace) -> int:
    try:
        model = read_model(args.file, args.format)
        fmt = args.format or guess_format(args.file)
        target = args.target or ([TERMINAL] if fmt == "bmdp" else None)
        if not target:
            print("hopnav imdp solve: --target LABEL is required", file=sys.stderr)
            return 2
        spec = Specification(
            ReachAvoid(target, args.avoid),
            "optimistic" if args.optimistic else "pessimistic",
            "minimize" if args.minimize else "maximize",
        )
        alg = ValueIteration(tolerance=args.tolerance, certified=not args.uncertified)
        sol = solve(Problem(model, spec), alg)
    except PlannerError as err:
        print(f"hopnav imdp solve: {err}", file=sys.stderr)
        return 1
    if args.json:
        out = {
            "values": sol.values.tolist(),
            "lower": sol.lower.tolist(),
            "upper": sol.upper.tolist(),
            "converged": sol.converged,
            "residual": sol.residual,
            "iterations": sol.iterations,
        }
        print(json.dumps(out))
    else:
        _print_bracket(sol.values, sol.lower, sol.upper)
        state = "certified" if sol.converged and not args.uncertified else "NOT certified"
        print(
            f"# bracket width {sol.error:.3g} ({state}), residual {sol.residual:.3g}, "
            f"iterations {sol.iterations}",
            file=sys.stderr,
        )
    return 0


def _print_bracket(values: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> None:
    """One line per state: ``state value lower upper``."""
    print("# state value lower upper", file=sys.stderr)
    for s, (v, lo, hi) in enumerate(zip(values, lower, upper, strict=True)):
        print(f"{s} {v:.12g} {lo:.12g} {hi:.12g}")


def run_check(args: argparse.Namespace) -> int:
    from planner.imdp.check import check_ltl

    try:
        if not args.tolerance > 0:
            raise PlannerError(f"--tolerance must be positive, got {args.tolerance}")
        model = read_model(args.file, args.format)
        result = check_ltl(
            model, args.ltl, args.optimistic, ValueIteration(tolerance=args.tolerance)
        )
    except PlannerError as err:
        print(f"hopnav imdp check: {err}", file=sys.stderr)
        return 2
    if args.json:
        out = {
            "initial": result.values[result.initial].tolist(),
            "values": result.values.tolist(),
            "lower": result.lower.tolist(),
            "upper": result.upper.tolist(),
            "automaton_states": result.automaton_states,
        }
        print(json.dumps(out))
    else:
        _print_bracket(result.values, result.lower, result.upper)
        state = "certified" if result.converged else "NOT certified"
        init = ", ".join(f"{result.values[i]:.12g}" for i in result.initial)
        print(
            f"# initial {init}; automaton states {result.automaton_states}; "
            f"bracket width {result.solution.error:.3g} ({state})",
            file=sys.stderr,
        )
    return 0


def scenario_product_model(name: str):
    """The labelled MT-PIMDP of scenario ``name`` under the GP prior (see the module doc)."""
    from hopper_sim.model import HopperModel
    from planner.gp.landing import LandingErrorGP
    from planner.imdp.grid import GridWorld
    from planner.imdp.product import ProductIMDP
    from planner.intervals import TruncatedGaussianNoise, cell_error_bounds, transition_intervals
    from planner.ltl.translate import translate
    from planner.scenario import load_scenario

    sc = load_scenario(name)
    w = sc.world
    grid = GridWorld(w.nx, w.ny, w.cell, sc.cell_labels, sc.hazard)
    pp = HopperModel.load().perturbation
    bounds = cell_error_bounds(LandingErrorGP(), grid)
    ti = transition_intervals(bounds, grid, TruncatedGaussianNoise(pp.noise_sigma, pp.noise_bound))
    model = grid.imdp_from_intervals(*ti.coo(), initial=[sc.start_cell])
    reward = np.append(np.asarray(sc.reward_grid, float).ravel(), 0.0)
    return ProductIMDP(model, translate(sc.formula), reward).labelled_model()


def run_export(args: argparse.Namespace) -> int:
    try:
        if args.scenario is not None:
            model = scenario_product_model(args.scenario)
        else:
            model = read_model(args.file, args.format)
        terminal = None
        if args.target:
            terminal = model.states_labelled(args.target[0])
            for name in args.target[1:]:
                terminal |= model.states_labelled(name)
        write_model(model, args.out, args.to, terminal=terminal)
    except PlannerError as err:
        print(f"hopnav imdp export: {err}", file=sys.stderr)
        return 1
    return 0
