"""Case-study scenarios: a labelled grid world, an LTL task, rewards and runner settings.

A :class:`Scenario` is pure data, validated when it is built. The world is ``width x height``
metres with its origin at the lower-left corner, split into ``nx x ny`` square cells of side
``cell`` metres; cell ``(i, j)`` covers ``[i*cell, (i+1)*cell) x [j*cell, (j+1)*cell)`` and has
the flat index ``i * ny + j``. The absorbing ``out`` state (a landing outside the world) has
index ``nx * ny`` and carries the hazard label.

A region is a union of axis-aligned rectangles ``[x0, y0, x1, y1]`` in world metres and of
single cells ``[i, j]``. A rectangle covers the cells whose centres lie in
``[x0, x1) x [y0, y1)``; a cell-aligned rectangle therefore covers exactly the cells inside it.
Each region's name is a label (an atomic proposition of the formula); a cell can carry several
labels. The reward ``W`` of a cell is the sum of the rewards of its labels (labels without a
reward give 0). ``collect`` says when it is paid: ``"once"`` (default) on the first landing in
the cell during a run, ``"every"`` on every landing (:data:`COLLECT_MODES`).

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

    [runner]                        # all optional; see RunnerParams
    batch_size = 50
"""

from __future__ import annotations

import difflib
import math
import re
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from planner.config import RunConfig
from planner.errors import (
    LTLSyntaxError,
    MissingKeyError,
    RegionOutsideWorldError,
    RegionOverlapError,
    ScenarioError,
    ScenarioFormulaError,
    ScenarioSyntaxError,
    ScenarioTypeError,
    ScenarioValueError,
    StartInHazardError,
    UndefinedLabelError,
    UnknownKeyError,
    UnknownPropositionError,
)
from planner.ltl.parser import check_propositions, parse
from planner.policy import SwitchingSettings
from planner.qlearning import QLearningSettings
from planner.textfile import read_text
from planner.toml_lines import key_lines, line_of, nesting_depth

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

SHIPPED_SCENARIOS: tuple[str, ...] = ("a", "b", "c", "d")
"""Names of the case studies shipped as package data (``planner/scenarios/<name>.toml``)."""

DEFAULT_FORMULA = "!Haz U Goal"

#: Limits of a scenario, checked before anything of that size is built: cells of the grid,
#: labelled regions, rectangles and cells listed per region, the magnitude of a cell's
#: reward, propositions of the formula (the letters 2^n of its automaton), nesting depth
#: of the TOML and the size of the file. The transition intervals of a synthesis are dense
#: (rows x cells, :func:`planner.intervals.transition_intervals`), so memory grows with the
#: square of the cells: ``imdp export --scenario`` of 45 x 45 cells took 1.2 GB, of 64 x 64
#: 3.6 GB, of 256 x 256 it asked for 254 GiB.
MAX_CELLS = 1 << 11
MAX_REGIONS = 64
MAX_REGION_ITEMS = 4096
MAX_REWARD = 1.0e6
MAX_PROPOSITIONS = 16
MAX_TOML_DEPTH = 32
MAX_FILE_BYTES = 1 << 20

COLLECT_MODES: tuple[str, ...] = ("once", "every")
"""When a cell's reward is paid: on the first landing in it during a run, or on every landing."""
_LABEL_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def _is_proposition(label: str) -> bool:
    """Whether ``label`` is an identifier that the LTL parser reads as that proposition."""
    if not _LABEL_RE.match(label):
        return False
    try:
        return parse(label).propositions() == {label}
    except LTLSyntaxError:
        return False


Rect = tuple[float, float, float, float]
Cell = tuple[int, int]


