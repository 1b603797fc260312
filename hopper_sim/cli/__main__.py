"""``python -m hopper_sim.cli``: the ``hopnav`` command line."""

import sys

from hopnav.cli import main

sys.exit(main())
