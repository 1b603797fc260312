"""Run a case study: ``python scripts/run_simulation.py [--scenario a] [--runs N] ...``.

The same as ``hopnav run`` (all its options apply): writes the rerun recording and the figure
under ``runs/`` and prints the summary table.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hopper_sim.cli import main
from planner.allocator import reuse_freed_memory_unless_disabled

if __name__ == "__main__":
    reuse_freed_memory_unless_disabled()  # as the hopnav command does
    sys.exit(main(["run", *sys.argv[1:]]))
