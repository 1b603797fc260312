"""The package layout rules of docs/architecture.md, checked on the source.

- no module of ``hopnav``, ``hopper_sim`` or ``planner`` over 500 lines;
- no function or method over 80 lines, except file and formula parsers (listed below, each
  a reader of one grammar) and numba kernels (compiled loops, decorated with ``njit``/``jit``);
- ``hopper_sim``'s modules live in its layer folders (docs/architecture.md), none at the top
  level but the package's ``__init__`` and its error base;
- the planner never imports MuJoCo, dm_control or the simulation.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hopnav", "hopper_sim", "planner")
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80
PARSERS = {
    # (module path relative to the repository, function name): the grammar it reads
    ("planner/imdp/io/prism.py", "read_prism"): "PRISM explicit files",
    ("planner/imdp/io/drn.py", "read_drn"): "Storm DRN files",
    ("planner/ltl/hoa.py", "_from_hoa"): "HOA v1 automata",
}
LAYERS = {"physics", "controller", "navigation", "experiments", "viz", "cli", "models", "data"}


def _modules() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def _is_kernel(node: ast.FunctionDef) -> bool:
    for dec in node.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name in ("njit", "jit"):
            return True
    return False


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_module_and_function_sizes(path: Path) -> None:
    text = path.read_text()
    lines = len(text.splitlines())
    rel = str(path.relative_to(ROOT))
    assert lines <= MAX_MODULE_LINES, f"{rel}: {lines} lines > {MAX_MODULE_LINES}"
    long = []
    for node in ast.walk(ast.parse(text)):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        size = node.end_lineno - node.lineno + 1
        if size > MAX_FUNCTION_LINES and not _is_kernel(node) and (rel, node.name) not in PARSERS:
            long.append(f"{node.name} ({size} lines)")
    assert not long, f"{rel}: functions over {MAX_FUNCTION_LINES} lines: {', '.join(long)}"


def test_parser_exemptions_name_existing_functions() -> None:
    for rel, name in PARSERS:
        tree = ast.parse((ROOT / rel).read_text())
        assert any(isinstance(n, ast.FunctionDef) and n.name == name for n in ast.walk(tree)), (
            f"{rel} has no function {name}: drop the exemption"
        )


def test_hopper_sim_modules_live_in_layer_folders() -> None:
    allowed = ("__init__.py", "errors.py")
    top = sorted(p.name for p in (ROOT / "hopper_sim").glob("*.py") if p.name not in allowed)
    assert top == [], f"modules outside the layer folders: {top}"
    # a folder counts if it holds files (a pulled checkout may keep an emptied one's caches)
    folders = {
        p.name
        for p in (ROOT / "hopper_sim").iterdir()
        if p.is_dir() and p.name != "__pycache__" and any(f.is_file() for f in p.iterdir())
    }
    assert folders <= LAYERS, f"folders that are not layers: {sorted(folders - LAYERS)}"


def test_planner_imports_no_simulation() -> None:
    banned = ("mujoco", "dm_control", "hopper_sim")
    for path in sorted((ROOT / "planner").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            else:
                continue
            bad = [n for n in names if n.split(".")[0] in banned]
            assert not bad, f"{path.relative_to(ROOT)}:{node.lineno} imports {bad}"
