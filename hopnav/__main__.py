"""``python -m hopnav ...``: the same as the ``hopnav`` console script."""

import sys

from hopnav.cli import main

if __name__ == "__main__":
    sys.exit(main())
