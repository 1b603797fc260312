"""Sub-commands of the ``hopnav`` CLI, one module each (listed in :data:`hopnav.cli.COMMANDS`).

The ``hopnav`` command line itself is :mod:`hopnav.cli`; it is re-exported here."""

from __future__ import annotations

from hopnav.cli import COMMANDS, build_parser, main, run_command

__all__ = ["COMMANDS", "build_parser", "main", "run_command"]
