"""``hopnav automaton FORMULA``: translate LTL to a deterministic Rabin automaton."""

from __future__ import annotations

import argparse
import sys
import time

from hopnav.arguments import at_least, positive_float, positive_int
from hopnav.errors import UsageError


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "automaton",
        description=(
            "Translate an LTL formula (Spot syntax) to a complete deterministic state-based "
            "Rabin automaton and print it as HOA v1 (default) or Graphviz DOT."
        ),
    )
    p.add_argument("formula", help='LTL formula, e.g. "!Haz U Goal"')
    p.add_argument("--dot", action="store_true", help="print Graphviz DOT instead of HOA")
    p.add_argument(
        "--stats", action="store_true", help="print states, pairs and translation time only"
    )
    p.add_argument(
        "--ap",
        nargs="+",
        metavar="NAME",
        help="alphabet in letter-bit order (default: the formula's propositions, sorted)",
    )
    add_translation_limits(p)
    p.set_defaults(func=run)


def add_translation_limits(p: argparse.ArgumentParser) -> None:
    """The options ``--max-states``, ``--max-letters``, ``--max-seconds`` of a command that
    translates a formula (read back by :func:`translation_limits`)."""
    # the defaults are planner.ltl.budget.TranslationLimits' (not imported here: it needs scipy)
    p.add_argument(
        "--max-states",
        type=positive_int,
        help="most states of any automaton built on the way [20000]",
    )
    p.add_argument("--max-letters", type=at_least(2), help="most letters 2^|AP| [65536]")
    p.add_argument("--max-seconds", type=positive_float, help="time limit of the translation [10]")


def translation_limits(args: argparse.Namespace):
    """The :class:`planner.ltl.budget.TranslationLimits` of the options, defaults elsewhere."""
    from planner.ltl.budget import TranslationLimits

    given = {
        "max_letters": args.max_letters,
        "max_states": args.max_states,
        "max_seconds": args.max_seconds,
    }
    return TranslationLimits(**{k: v for k, v in given.items() if v is not None})


def run(args: argparse.Namespace) -> int:
    from planner.errors import PlannerError
    from planner.ltl.dot import to_dot
    from planner.ltl.hoa import to_hoa
    from planner.ltl.translate import translate

    limits = translation_limits(args)
    try:
        t0 = time.perf_counter()
        aut = translate(args.formula, args.ap, limits)
        elapsed = time.perf_counter() - t0
    except PlannerError as err:
        raise UsageError(str(err)) from None
    if args.stats:
        print(f"states: {aut.n_states}")
        print(f"pairs: {len(aut.pairs)}")
        print(f"propositions: {' '.join(aut.propositions)}")
        print(f"time_s: {elapsed:.4f}")
    elif args.dot:
        sys.stdout.write(to_dot(aut, title=args.formula))
    else:
        sys.stdout.write(to_hoa(aut, name=args.formula))
    return 0
