"""``hopnav imdp``: solve an interval MDP file, or convert it to another format.

``hopnav imdp solve FILE [--format prism|drn|bmdp] [--target LABEL] [--avoid LABEL]
[--optimistic] [--minimize] [--tolerance T] [--uncertified] [--json]`` prints, per state,
the value and its certified bracket ``lower upper`` (the maximal probability of
``(!avoid) U target``; worst case unless ``--optimistic``): the solver stops when every
bracket is narrower than the tolerance. ``--uncertified`` stops on the residual instead
(faster, no error bound; ``upper`` is then the trivial 1).

``hopnav imdp check FILE --ltl FORMULA [--format F] [--optimistic] [--tolerance T]
[--max-states N] [--max-letters N] [--max-seconds S] [--json]``
prints, per state, the maximal probability that a run from there satisfies the LTL
formula (over the file's labels; worst case unless ``--optimistic``) with its certified
bracket, through the project's automaton translation, product and exact game solution
(:func:`planner.imdp.check.check_ltl`). JSON: ``{"initial": [...], "values": [...],
"lower": [...], "upper": [...], "automaton_states": n}`` (``initial``: the values at the
file's initial states). A formula that does not parse, or names a proposition that is not
a label of the file, is a usage error (exit 2), as is a translation beyond the limits
(those of ``hopnav automaton``) or a product beyond
:data:`planner.imdp.product.MAX_PRODUCT_STATES` / ``MAX_PRODUCT_ENTRIES``.

``hopnav imdp export FILE --out PATH [--format F] [--to F] [--target LABEL]`` writes the
model in another format (``--target`` names bmdp-tool's terminal states).

``hopnav imdp export --scenario NAME --out PATH [--to F]`` writes a scenario's MT-PIMDP: the
grid abstraction with the transition intervals of the landing-error GP prior (no data yet, as
at the start of a run; noise parameters from the MJCF), times the automaton of the scenario's
formula, with the labels ``accept`` (the almost-sure winning states) and ``fail``
(failure states) added, so that Storm, PRISM or bmdp-tool can check it
(``--target accept`` for bmdp-tool's terminal states).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hopnav.arguments import input_file, output_file, positive_float
from hopnav.errors import UsageError
from hopper_sim.cli.automaton import add_translation_limits, translation_limits

#: The model formats and the file suffix each is recognised by.
FORMATS = ("prism", "drn", "bmdp")
SUFFIXES = {".tra": "prism", ".drn": "drn", ".bmdp": "bmdp"}


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("imdp", description=__doc__)
    sub = p.add_subparsers(dest="imdp_command", metavar="ACTION", required=True)

    s = sub.add_parser("solve", help="robust reachability values of a model file")
    s.add_argument("file")
    s.add_argument("--format", choices=FORMATS, help="default: from the file suffix")
    s.add_argument("--target", action="append", help="target label (repeatable)")
    s.add_argument("--avoid", action="append", help="label to avoid (repeatable)")
    s.add_argument("--optimistic", action="store_true", help="best case instead of worst")
    s.add_argument("--minimize", action="store_true", help="minimise instead of maximise")
    s.add_argument("--tolerance", type=positive_float, default=1e-8)
    s.add_argument(
        "--uncertified",
        action="store_true",
        help="stop on the residual (no error bound) instead of the certified bracket",
    )
    s.add_argument("--json", action="store_true", help="print a JSON object")
    s.set_defaults(func=run_solve, prog=s.prog)

    c = sub.add_parser("check", help="robust satisfaction of an LTL formula on a model file")
    c.add_argument("file")
    c.add_argument("--ltl", required=True, help="LTL formula over the file's labels")
    c.add_argument("--format", choices=FORMATS, help="default: from the file suffix")
    c.add_argument("--optimistic", action="store_true", help="best case instead of worst")
    c.add_argument("--tolerance", type=positive_float, default=1e-8)
    add_translation_limits(c)
    c.add_argument("--json", action="store_true", help="print a JSON object")
    c.set_defaults(func=run_check, prog=c.prog)

    e = sub.add_parser("export", help="write a model file, or a scenario's product, in a format")
    src = e.add_mutually_exclusive_group(required=True)
    src.add_argument("file", nargs="?", help="model file to convert")
    src.add_argument("--scenario", help="shipped scenario name or TOML path: export its product")
    e.add_argument("--out", required=True)
    e.add_argument("--format", choices=FORMATS, help="input format (default: suffix)")
    e.add_argument("--to", choices=FORMATS, help="output format (default: suffix)")
    e.add_argument("--target", action="append", help="bmdp: labels of the terminal states")
    e.add_argument(
        "--force",
        action="store_true",
        help="prism: also replace a .lab file that belongs to no .tra of that name",
    )
    e.set_defaults(func=run_export, prog=e.prog)


def model_format(path: str, explicit: str | None, option: str) -> str:
    """``explicit``, else the format of ``path``'s suffix (:data:`SUFFIXES`).

    Raises:
        UsageError: no format given and the suffix names none.
    """
    if explicit is not None:
        return explicit
    fmt = SUFFIXES.get(Path(path).suffix.lower())
    if fmt is None:
        known = ", ".join(f"{k} ({v})" for k, v in SUFFIXES.items())
        raise UsageError(
            f"{path}: cannot tell the model format from the suffix {Path(path).suffix!r} "
            f"(known: {known}); give {option} {'|'.join(FORMATS)}"
        )
    return fmt


def run_solve(args: argparse.Namespace) -> int:
    from planner.errors import PlannerError
    from planner.imdp import Problem, ReachAvoid, Specification, ValueIteration, solve
    from planner.imdp.io import TERMINAL, read_model
    from planner.modes import Adversary, Objective

    fmt = model_format(args.file, args.format, "--format")
    input_file(args.file, "model file")
    target = args.target or ([TERMINAL] if fmt == "bmdp" else None)
    if not target:
        raise UsageError("--target LABEL is required (the states to reach)")
    try:
        model = read_model(args.file, fmt)
        spec = Specification(
            ReachAvoid(target, args.avoid),
            Adversary.OPTIMISTIC if args.optimistic else Adversary.PESSIMISTIC,
            Objective.MINIMIZE if args.minimize else Objective.MAXIMIZE,
        )
        alg = ValueIteration(tolerance=args.tolerance, certified=not args.uncertified)
        sol = solve(Problem(model, spec), alg)
    except PlannerError as err:
        raise UsageError(str(err)) from None
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


def _print_bracket(values, lower, upper) -> None:
    """One line per state: ``state value lower upper``."""
    print("# state value lower upper", file=sys.stderr)
    for s, (v, lo, hi) in enumerate(zip(values, lower, upper, strict=True)):
        print(f"{s} {v:.12g} {lo:.12g} {hi:.12g}")


def run_check(args: argparse.Namespace) -> int:
    from planner.errors import PlannerError
    from planner.imdp import ValueIteration
    from planner.imdp.check import check_ltl
    from planner.imdp.io import read_model

    fmt = model_format(args.file, args.format, "--format")
    input_file(args.file, "model file")
    try:
        model = read_model(args.file, fmt)
        result = check_ltl(
            model,
            args.ltl,
            args.optimistic,
            ValueIteration(tolerance=args.tolerance),
            limits=translation_limits(args),
        )
    except PlannerError as err:
        raise UsageError(str(err)) from None
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
    from hopper_sim.physics.model import HopperModel
    from planner.gp.landing import LandingErrorGP
    from planner.imdp.analysis import labelled_model
    from planner.imdp.grid import GridWorld
    from planner.imdp.product import ProductIMDP
    from planner.intervals import TruncatedGaussianNoise, cell_error_bounds, transition_intervals
    from planner.learning import PlannerConfig
    from planner.ltl.translate import translate
    from planner.scenario import load_scenario

    sc = load_scenario(name)
    grid = GridWorld.from_scenario(sc)
    pp = HopperModel.load().perturbation
    # the prior's abstraction with 3 points per cell and axis (the export's, unchanged)
    options = PlannerConfig(samples_per_axis=3).interval_options()
    bounds = cell_error_bounds(LandingErrorGP(), grid, **options)
    ti = transition_intervals(bounds, grid, TruncatedGaussianNoise(pp.noise_sigma, pp.noise_bound))
    model = grid.imdp_from_intervals(*ti.coo(), initial=[sc.start_cell])
    return labelled_model(ProductIMDP(model, translate(sc.formula), sc.state_rewards))


def run_export(args: argparse.Namespace) -> int:
    from planner.errors import PlannerError
    from planner.imdp.io import read_model, write_model

    to = model_format(args.out, args.to, "--to")
    output_file(args.out, "--out")
    if to == "prism":  # PRISM's explicit format is two files, the .tra and the .lab
        lab = Path(args.out).with_suffix(".lab")
        output_file(lab, "--out (its .lab file)")
        if lab.exists() and not Path(args.out).exists() and not args.force:
            raise UsageError(
                f"--out {args.out}: writing it would replace {lab}, which belongs to no "
                f"{Path(args.out).name}; remove it, choose another --out, or add --force"
            )
    if args.scenario is None:
        fmt = model_format(args.file, args.format, "--format")
        input_file(args.file, "model file")
    try:
        if args.scenario is not None:
            model = scenario_product_model(args.scenario)
        else:
            model = read_model(args.file, fmt)
        terminal = None
        if args.target:
            terminal = model.states_labelled(args.target[0])
            for name in args.target[1:]:
                terminal |= model.states_labelled(name)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        write_model(model, args.out, to, terminal=terminal)
    except PlannerError as err:
        raise UsageError(str(err)) from None
    return 0
