"""Benchmark scripts that reach into the planner's internals still run (on small sizes):
they patch module attributes that a refactoring can rename without any test noticing."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_certified_parts_runs_and_the_in_turn_solve_matches():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_certified_parts.py"), "--size", "24"],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "identical solutions: True" in proc.stdout, proc.stdout
    assert "ratio defaults/chain_lu" in proc.stdout
