"""The command line's shape: lazy commands, --version, python -m hopnav, one-line usage
errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import hopnav
from hopnav.cli import COMMANDS, build_parser

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("torch", "numba", "mujoco", "gpytorch", "rerun", "dm_control", "matplotlib", "scipy")

PROBE = """
import sys
from hopnav.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
heavy = sorted(m for m in {heavy!r} if m in sys.modules)
print("HEAVY", ",".join(heavy), "CODE", code, file=sys.stderr)
"""


def heavy_imports(*args: str) -> tuple[list[str], str]:
    proc = subprocess.run(
        [sys.executable, "-c", PROBE.format(heavy=HEAVY), *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    line = next(x for x in proc.stderr.splitlines() if x.startswith("HEAVY"))
    names = line.split()[1] if len(line.split()) > 3 else ""
    return [n for n in names.split(",") if n], line.split()[-1]


def test_help_and_version_import_no_heavy_library():
    for args in (["--help"], ["--version"], []):
        heavy, code = heavy_imports(*args)
        assert heavy == [], (args, heavy)
        assert code == ("2" if not args else "0")


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_each_command_help_imports_no_heavy_library(command):
    heavy, code = heavy_imports(command, "--help")
    assert heavy == [] and code == "0", (command, heavy)


def test_validation_errors_come_before_heavy_imports():
    heavy, code = heavy_imports("run", "--seed", "-3")
    assert heavy == [] and code == "2"
    heavy, code = heavy_imports("train-controller", "--samples", "0")
    assert heavy == [] and code == "2"


def test_every_command_module_is_listed():
    cli = ROOT / "hopper_sim" / "cli"
    modules = {p.stem for p in cli.glob("*.py") if not p.stem.startswith("__")}
    listed = {module.rsplit(".", 1)[1] for module, _ in COMMANDS.values()}
    assert modules == listed
    parser = build_parser("*")  # every command registers with its module's own parser
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(sub.choices) == set(COMMANDS)


def test_version_and_python_m_hopnav():
    proc = subprocess.run(
        [sys.executable, "-m", "hopnav", "--version"], capture_output=True, text=True, cwd=ROOT
    )
    assert proc.returncode == 0 and proc.stdout.strip() == f"hopnav {hopnav.__version__}"
    proc = subprocess.run(
        [sys.executable, "-m", "hopnav", "automaton", "!Haz U Goal", "--stats"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert proc.returncode == 0 and "states: 3" in proc.stdout


def test_unknown_command_and_option_are_one_line(hopnav):
    from tests.hopnav.conftest import assert_one_line_failure

    assert_one_line_failure(hopnav("fly"), 2, "invalid choice: 'fly'")
    assert_one_line_failure(hopnav("run", "--fast"), 2, "unrecognized arguments: --fast")
    assert_one_line_failure(hopnav("run", "--runs", "x"), 2, "--runs", "'x'")


def test_an_unexpected_error_is_one_line(hopnav, monkeypatch):
    from hopper_sim.cli import automaton
    from tests.hopnav.conftest import assert_one_line_failure

    def broken(args):
        raise RuntimeError("boom\nsecond line")

    monkeypatch.setattr(automaton, "run", broken)
    line = assert_one_line_failure(hopnav("automaton", "F a"), 1, "RuntimeError: boom")
    assert "HOPNAV_DEBUG=1" in line
    monkeypatch.setenv("HOPNAV_DEBUG", "1")
    with pytest.raises(RuntimeError):
        hopnav("automaton", "F a")


def test_kernel_notice(capsys):
    from hopnav.kernels import prepare_kernels

    prepare_kernels("hopnav test", after=0.0)
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("hopnav test: preparing the value-iteration kernels")
    assert err[1].startswith("hopnav test: kernels ready in")
    prepare_kernels("hopnav test", quiet=True, after=0.0)
    assert capsys.readouterr().err == ""


FIRST_SYNTHESIS = """
import numba
import numpy as np
from planner.imdp.kernels import components, pruning, rows, search, sweeps, upper
from planner.warmup import compile_kernels

def signatures():
    return {f"{m.__name__}.{n}": len(d.signatures)
            for m in (components, pruning, rows, search, sweeps, upper)
            for n, d in vars(m).items() if isinstance(d, numba.core.registry.CPUDispatcher)}

compile_kernels()
before = signatures()
from planner.gp.landing import LandingErrorGP
from planner.imdp.grid import GridWorld
from planner.learning import resynthesise
from planner.ltl.translate import translate
from planner.scenario import load_scenario
sc = load_scenario("a")
w = sc.world
grid = GridWorld(w.nx, w.ny, w.cell, sc.cell_labels, sc.hazard)
reward = np.append(np.asarray(sc.reward_grid, float).ravel(), 0.0)
none = np.zeros((0, 2))
resynthesise(LandingErrorGP(), grid, translate(sc.formula), none, none, reward=reward,
             initial_cell=sc.start_cell)
after = signatures()
assert sum(before.values()) > 0, before
print("NEW", {n: after[n] - before[n] for n in after if after[n] != before[n]})
"""


@pytest.mark.slow
def test_first_synthesis_compiles_nothing_after_the_warm_up():
    proc = subprocess.run(
        [sys.executable, "-c", FIRST_SYNTHESIS],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.strip().splitlines()[-1] == "NEW {}"


def test_an_interrupt_inside_a_compiled_kernel_counts_as_an_interrupt():
    """CPython turns a Ctrl-C handled inside a numba function into a SystemError whose cause
    is the KeyboardInterrupt; the commands report it as an interruption, not a failure."""
    from hopnav.errors import is_interrupt

    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as ki:
            raise SystemError("returned a result with an exception set") from ki
    except SystemError as err:
        assert is_interrupt(err)
    assert not is_interrupt(SystemError("something else"))
    assert not is_interrupt(ValueError("bad"))
