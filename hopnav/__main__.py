"""``python -m hopnav ...``: the same as the ``hopnav`` console script."""

import sys

try:
    from hopnav.cli import entry
except KeyboardInterrupt:  # Ctrl-C while Python was still starting
    sys.stderr.write("hopnav: interrupted\n")
    sys.exit(1)

if __name__ == "__main__":
    sys.exit(entry())
