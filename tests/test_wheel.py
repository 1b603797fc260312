"""Build a wheel, install it into a fresh virtual environment and use it from an unrelated
folder: a hop, a short navigation run, --version, python -m hopnav.

Cheap but honest: the wheel is built from a copy of the tracked sources without build
isolation (nothing is downloaded), and installed with ``--no-deps --no-index`` into a new
venv whose only link to this environment is a ``.pth`` line naming this environment's
site-packages, for the dependencies (torch, MuJoCo, ...). A ``.pth`` line adds a folder to
``sys.path`` without running the ``.pth`` files inside it, so the editable install of this
checkout stays inactive there; the test checks that every hopnav module comes from the
fresh venv and that no source tree is on ``sys.path``. Set ``HOPNAV_SKIP_WHEEL=1`` to skip
it locally; CI runs it.
"""

from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = [
    pytest.mark.slow,
    pytest.mark.wheel,
    pytest.mark.skipif(
        os.environ.get("HOPNAV_SKIP_WHEEL") == "1", reason="HOPNAV_SKIP_WHEEL=1 skips the wheel"
    ),
]


def _tracked_sources(dest: Path) -> None:
    """Copy the files git tracks (or, without git, the source tree less build outputs)."""
    try:
        names = subprocess.run(
            [
                "git",
                "-C",
                str(ROOT),
                "ls-files",
                "-z",
                "--cached",
                "--others",
                "--exclude-standard",
            ],
            capture_output=True,
            check=True,
        ).stdout.split(b"\0")
    except (OSError, subprocess.CalledProcessError):
        ignore = shutil.ignore_patterns(".git", ".venv", "runs", "build", "dist", "*.egg-info")
        shutil.copytree(ROOT, dest, ignore=ignore)
        return
    for raw in filter(None, names):
        src = ROOT / raw.decode()
        if src.is_file():
            target = dest / raw.decode()
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, target)


def _run(cmd: list[str], cwd: Path, env: dict[str, str], timeout: int = 600):
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{cmd}\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
    return proc


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> tuple[Path, dict[str, str], Path]:
    """(venv python, environment without PYTHONPATH, an unrelated working folder)."""
    base = tmp_path_factory.mktemp("wheel")
    src = base / "src"
    _tracked_sources(src)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    wheels = base / "dist"
    build = ["wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", str(wheels)]
    _run([sys.executable, "-m", "pip", *build, "./src"], base, env)
    (wheel,) = wheels.glob("hopnav-*.whl")
    venv = base / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], base, env)
    python = venv / "bin" / "python"
    purelib = Path(
        _run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            base,
            env,
        ).stdout.strip()
    )
    deps = [*site.getsitepackages(), sysconfig.get_paths()["purelib"]]
    (purelib / "_hopnav_test_dependencies.pth").write_text("\n".join(dict.fromkeys(deps)) + "\n")
    _run([str(python), "-m", "pip", "install", "--no-deps", "--no-index", str(wheel)], base, env)
    elsewhere = base / "elsewhere"
    elsewhere.mkdir()
    return python, env, elsewhere


def test_modules_and_data_come_from_the_wheel(installed):
    python, env, cwd = installed
    code = (
        "import json, sys, importlib.metadata as md, hopnav, planner, hopper_sim\n"
        "from hopper_sim.physics import constants\n"
        "from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT\n"
        "from planner.scenario import resolve_scenario_path\n"
        "print(json.dumps({'files': [hopnav.__file__, planner.__file__, hopper_sim.__file__,\n"
        "  str(constants.SCENE_XML), str(DEFAULT_CHECKPOINT), str(resolve_scenario_path('a'))],\n"
        "  'version': md.version('hopnav'), 'path': sys.path}))"
    )
    info = json.loads(_run([str(python), "-c", code], cwd, env).stdout)
    venv = python.parent.parent.resolve()
    for path in info["files"]:
        assert Path(path).resolve().is_relative_to(venv), path
        assert Path(path).is_file(), path
    assert not any(Path(p).resolve() == ROOT for p in info["path"] if p)
    import hopnav

    assert info["version"] == hopnav.__version__


def test_console_script_and_python_m(installed):
    python, env, cwd = installed
    hopnav_bin = python.parent / "hopnav"
    import hopnav

    out = _run([str(hopnav_bin), "--version"], cwd, env).stdout.strip()
    assert out == f"hopnav {hopnav.__version__}"
    assert "COMMAND" in _run([str(hopnav_bin), "--help"], cwd, env).stdout
    assert _run([str(python), "-m", "hopnav", "--version"], cwd, env).stdout.strip() == out


def test_a_hop_and_a_short_navigation_run(installed):
    python, env, cwd = installed
    hopnav_bin = str(python.parent / "hopnav")
    gait = ["--vel", "2.5", "0", "-2.4", "--alpha", "1.324", "--beta", "0.1", "--json"]
    hop = json.loads(_run([hopnav_bin, "hop", *gait], cwd, env).stdout)
    assert hop["ok"] is True and len(hop["next_pos"]) == 2
    proc = _run([hopnav_bin, "run", "--scenario", "a", "--max-steps", "30", "--json"], cwd, env)
    (run,) = json.loads(proc.stdout)
    assert run["outcome"] in ("success", "violation", "timeout") and 1 <= run["steps"] <= 30
    assert run["provenance"]["git_commit"] is None  # an installed wheel is not a checkout
    assert run["provenance"]["scenario"] == "a"
    assert (cwd / "runs" / "a.rrd").is_file() and (cwd / "runs" / "a.png").is_file()
