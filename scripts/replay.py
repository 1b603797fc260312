"""Replay a rerun recording: ``python scripts/replay.py FILE.rrd`` (same as ``hopnav replay``)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hopper_sim.cli import main

if __name__ == "__main__":
    sys.exit(main(["replay", *sys.argv[1:]]))
