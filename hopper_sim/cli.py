"""The ``hopnav`` command line (defined in :mod:`hopnav.cli`; kept here for imports)."""

from __future__ import annotations

import sys

from hopnav.cli import COMMANDS, build_parser, main, run_command

__all__ = ["COMMANDS", "build_parser", "main", "run_command"]

if __name__ == "__main__":
    sys.exit(main())