@dataclass(frozen=True)
class World:
    """A rectangle ``[0, width) x [0, height)`` in metres, split into square cells.

    Raises:
        ScenarioValueError: on a non-positive size or cell, or a size that is not a whole
            number of cells.
    """

    width: float
    height: float
    cell: float = 1.0

    def __post_init__(self) -> None:
        for name in ("width", "height", "cell"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                key = "world.cell" if name == "cell" else "world.size"
                raise ScenarioValueError(
                    f"{name} must be positive and finite, got {value}", key=key
                )
        cells = (self.width / self.cell) * (self.height / self.cell)
        if not cells <= MAX_CELLS:
            raise ScenarioValueError(
                f"a {self.width} x {self.height} m world of {self.cell} m cells has {cells:.4g} "
                f"cells, more than the limit of {MAX_CELLS}",
                key="world.size",
            )
        for name in ("width", "height"):
            n = getattr(self, name) / self.cell
            if abs(n - round(n)) > 1e-9 * max(1.0, n):
                raise ScenarioValueError(
                    f"{name} {getattr(self, name)} m is not a whole number of {self.cell} m cells",
                    key="world.size",
                )

    @property
    def nx(self) -> int:
        """Number of cells along x."""
        return round(self.width / self.cell)

    @property
    def ny(self) -> int:
        """Number of cells along y."""
        return round(self.height / self.cell)

    @property
    def n_cells(self) -> int:
        """``nx * ny``; also the index of the ``out`` state."""
        return self.nx * self.ny

    def cell_of(self, xy: np.ndarray | Sequence[float]) -> np.ndarray:
        """Flat cell index of each point ``(..., 2)`` in metres; ``n_cells`` when outside."""
        p = np.asarray(xy, dtype=float)
        ij = np.floor(p / self.cell).astype(np.int64)
        inside = (
            (p[..., 0] >= 0)
            & (p[..., 0] < self.width)
            & (p[..., 1] >= 0)
            & (p[..., 1] < self.height)
            & (ij[..., 0] < self.nx)
            & (ij[..., 1] < self.ny)
        )
        return np.where(inside, ij[..., 0] * self.ny + ij[..., 1], self.n_cells)

    def cell_centers(self) -> np.ndarray:
        """Centres of all cells in metres, shape ``(n_cells, 2)``, flat-index order."""
        i, j = np.meshgrid(np.arange(self.nx), np.arange(self.ny), indexing="ij")
        return (np.stack([i.ravel(), j.ravel()], axis=1) + 0.5) * self.cell


@dataclass(frozen=True)
class Region:
    """A union of rectangles ``(x0, y0, x1, y1)`` in metres and of cells ``(i, j)``."""

    rects: tuple[Rect, ...] = ()
    cells: tuple[Cell, ...] = ()

    def mask(self, world: World) -> np.ndarray:
        """Boolean ``(nx, ny)`` array of the covered cells (no bounds checks; see Scenario)."""
        centers = world.cell_centers().reshape(world.nx, world.ny, 2)
        out = np.zeros((world.nx, world.ny), dtype=bool)
        if self.rects:
            r = np.asarray(self.rects, dtype=float)  # (R, 4)
            x = centers[None, :, :, 0]
            y = centers[None, :, :, 1]
            inside = (
                (x >= r[:, 0, None, None])
                & (x < r[:, 2, None, None])
                & (y >= r[:, 1, None, None])
                & (y < r[:, 3, None, None])
            )
            out |= inside.any(axis=0)
        if self.cells:
            c = np.asarray(self.cells, dtype=np.int64)
            out[c[:, 0], c[:, 1]] = True
        return out


@dataclass(frozen=True)
class RunnerParams:
    """The scenario's ``[runner]`` table (the paper's symbols in brackets).

    Each key maps onto a key of the run's configuration tree (:data:`planner.config.RUNNER_KEYS`,
    :class:`hopper_sim.config.RunnerSettings`), whose field holds the default.

    Attributes:
        batch_size: hops between two GP refits and re-syntheses.
        max_steps: hop cap of one run; reaching it ends the run as a timeout.
        p_rl_ee: probability of the RL action in the exploration phase [P_RL,ee].
        c: initial probability of the RL action in goal reaching [C].
        eps: decay rate of P_RL,gr = C exp(-eps m) per goal-reaching step m [epsilon].
        discount: discount factor of the reward Q-learning [gamma], in (0, 1).
        runs: number of consecutive runs (Q-values and learned rewards carried over).
        seed: seed of the first run.
        window: hops of the last window by which a run still undecided at ``max_steps`` is
            judged (recurrence, persistence, safety formulas; 0: the last half of the run;
            :class:`planner.verdict.MissionMonitor`).
    """

    batch_size: int = RunConfig.batch_size
    max_steps: int = RunConfig.max_steps
    p_rl_ee: float = SwitchingSettings.p_rl_explore
    c: float = SwitchingSettings.c
    eps: float = SwitchingSettings.eps
    discount: float = QLearningSettings.discount
    runs: int = RunConfig.runs
    seed: int = RunConfig.seed
    window: int = RunConfig.window

    def __post_init__(self) -> None:
        checks: dict[str, tuple[Callable[[Any], bool], str]] = {
            "batch_size": (lambda v: v >= 1, "at least 1"),
            "max_steps": (lambda v: v >= 1, "at least 1"),
            "p_rl_ee": (lambda v: 0.0 <= v <= 1.0, "in [0, 1]"),
            "c": (lambda v: 0.0 <= v <= 1.0, "in [0, 1]"),
            "eps": (lambda v: v >= 0.0 and math.isfinite(v), "finite and >= 0"),
            "discount": (lambda v: 0.0 < v < 1.0, "in (0, 1)"),
            "runs": (lambda v: v >= 1, "at least 1"),
            "seed": (lambda v: v >= 0, ">= 0"),
            "window": (lambda v: v >= 0, ">= 0"),
        }
        for name, (ok, what) in checks.items():
            value = getattr(self, name)
            if not ok(value):
                raise ScenarioValueError(f"must be {what}, got {value}", key=f"runner.{name}")


@dataclass(frozen=True)
class Scenario:
    """A case study: world, labelled regions, start, LTL task, rewards, runner settings.

    Attributes:
        name: short name (``"a"``).
        world: the grid.
        regions: label -> region. The hazard label need not have a region (the ``out`` state
            carries it anyway).
        initial: the initial region (drawn blue; not a label).
        start: start position ``(x, y)`` in metres, inside ``initial`` and not in a hazard.
        formula: LTL formula over the labels.
        rewards: label -> reward of a cell with that label (paid as ``collect`` says).
        hazard: the hazard label.
        goal: the goal label (drawn green); its cells may not carry the hazard label. A
            scenario whose formula has no goal may leave it without a region.
        p_sat: worst-case satisfaction probability that starts goal reaching [P_sat].
        reward_known: whether the planner knows ``rewards`` (else it learns them).
        collect: ``"once"``: a cell's reward is paid on the first landing in it during a run
            (later landings pay 0; a new run pays again); ``"every"``: on every landing.
        runner: runner settings.
        description: free text.

    Raises:
        ScenarioError: a subclass naming the offending key (see :mod:`planner.errors`).
    """

    name: str
    world: World
    regions: Mapping[str, Region]
    initial: Region
    start: tuple[float, float]
    formula: str = DEFAULT_FORMULA
    rewards: Mapping[str, float] = field(default_factory=dict)
    hazard: str = "Haz"
    goal: str = "Goal"
    p_sat: float = SwitchingSettings.p_sat
    reward_known: bool = True
    collect: str = "once"
    runner: RunnerParams = field(default_factory=RunnerParams)
    description: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "regions", MappingProxyType(dict(self.regions)))
        object.__setattr__(self, "rewards", MappingProxyType(dict(self.rewards)))
        object.__setattr__(self, "start", (float(self.start[0]), float(self.start[1])))
        if len(self.regions) > MAX_REGIONS:
            raise ScenarioValueError(
                f"{len(self.regions)} regions, more than the limit of {MAX_REGIONS}",
                key="regions",
            )
        named = [(label, f"regions.{label}") for label in self.regions]
        for label, key in [*named, (self.hazard, "hazard"), (self.goal, "goal")]:
            if not _is_proposition(label):
                raise ScenarioValueError(
                    f"label {label!r} is not a valid proposition name (letters, digits and "
                    "'_', not starting with a digit, not an LTL keyword such as U, F, G, X, "
                    "true)",
                    key=key,
                )
        for label, region in self.regions.items():
            self._check_region(region, f"regions.{label}")
        for label in self.regions:
            if not self.region_mask(label).any():
                raise ScenarioValueError("region covers no cell", key=f"regions.{label}")
        self._check_region(self.initial, "initial")
        if not self.initial_mask.any():
            raise ScenarioValueError("initial region covers no cell", key="initial")
        both = self.region_mask(self.goal) & self.hazard_mask
        if both.any():
            cells = [tuple(int(v) for v in c) for c in np.argwhere(both)[:5]]
            raise RegionOverlapError(
                f"goal '{self.goal}' and hazard '{self.hazard}' share cells {cells}",
                key=f"regions.{self.goal}",
            )
        x, y = self.start
        if not (0 <= x < self.world.width and 0 <= y < self.world.height):
            raise RegionOutsideWorldError(
                f"start {self.start} is outside the {self.world.width} x {self.world.height} m "
                "world",
                key="initial.start",
            )
        i, j = divmod(self.start_cell, self.world.ny)
        if self.hazard_mask[i, j]:
            raise StartInHazardError(
                f"start {self.start} is in cell ({i}, {j}), labelled '{self.hazard}'",
                key="initial.start",
            )
        if not self.initial_mask[i, j]:
            raise ScenarioValueError(
                f"start {self.start} (cell ({i}, {j})) is outside the initial region",
                key="initial.start",
            )
        for label, reward in self.rewards.items():
            if label not in self.labels:
                raise UndefinedLabelError(
                    f"reward for unknown label '{label}' (labels: {', '.join(self.labels)})",
                    key=f"rewards.{label}",
                )
            if not math.isfinite(reward):
                raise ScenarioValueError(
                    f"reward must be finite, got {reward}", key=f"rewards.{label}"
                )
        big = np.flatnonzero(~(np.abs(self.reward_grid) <= MAX_REWARD).ravel())
        if big.size:
            i, j = divmod(int(big[0]), self.world.ny)
            raise ScenarioValueError(
                f"the rewards of cell ({i}, {j}) sum to {self.reward_grid[i, j]:.4g}, beyond the "
                f"limit of +-{MAX_REWARD:g}",
                key="rewards",
            )
        if self.collect not in COLLECT_MODES:
            raise ScenarioValueError(
                f"must be one of {COLLECT_MODES}, got {self.collect!r}", key="collect"
            )
        if not 0.0 < self.p_sat <= 1.0:
            raise ScenarioValueError(f"must be in (0, 1], got {self.p_sat}", key="p_sat")
        self._check_formula()

    def __reduce__(self) -> tuple[Callable[..., Scenario], tuple[dict[str, Any]]]:
        # The mapping proxies do not pickle; rebuild from plain dicts (for worker processes).
        kwargs = {f.name: getattr(self, f.name) for f in fields(self)}
        kwargs["regions"] = dict(self.regions)
        kwargs["rewards"] = dict(self.rewards)
        return (_scenario_from_kwargs, (kwargs,))

    def _check_region(self, region: Region, key: str) -> None:
        w = self.world
        for what, items in (("rects", region.rects), ("cells", region.cells)):
            if len(items) > MAX_REGION_ITEMS:
                raise ScenarioValueError(
                    f"{len(items)} {what}, more than the limit of {MAX_REGION_ITEMS} per region",
                    key=f"{key}.{what}",
                )
        for k, (x0, y0, x1, y1) in enumerate(region.rects):
            if not (x0 < x1 and y0 < y1):
                raise ScenarioValueError(
                    f"rectangle [{x0}, {y0}, {x1}, {y1}] is empty (need x0 < x1 and y0 < y1)",
                    key=f"{key}.rects[{k}]",
                )
            if x0 < 0 or y0 < 0 or x1 > w.width or y1 > w.height:
                raise RegionOutsideWorldError(
                    f"rectangle [{x0}, {y0}, {x1}, {y1}] leaves the world "
                    f"[0, {w.width}] x [0, {w.height}] m",
                    key=f"{key}.rects[{k}]",
                )
        for k, (i, j) in enumerate(region.cells):
            if not (0 <= i < w.nx and 0 <= j < w.ny):
                raise RegionOutsideWorldError(
                    f"cell ({i}, {j}) is outside the {w.nx} x {w.ny} grid",
                    key=f"{key}.cells[{k}]",
                )

    def _check_formula(self) -> None:
        try:
            parsed = check_propositions(self.formula, self.labels)
        except UnknownPropositionError as err:
            raise UndefinedLabelError(str(err), key="formula") from err
        except LTLSyntaxError as err:
            raise ScenarioFormulaError(
                f"formula {self.formula!r} does not parse: {err}", key="formula"
            ) from err
        # A hazard or goal label that names no region and is not in the formula is a typo.
        atoms = parsed.propositions()
        if len(atoms) > MAX_PROPOSITIONS:
            raise ScenarioFormulaError(
                f"the formula uses {len(atoms)} propositions, more than the limit of "
                f"{MAX_PROPOSITIONS} (its automaton reads 2^n letters)",
                key="formula",
            )
        for key, label in (("hazard", self.hazard), ("goal", self.goal)):
            if label not in self.regions and label not in atoms:
                close = difflib.get_close_matches(label, [*self.regions, *sorted(atoms)], n=1)
                hint = f"; did you mean '{close[0]}'?" if close else ""
                raise UndefinedLabelError(
                    f"{key} label '{label}' names no region and does not occur in the "
                    f"formula {self.formula!r}{hint}",
                    key=key,
                )

    @property
    def labels(self) -> tuple[str, ...]:
        """All labels: the regions' names, then the hazard label if it has no region."""
        extra = () if self.hazard in self.regions else (self.hazard,)
        return (*self.regions, *extra)

    def region_mask(self, label: str) -> np.ndarray:
        """Boolean ``(nx, ny)`` array of the cells labelled ``label`` (all False if none)."""
        return self._masks.get(label, np.zeros((self.world.nx, self.world.ny), dtype=bool))

    @cached_property
    def _masks(self) -> dict[str, np.ndarray]:
        masks = {}
        for label, region in self.regions.items():
            m = region.mask(self.world)
            m.flags.writeable = False
            masks[label] = m
        return masks

    @property
    def hazard_mask(self) -> np.ndarray:
        """Boolean ``(nx, ny)`` array of hazard cells (the ``out`` state is not a cell)."""
        return self.region_mask(self.hazard)

    @cached_property
    def initial_mask(self) -> np.ndarray:
        """Boolean ``(nx, ny)`` array of the initial region's cells."""
        m = self.initial.mask(self.world)
        m.flags.writeable = False
        return m

    @cached_property
    def cell_labels(self) -> tuple[frozenset[str], ...]:
        """Label set of each cell, flat index ``i * ny + j`` (length ``nx * ny``)."""
        names = list(self.regions)
        if not names:
            return (frozenset(),) * self.world.n_cells
        stack = np.stack([self._masks[n].ravel() for n in names], axis=1)
        return tuple(frozenset(n for n, on in zip(names, row, strict=True) if on) for row in stack)

    @cached_property
    def state_labels(self) -> tuple[frozenset[str], ...]:
        """:attr:`cell_labels` followed by the ``out`` state's label set ``{hazard}``."""
        return (*self.cell_labels, frozenset({self.hazard}))

    def state_letters(self, propositions: Sequence[str]) -> np.ndarray:
        """Letter (bitmask over ``propositions``) of every state incl. ``out``, int64.

        Bit ``b`` is set for a state iff it carries ``propositions[b]``; propositions that
        no region defines are never set (except the hazard label on ``out``).
        """
        letters = np.zeros(self.world.n_cells + 1, dtype=np.int64)
        for bit, p in enumerate(propositions):
            on = np.append(self.region_mask(p).ravel(), p == self.hazard)
            letters |= on.astype(np.int64) << bit
        return letters

    @cached_property
    def reward_grid(self) -> np.ndarray:
        """Reward per cell, ``(nx, ny)`` float: the sum of the rewards of the cell's labels."""
        grid = np.zeros((self.world.nx, self.world.ny))
        with np.errstate(over="ignore"):  # a sum beyond the floats is refused by the caller
            for label, reward in self.rewards.items():
                grid += reward * self.region_mask(label)
        grid.flags.writeable = False
        return grid

    @property
    def start_cell(self) -> int:
        """Flat index of the cell holding :attr:`start`."""
        return int(self.world.cell_of(self.start))

    @property
    def goal_mask(self) -> np.ndarray:
        """Boolean ``(nx, ny)`` array of the goal cells."""
        return self.region_mask(self.goal)

    def with_runner(self, **changes: Any) -> Scenario:
        """A copy with some runner settings changed (validated)."""
        return replace(self, runner=replace(self.runner, **changes))


