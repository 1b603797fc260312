"""Sub-commands of the ``hopnav`` CLI; each module exposes ``register(subparsers)``.

``register`` adds one sub-parser and sets its ``func`` default to a callable taking the parsed
``argparse.Namespace`` and returning the process exit code.
"""
