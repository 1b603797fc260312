"""README's Python snippets run as written, and its two commands are the ones CI uses."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_ci_installs_and_tests_as_the_readme_says():
    commands = re.findall(r"```bash\n(python3 -m venv .*?)\n```", README)
    assert len(commands) == 2
    ci = (ROOT / ".ci" / "run").read_text()
    steps = [s.strip() for s in commands[1].split("&&")]
    lines = [x.strip() for x in ci.splitlines() if x.strip() and not x.startswith("#")]
    for step in steps:
        assert step in lines, step
    assert "pip install ." in commands[0] and commands[0].endswith("hopnav run")
    assert "issue" not in README.lower() and "DESIGN.md" not in README


@pytest.mark.slow
@pytest.mark.parametrize("index", [0, 1])
def test_python_snippets_run(index, tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", README, flags=re.S)
    assert len(blocks) == 2
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-c", blocks[index]],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
