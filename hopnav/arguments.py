"""Checked argument types and output destinations for the ``hopnav`` commands.

The types raise :class:`argparse.ArgumentTypeError`, which argparse reports as one line with
the option's name (exit code 2). :func:`output_file` and :func:`output_folder` check a
destination before any work starts, by creating and removing a probe file in the nearest
existing folder, so that an unwritable folder fails at once (also for root, whom permission
bits do not stop, and on read-only mounts) instead of after a long run.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from hopnav.errors import UsageError


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None


def non_negative_int(text: str) -> int:
    """A whole number >= 0 (seeds)."""
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {value}")
    return value


def positive_int(text: str) -> int:
    """A whole number >= 1 (counts)."""
    value = _integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {value}")
    return value


def at_least(minimum: int, why: str = "") -> Callable[[str], int]:
    """A whole number >= ``minimum``; ``why`` is added to the message."""

    def parse(text: str) -> int:
        value = _integer(text)
        if value < minimum:
            reason = f" ({why})" if why else ""
            raise argparse.ArgumentTypeError(f"must be at least {minimum}{reason}, got {value}")
        return value

    parse.__name__ = f"at_least_{minimum}"
    return parse


def int_range(minimum: int, maximum: int, what: str = "") -> Callable[[str], int]:
    """A whole number in ``[minimum, maximum]`` (an upper bound on an input-sized
    resource); ``what`` names the resource in the message."""

    def parse(text: str) -> int:
        value = _integer(text)
        reason = f" ({what})" if what else ""
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}{reason}, got {value}")
        if value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum}{reason}, got {value}")
        return value

    parse.__name__ = f"int_range_{minimum}_{maximum}"
    return parse


def positive_float(text: str) -> float:
    """A finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value) or value <= 0.0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def _probe(folder: Path, what: str, target: Path) -> None:
    try:
        fd, probe = tempfile.mkstemp(prefix=".hopnav-probe-", dir=folder)
    except OSError as err:
        raise UsageError(
            f"{what} {target}: cannot write in folder {folder} ({err.strerror or err})"
        ) from None
    os.close(fd)
    os.unlink(probe)


def _existing_ancestor(path: Path, what: str, target: Path) -> Path:
    folder = path
    while not folder.exists():
        if folder.parent == folder:
            break
        folder = folder.parent
    if not folder.is_dir():
        raise UsageError(f"{what} {target}: {folder} is a file, not a folder")
    return folder


def output_file(
    path: str | os.PathLike[str], what: str, suffixes: Sequence[str] | None = None
) -> Path:
    """Check that ``path`` can be written (``what`` names it in errors, e.g. ``"--png"``).

    Its suffix must be one of ``suffixes`` (lower-case, with the dot) when given; it must not
    be a folder; its folder (or the nearest existing one above, which the writer creates the
    rest of) must accept a new file. Nothing is left on disk.

    Raises:
        UsageError: naming the option, the path and the problem.
    """
    target = Path(path)
    if suffixes is not None and target.suffix.lower() not in suffixes:
        raise UsageError(
            f"{what} {target}: the file must end in {' or '.join(suffixes)} "
            f"(it is written in that format)"
        )
    if target.is_dir():
        raise UsageError(f"{what} {target}: is a folder, not a file")
    parent = target.parent if str(target.parent) else Path(".")
    _probe(_existing_ancestor(parent, what, target), what, target)
    return target


def figure_file(path: str | os.PathLike[str], what: str) -> Path:
    """Check that a figure can be written at ``path``: its extension names a format of
    :data:`hopper_sim.viz.figure_files.FIGURE_FORMATS` (``.png``, ``.svg``, ``.pdf``), and
    :func:`output_file` accepts it.

    Raises:
        UsageError: naming the option, the path and the problem.
    """
    from hopper_sim.viz.figure_files import FIGURE_FORMATS

    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in FIGURE_FORMATS:
        raise UsageError(
            f"{what} {target}: unknown figure format {suffix or '(no extension)'!r}; the file "
            f"must end in {', '.join(FIGURE_FORMATS)} (it is written in that format)"
        )
    return output_file(target, what)


def output_folder(path: str | os.PathLike[str], what: str) -> Path:
    """Check that files can be written in folder ``path`` (created later if missing).

    Raises:
        UsageError: ``path`` is a file, or the folder (or the nearest existing one above)
            does not accept a new file.
    """
    target = Path(path)
    if target.exists() and not target.is_dir():
        raise UsageError(f"{what} {target}: is a file, not a folder")
    _probe(_existing_ancestor(target, what, target), what, target)
    return target


def input_file(path: str | os.PathLike[str], what: str) -> Path:
    """An existing, readable file.

    Raises:
        UsageError: it does not exist, is a folder or cannot be read.
    """
    target = Path(path)
    if not target.exists():
        raise UsageError(f"{what} {target}: no such file")
    if target.is_dir():
        raise UsageError(f"{what} {target}: is a folder, not a file")
    if not os.access(target, os.R_OK):
        raise UsageError(f"{what} {target}: cannot be read")
    return target


def add_set_argument(parser: argparse.ArgumentParser) -> None:
    """The repeatable ``--set KEY=VALUE`` of the commands that run the navigation loop."""
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change a setting of the run's configuration tree, e.g. --set switching.c=0.75 "
        "(repeatable; after the scenario's [runner] table and p_sat; `hopnav config` lists "
        "the keys and defaults)",
    )


def run_config(
    scenario: Any,
    items: Sequence[str],
    flags: Mapping[str, tuple[str, Any]],
    base: Any = None,
) -> Any:
    """The configuration tree of a run: ``scenario``'s (``None``: ``base``, the shipped
    defaults), then the given ``flags`` (tree key -> (option, value or ``None`` where not
    given)), then the ``--set`` ``items``.

    Raises:
        UsageError: a malformed, unknown or ambiguous key, a wrong type or a value out of
            range (naming the option and the key), or a key set by a flag and ``--set``.
    """
    from hopper_sim.navigation.config import (
        ConfigError,
        NavigationConfig,
        parse_assignments,
        resolve_key,
    )

    try:
        if scenario is None:
            config = NavigationConfig() if base is None else base
        else:
            config = NavigationConfig.from_scenario(scenario, base)
        given = {key: v for key, (_, v) in flags.items() if v is not None}
        for key, value in given.items():
            config = config.override({key: value}, source=flags[key][0])
        sets = parse_assignments(items)
        for key in sets:
            full = resolve_key(key, "--set: ")
            if full in given:
                raise UsageError(f"--set {key}: {full} is also given by {flags[full][0]}")
        return config.override(sets, text=True, source="--set")
    except ConfigError as err:
        raise UsageError(str(err)) from None