def _scenario_from_kwargs(kwargs: dict[str, Any]) -> Scenario:
    return Scenario(**kwargs)


# --------------------------------------------------------------------------- loading

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
_RUNNER_TYPES: dict[str, type] = {f.name: f.type for f in fields(RunnerParams)}  # type: ignore[misc]


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
    runner = RunnerParams(
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


def ascii_map(scenario: Scenario) -> str:
    """A text map of the grid, top row = highest y, one character per cell.

    ``@`` start, ``#`` hazard, ``G`` goal, ``s`` initial region, ``.`` unlabelled; other
    labels show a character of their own (their first unused letter; later labels in
    scenario order win where labels overlap), and a legend line follows the map.
    """
    w = scenario.world
    grid = np.full((w.nx, w.ny), ".", dtype="<U1")
    legend = {".": "no label", "s": "initial region"}
    used = {".", "s", "G", "#", "@"}
    grid[scenario.initial_mask] = "s"
    pool = "abcdefghijklmnopqrstuvwxyzABCDEFHIJKLMNOPQRSTUVWXYZ0123456789"
    for label in scenario.regions:
        if label in (scenario.goal, scenario.hazard):
            continue
        char = next((c for c in label + label.lower() + pool if c not in used), "?")
        used.add(char)
        grid[scenario.region_mask(label)] = char
        legend[char] = label
    grid[scenario.goal_mask] = "G"
    grid[scenario.hazard_mask] = "#"
    i, j = divmod(scenario.start_cell, w.ny)
    grid[i, j] = "@"
    legend.update({"G": scenario.goal, "#": scenario.hazard, "@": "start"})
    rows = ["".join(grid[:, jj]) for jj in range(w.ny - 1, -1, -1)]
    return "\n".join([*rows, "  ".join(f"{k} {v}" for k, v in legend.items())])
