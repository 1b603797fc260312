"""Sub-commands of the ``hopnav`` CLI, one module each (listed in :data:`hopnav.cli.COMMANDS`).

Each module exposes ``register(subparsers)``: it adds one sub-parser and sets its ``func``
default to a callable taking the parsed ``argparse.Namespace`` and returning the exit code.
A module imports only the standard library at the top (the heavy libraries inside the
function that runs the command), raises :class:`hopnav.errors.UsageError` for bad input and
:class:`hopnav.errors.RunFailed` for a run that did not complete, and checks every output
destination with :mod:`hopnav.arguments` before the work starts.
"""
