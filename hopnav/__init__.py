"""hopnav, the application: its version and the ``hopnav`` command line.

The libraries are :mod:`planner` (pure planning: LTL, interval MDPs, synthesis, learned
intervals) and :mod:`hopper_sim` (the MuJoCo hopper, its controller, the navigation loop).
This package holds only what the command line needs before it knows which command runs, so
that ``hopnav --help`` imports none of them.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
