"""``hopnav replay FILE.rrd``: open a recording in the rerun viewer, or summarise it.

The viewer opens when a display is available (``DISPLAY`` or ``WAYLAND_DISPLAY`` set) and the
``rerun`` viewer executable is found; otherwise (or with ``--summary``/``--json``) the command
prints what the recording holds: entities, timelines, and per run the number of hops and the
outcome (runs are numbered from 1, as in the entity paths ``run_K``). Opening the file in the
viewer shows the layout sent with it (one tab per run, see :mod:`hopper_sim.viz.rerun_blueprint`).
The file is always read and checked first, so a missing or corrupt file fails with a message
and exit code 2 in both modes.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from hopnav.errors import UsageError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "replay",
        description=__doc__,
    )
    p.add_argument("file", help="the .rrd recording")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--summary", action="store_true", help="print the summary, no viewer")
    mode.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def viewer_command() -> list[str] | None:
    """The command that opens the rerun viewer, or ``None`` when no display/viewer exists."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return None
    exe = shutil.which("rerun")
    if exe is None:  # the viewer installed beside this interpreter (venv not on PATH)
        beside = Path(sys.executable).with_name("rerun")
        exe = str(beside) if beside.is_file() and os.access(beside, os.X_OK) else None
    return [exe] if exe else None


def run(args: argparse.Namespace) -> int:
    from hopper_sim.viz.recording import RecordingError
    from hopper_sim.viz.recording_reader import format_summary, summarize_recording

    try:
        summary = summarize_recording(args.file)
    except RecordingError as err:
        raise UsageError(str(err)) from None
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    viewer = None if args.summary else viewer_command()
    if viewer is None:
        print(format_summary(summary))
        return 0
    return subprocess.call([*viewer, str(args.file)])
