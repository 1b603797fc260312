"""The ``hopnav`` command line: one sub-command per module, imported only when it runs.

:data:`COMMANDS` maps each command to the module that defines it and its one-line help. A
module exposes ``register(subparsers)``, which adds one sub-parser and sets its ``func``
default to a callable taking the parsed :class:`argparse.Namespace` and returning the exit
code. Only the module of the command on the command line is imported (``hopnav --help`` and
``hopnav --version`` import none of them, nor torch, numba, MuJoCo or rerun), so a new
command is one module plus one line here.

Errors follow :mod:`hopnav.errors`: one line on stderr, exit code 2 for bad input, 1 for a
failed or interrupted run. SIGTERM is handled as Ctrl-C (SIGINT): the command stops, keeps
what it finished, removes its temporary files and says so in one line.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any, NoReturn

from hopnav import __version__
from hopnav.errors import EXIT_FAILED, EXIT_USAGE, CommandError, is_interrupt
from hopnav.interrupts import interrupt_here
from planner.allocator import reuse_freed_memory_unless_disabled

#: command -> (module, one-line help), in the order ``hopnav --help`` lists them.
COMMANDS: dict[str, tuple[str, str]] = {
    "run": (
        "hopper_sim.cli.run",
        "run a case study (default: scenario a) with recording, figure and summary",
    ),
    "sweep": (
        "hopper_sim.cli.sweep",
        "reproduce Table I: reward / steps over P_RL,ee = C x eps, with 95 %% CIs",
    ),
    "config": (
        "hopper_sim.cli.config",
        "print a run's configuration tree (every --set key with its value)",
    ),
    "scenario": (
        "hopper_sim.cli.scenario",
        "validate a scenario (shipped name a-d or a TOML path) and print its map",
    ),
    "replay": (
        "hopper_sim.cli.replay",
        "open a .rrd recording in the rerun viewer, or print its summary headlessly",
    ),
    "hop": (
        "hopper_sim.cli.hop",
        "simulate one hop (or one per stdin line with --jsonl) and print the result",
    ),
    "automaton": (
        "hopper_sim.cli.automaton",
        "translate an LTL formula to a deterministic Rabin automaton (HOA on stdout)",
    ),
    "figure": (
        "hopper_sim.cli.figure",
        "draw Figure 4 (runs scenarios or reads recordings) or the Table I plot",
    ),
    "imdp": ("hopper_sim.cli.imdp", "solve or convert interval MDP files"),
    "train-controller": (
        "hopper_sim.cli.train_controller",
        "generate hop data with MuJoCo, train the hop MLP, write a controller checkpoint",
    ),
}


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (``prog: message``), exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: {message} (see {self.prog} --help)\n")


class _Subparsers:
    """The ``subparsers`` a command module registers with: fills in the help of
    :data:`COMMANDS` when the module gives none."""

    def __init__(self, action: argparse._SubParsersAction) -> None:
        self._action = action

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser:
        kwargs.setdefault("help", COMMANDS[name][1] if name in COMMANDS else None)
        kwargs.setdefault("description", kwargs["help"])
        return self._action.add_parser(name, **kwargs)


def build_parser(command: str | None = "*") -> Parser:
    """The parser with ``command``'s sub-parser defined in full (``"*"``: every command;
    ``None``: none, only their names and help)."""
    parser = Parser(
        prog="hopnav",
        description=(
            "Multi-task navigation of a MuJoCo SLIP hopper: LTL tasks, reward tasks and "
            "online learning of terrain perturbations. `hopnav COMMAND --help` shows a "
            "command's options."
        ),
    )
    parser.add_argument("--version", action="version", version=f"hopnav {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module, text) in COMMANDS.items():
        if command in ("*", name):
            importlib.import_module(module).register(_Subparsers(sub))
        else:
            sub.add_parser(name, help=text, add_help=False)
    return parser


def _say(prog: str, message: str) -> None:
    sys.stderr.write(f"{prog}: {message}\n")
    sys.stderr.flush()


def run_command(args: argparse.Namespace) -> int:
    """Call ``args.func(args)`` under the error convention; returns the exit code."""
    prog = getattr(args, "prog", None) or f"hopnav {args.command}"
    try:
        return int(args.func(args) or 0)
    except CommandError as err:
        _say(prog, err.one_line())
        return err.exit_code
    except KeyboardInterrupt:
        _say(prog, "interrupted")
        return EXIT_FAILED
    except BrokenPipeError:
        # the reader of stdout went away (`hopnav ... | head`): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_FAILED
    except Exception as err:
        if os.environ.get("HOPNAV_DEBUG"):
            raise
        if is_interrupt(err):  # Ctrl-C inside a compiled kernel
            _say(prog, "interrupted")
            return EXIT_FAILED
        if isinstance(err, OSError) and err.filename is not None:
            message = f"{err.strerror or err}: {err.filename}"
        else:
            text = " ".join(str(err).split())
            message = f"{type(err).__name__}: {text}" if text else type(err).__name__
        _say(prog, f"{message} (HOPNAV_DEBUG=1 shows the traceback)")
        return EXIT_FAILED


def _terminated(signum: int, frame: Any) -> None:
    if interrupt_here(signum, frame):  # else delivered again later
        raise KeyboardInterrupt(f"signal {signum}")


@contextmanager
def _signals_as_interrupt() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt inside the block (main thread only), so that the
    interrupt handling of the commands (keep finished results, remove temporary files)
    applies to it too, and so does SIGINT, both deferred where an exception cannot land
    safely (numba, torch, an import, a thread pool starting: :mod:`hopnav.interrupts`);
    the previous handlers are restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    kinds = (signal.SIGTERM, signal.SIGINT)
    previous = [signal.signal(k, _terminated) for k in kinds]
    try:
        yield
    finally:
        for k, handler in zip(kinds, previous, strict=True):
            signal.signal(k, handler)


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default: ``sys.argv[1:]``), run the command, return its exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    with _signals_as_interrupt():
        try:
            parser = build_parser(command if command in COMMANDS else None)
            args = parser.parse_args(argv)
        except KeyboardInterrupt:
            _say(f"hopnav {command}" if command in COMMANDS else "hopnav", "interrupted")
            return EXIT_FAILED
        return run_command(args)


def entry() -> int:
    """The console script: :func:`main`, then Ctrl-C is ignored while Python shuts down (the
    command has finished and said so; unloading torch takes a second, and an interrupt then
    would end the process without a word). Before it, the process's allocator is set to
    reuse freed large arrays (:mod:`planner.allocator`; ``HOPNAV_REUSE_FREED_MEMORY=0``
    leaves it as it is)."""
    reuse_freed_memory_unless_disabled()
    try:
        code = main()
    except KeyboardInterrupt:  # between the command's end and the line below
        _say("hopnav", "interrupted")
        code = EXIT_FAILED
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code


if __name__ == "__main__":
    sys.exit(entry())
