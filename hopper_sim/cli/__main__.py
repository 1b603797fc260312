"""``python -m hopper_sim.cli``: the ``hopnav`` command line."""

import sys

from hopnav.cli import main

if __name__ == "__main__":
    sys.exit(main())
