"""The pipeline's nouns are importable from the two packages, lazily."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import hopnav
import hopper_sim
import planner

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("package", [planner, hopper_sim])
def test_every_export_resolves(package):
    for name in package.__all__:
        assert getattr(package, name) is not None, name
        assert name in dir(package)
    assert package.__version__ == hopnav.__version__
    with pytest.raises(AttributeError):
        package.no_such_name  # noqa: B018


def test_exports_are_the_defining_objects():
    from hopper_sim.navigation.runner import NavigationRunner
    from planner.imdp import solve
    from planner.ltl.parser import parse

    assert hopper_sim.NavigationRunner is NavigationRunner
    assert planner.solve is solve and planner.parse_formula is parse


def test_importing_the_packages_is_cheap():
    code = (
        "import sys, planner, hopper_sim; "
        "print(sorted(m for m in ('torch', 'mujoco', 'numba', 'gpytorch', 'rerun') "
        "if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True
    ).stdout
    assert out.strip() == "[]"
