"""Every script in examples/ runs (from an unrelated folder) and prints what it promises."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"

EXPECT = {
    "01_one_hop.py": ([], ["steady hop: lands at", "controller: alpha"]),
    "02_abstraction.py": ([], ["GP prior only", "after 400 landings"]),
    "03_closed_loop.py": (["--max-steps", "25"], ["synthesis after   0 hops", "run ended:"]),
    "04_small_sweep.py": (["--out", "{tmp}/sweep", "--max-steps", "6"], ["Table I", "rows:"]),
    "05_ltl_imdp_check.py": (["--out", "{tmp}/c.drn"], ["pessimistic: P(!Haz U Goal)"]),
}


def test_every_example_is_tested():
    assert sorted(p.name for p in EXAMPLES.glob("*.py")) == sorted(EXPECT)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(EXPECT))
def test_example_runs(name, tmp_path):
    args, needles = EXPECT[name]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *(a.format(tmp=tmp_path) for a in args)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    for needle in needles:
        assert needle in proc.stdout, proc.stdout
