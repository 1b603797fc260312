"""Scenario files: TOML text to a validated :class:`~planner.scenario.Scenario`, and the
case studies shipped with the package.

Scenario files are TOML; :func:`load_scenario` reads one (or a shipped case study by name,
``a`` to ``d``) and reports problems with the key and the line. The format::

    name = "a"                      # required
    description = "..."             # optional
    formula = "!Haz U Goal"         # LTL over the labels (default shown)
    hazard = "Haz"                  # the label of hazards and of the out state (default)
    goal = "Goal"                   # the goal label, kept apart from the hazard (default)
    p_sat = 0.65                    # switch to goal reaching above this probability
    reward_known = true             # false: rewards are learned from visits
    collect = "once"                # "once": a cell pays on its first landing of a run;
                                    # "every": on every landing

    [world]
    size = [15.0, 15.0]             # metres (width, height), required
    cell = 1.0                      # metres

    [initial]                       # the initial region and the start position
    rects = [[1.0, 6.0, 3.0, 9.0]]
    start = [1.5, 7.5]              # metres, required

    [regions.Goal]                  # one table per label
    rects = [[13.0, 6.0, 15.0, 9.0]]
    cells = [[12, 7]]

    [rewards]                       # per label, collected on landing
    A = 20.0

    [runner]                        # all optional; see RunnerTableConfig
    batch_size = 50

:func:`parse_scenario` and :func:`scenario_from_dict` take the text and the parsed table.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Iterable
from dataclasses import fields
from importlib import resources
from pathlib import Path
from typing import Any

from planner._util.textfile import read_text
from planner._util.toml_lines import key_lines, line_of, nesting_depth
from planner.errors import (
    MissingKeyError,
    ScenarioError,
    ScenarioSyntaxError,
    ScenarioTypeError,
    UnknownKeyError,
)
from planner.scenario import DEFAULT_FORMULA, RunnerTableConfig, Scenario
from planner.world import Region, World

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

SHIPPED_SCENARIOS: tuple[str, ...] = ("a", "b", "c", "d")
"""Names of the case studies shipped as package data (``planner/scenarios/<name>.toml``)."""

#: Limits of a scenario file, checked before it is parsed: nesting depth of the TOML and
#: the size of the file [bytes].
MAX_TOML_DEPTH = 32
MAX_FILE_BYTES = 1 << 20

_TOP_KEYS = {
    "name",
    "description",
    "formula",
    "hazard",
    "goal",
    "p_sat",
    "reward_known",
    "collect",
    "world",
    "initial",
    "regions",
    "rewards",
    "runner",
}
_RUNNER_TYPES: dict[str, type] = {f.name: f.type for f in fields(RunnerTableConfig)}  # type: ignore[misc]


class _Reader:
    """Typed access to the parsed TOML, raising errors that carry key paths."""

    def __init__(self, data: dict[str, Any]) -> None:
        self.data = data

    @staticmethod
    def _type_name(value: Any) -> str:
        return {bool: "boolean", int: "integer", float: "float", str: "string"}.get(
            type(value), type(value).__name__
        )

    def table(self, parent: dict[str, Any], key: str, path: str, required: bool) -> dict:
        if key not in parent:
            if required:
                where = f"table [{path.rpartition('.')[0]}]" if "." in path else "top-level table"
                raise MissingKeyError(f"missing required key (in the {where})", key=path)
            return {}
        value = parent[key]
        if not isinstance(value, dict):
            raise ScenarioTypeError(f"must be a table, got {self._type_name(value)}", key=path)
        return value

    def scalar(
        self, parent: dict, key: str, path: str, kind: str, default: Any = ..., required=False
    ) -> Any:
        if key not in parent:
            if required or default is ...:
                where = f"table [{path.rpartition('.')[0]}]" if "." in path else "top-level table"
                raise MissingKeyError(f"missing required key (in the {where})", key=path)
            return default
        return self.convert(parent[key], path, kind)

    def convert(self, value: Any, path: str, kind: str) -> Any:
        if kind == "str" and isinstance(value, str):
            return value
        if kind == "bool" and isinstance(value, bool):
            return value
        if kind == "int" and isinstance(value, int) and not isinstance(value, bool):
            return value
        if (
            kind == "float"
            and isinstance(value, (int, float))
            and not isinstance(value, bool)
            and math.isfinite(value)
        ):
            return float(value)
        want = {"str": "a string", "bool": "a boolean", "int": "an integer", "float": "a number"}
        raise ScenarioTypeError(
            f"must be {want[kind]}, got {self._type_name(value)} {value!r}", key=path
        )

    def vector(self, value: Any, path: str, n: int, kind: str) -> tuple:
        if not isinstance(value, list) or len(value) != n:
            raise ScenarioTypeError(
                f"must be an array of {n} {'integers' if kind == 'int' else 'numbers'}, "
                f"got {value!r}",
                key=path,
            )
        return tuple(self.convert(v, f"{path}[{k}]", kind) for k, v in enumerate(value))

    def vectors(self, parent: dict, key: str, path: str, n: int, kind: str) -> tuple:
        value = parent.get(key, [])
        if not isinstance(value, list):
            raise ScenarioTypeError(f"must be an array of arrays, got {value!r}", key=path)
        return tuple(self.vector(v, f"{path}[{k}]", n, kind) for k, v in enumerate(value))

    def region(self, table: dict, path: str, extra: Iterable[str] = ()) -> Region:
        allowed = {"rects", "cells", *extra}
        self.no_unknown(table, allowed, path)
        if "rects" not in table and "cells" not in table:
            raise MissingKeyError(
                f"a region needs 'rects' (metres) and/or 'cells' (indices) in [{path}]",
                key=f"{path}.rects",
            )
        return Region(
            rects=self.vectors(table, "rects", f"{path}.rects", 4, "float"),
            cells=self.vectors(table, "cells", f"{path}.cells", 2, "int"),
        )

    @staticmethod
    def no_unknown(table: dict, allowed: Iterable[str], path: str) -> None:
        allowed = set(allowed)
        for key in table:
            if key not in allowed:
                full = f"{path}.{key}" if path else key
                raise UnknownKeyError(
                    f"unknown key (allowed here: {', '.join(sorted(allowed))})", key=full
                )


def scenario_from_dict(data: dict[str, Any]) -> Scenario:
    """Build a :class:`Scenario` from parsed TOML (see the module doc for the format).

    Raises:
        ScenarioError: a subclass naming the key (without a line; see :func:`parse_scenario`).
    """
    r = _Reader(data)
    r.no_unknown(data, _TOP_KEYS, "")
    world_t = r.table(data, "world", "world", required=True)
    r.no_unknown(world_t, {"size", "cell"}, "world")
    if "size" not in world_t:
        raise MissingKeyError("missing required key (in the table [world])", key="world.size")
    width, height = r.vector(world_t["size"], "world.size", 2, "float")
    world = World(width, height, r.scalar(world_t, "cell", "world.cell", "float", 1.0))

    initial_t = r.table(data, "initial", "initial", required=True)
    initial = r.region(initial_t, "initial", extra=("start",))
    if "start" not in initial_t:
        raise MissingKeyError("missing required key (in the table [initial])", key="initial.start")
    start = r.vector(initial_t["start"], "initial.start", 2, "float")

    regions_t = r.table(data, "regions", "regions", required=True)
    regions = {}
    for label, table in regions_t.items():
        path = f"regions.{label}"
        if not isinstance(table, dict):
            raise ScenarioTypeError(
                f"must be a table with 'rects' and/or 'cells', got {r._type_name(table)}",
                key=path,
            )
        regions[label] = r.region(table, path)

    rewards_t = r.table(data, "rewards", "rewards", required=False)
    rewards = {k: r.convert(v, f"rewards.{k}", "float") for k, v in rewards_t.items()}

    runner_t = r.table(data, "runner", "runner", required=False)
    r.no_unknown(runner_t, _RUNNER_TYPES, "runner")
    runner = RunnerTableConfig(
        **{
            k: r.convert(v, f"runner.{k}", "int" if _RUNNER_TYPES[k] in (int, "int") else "float")
            for k, v in runner_t.items()
        }
    )

    return Scenario(
        name=r.scalar(data, "name", "name", "str", required=True),
        description=r.scalar(data, "description", "description", "str", ""),
        world=world,
        regions=regions,
        initial=initial,
        start=start,
        formula=r.scalar(data, "formula", "formula", "str", DEFAULT_FORMULA),
        rewards=rewards,
        hazard=r.scalar(data, "hazard", "hazard", "str", "Haz"),
        goal=r.scalar(data, "goal", "goal", "str", "Goal"),
        p_sat=r.scalar(data, "p_sat", "p_sat", "float", Scenario.p_sat),
        reward_known=r.scalar(data, "reward_known", "reward_known", "bool", True),
        collect=r.scalar(data, "collect", "collect", "str", "once"),
        runner=runner,
    )


def parse_scenario(text: str, source: str = "<string>") -> Scenario:
    """Parse and validate scenario TOML ``text``; errors carry the key, line and ``source``.

    Raises:
        ScenarioSyntaxError: the text is not TOML (line from tomllib's message).
        ScenarioError: any other problem (a subclass), located at the key's line.
    """
    depth, line = nesting_depth(text)
    if depth > MAX_TOML_DEPTH:
        raise ScenarioSyntaxError(
            f"arrays or tables nested {depth} deep, more than the limit of {MAX_TOML_DEPTH}",
            line=line,
            source=source,
        )
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        match = re.search(r"line (\d+)", str(err))
        line = int(match.group(1)) if match else getattr(err, "lineno", None)
        raise ScenarioSyntaxError(f"malformed TOML: {err}", line=line, source=source) from err
    except ValueError as err:  # tomllib's int() of a number with thousands of digits
        raise ScenarioSyntaxError(f"malformed TOML: {err}", source=source) from None
    try:
        return scenario_from_dict(data)
    except ScenarioError as err:
        lines = key_lines(text)
        line = line_of(lines, err.key) if err.key is not None else None
        if line is None and err.key is not None and "." in err.key:
            line = line_of(lines, err.key.rpartition(".")[0])
        if line is None:
            line = 1  # the top-level table starts at line 1
        raise err.located(line, source) from err


def resolve_scenario_path(name_or_path: str | Path) -> Path:
    """The file of a shipped case study (``"a"``..``"d"``) or the given path.

    Raises:
        ScenarioError: neither a shipped name nor an existing file.
    """
    text = str(name_or_path)
    if text in SHIPPED_SCENARIOS:
        return Path(str(resources.files("planner") / "scenarios" / f"{text}.toml"))
    path = Path(text)
    if not path.is_file():
        raise ScenarioError(
            f"no scenario '{text}': not a shipped name ({', '.join(SHIPPED_SCENARIOS)}) "
            "and not an existing file"
        )
    return path


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a shipped case study by name (``"a"``..``"d"``) or a scenario TOML file by path.

    Raises:
        ScenarioError: a subclass naming the problem, the key and the line.
    """
    path = resolve_scenario_path(name_or_path)
    text = read_text(path, ScenarioError, MAX_FILE_BYTES)
    return parse_scenario(text, source=str(path))
