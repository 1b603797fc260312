"""Case-study scenarios: a labelled grid world, an LTL task, rewards and runner settings.

A :class:`Scenario` is pure data, validated when it is built. Its world is a rectangle of
square cells (:mod:`planner.world`, indices in :mod:`planner.geometry`); the absorbing
``out`` state (a landing outside the world) has index ``nx * ny`` and carries the hazard
label. Each region's name is a label (an atomic proposition of the formula); a cell can carry
several labels. The reward ``W`` of a cell is the sum of the rewards of its labels (labels
without a reward give 0). ``collect`` says when it is paid: ``"once"`` (default) on the first
landing in the cell during a run, ``"every"`` on every landing (:data:`COLLECT_MODES`).

Scenario files (TOML) and the shipped case studies are read by :mod:`planner.scenario_file`
(:func:`load_scenario`, :func:`parse_scenario`; also importable from here).
"""

from __future__ import annotations

import difflib
import importlib
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from types import MappingProxyType
from typing import Any

import numpy as np

from planner.config import RunConfig
from planner.errors import (
    LTLSyntaxError,
    RegionOutsideWorldError,
    RegionOverlapError,
    ScenarioFormulaError,
    ScenarioValueError,
    StartInHazardError,
    UndefinedLabelError,
    UnknownPropositionError,
)
from planner.ltl.parser import check_propositions, parse
from planner.policy import SwitchingConfig
from planner.qlearning import QLearningConfig
from planner.world import MAX_CELLS, Cell, Rect, Region, World

__all__ = [
    "COLLECT_MODES",
    "DEFAULT_FORMULA",
    "MAX_CELLS",
    "Cell",
    "Rect",
    "Region",
    "RunnerTableConfig",
    "Scenario",
    "World",
    "ascii_map",
]

DEFAULT_FORMULA = "!Haz U Goal"

#: Limits of a scenario, checked before anything of that size is built: labelled regions,
#: rectangles and cells listed per region, the magnitude of a cell's reward, propositions of
#: the formula (the letters 2^n of its automaton). The cells of the grid: :data:`MAX_CELLS`;
#: the file: :mod:`planner.scenario_file`.
MAX_REGIONS = 64
MAX_REGION_ITEMS = 4096
MAX_REWARD = 1.0e6
MAX_PROPOSITIONS = 16

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


@dataclass(frozen=True)
class RunnerTableConfig:
    """The scenario's ``[runner]`` table (the paper's symbols in brackets).

    Each key maps onto a key of the run's configuration tree (:data:`planner.config.RUNNER_KEYS`,
    :class:`hopper_sim.navigation.config.NavigationConfig`), whose field holds the default.

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
    p_rl_ee: float = SwitchingConfig.p_rl_explore
    c: float = SwitchingConfig.c
    eps: float = SwitchingConfig.eps
    discount: float = QLearningConfig.discount
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
    p_sat: float = SwitchingConfig.p_sat
    reward_known: bool = True
    collect: str = "once"
    runner: RunnerTableConfig = field(default_factory=RunnerTableConfig)
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

    @cached_property
    def state_rewards(self) -> np.ndarray:
        """:attr:`reward_grid` in flat cell order followed by the ``out`` state's 0,
        ``(nx * ny + 1,)`` float (the reward ``W`` per state of the abstraction)."""
        w = np.append(np.asarray(self.reward_grid, dtype=float).ravel(), 0.0)
        w.flags.writeable = False
        return w

    @property
    def start_cell(self) -> int:
        """Flat index of the cell holding :attr:`start`."""
        return int(self.world.geometry.locate(self.start))

    @property
    def goal_mask(self) -> np.ndarray:
        """Boolean ``(nx, ny)`` array of the goal cells."""
        return self.region_mask(self.goal)

    def with_runner(self, **changes: Any) -> Scenario:
        """A copy with some runner settings changed (validated)."""
        return replace(self, runner=replace(self.runner, **changes))


def _scenario_from_kwargs(kwargs: dict[str, Any]) -> Scenario:
    return Scenario(**kwargs)


#: Names served by :mod:`planner.scenario_file` (which imports this module).
_FILE_NAMES = frozenset(
    {
        "SHIPPED_SCENARIOS",
        "MAX_FILE_BYTES",
        "MAX_TOML_DEPTH",
        "load_scenario",
        "parse_scenario",
        "resolve_scenario_path",
        "scenario_from_dict",
    }
)


def __getattr__(name: str) -> Any:
    if name in _FILE_NAMES:
        return getattr(importlib.import_module("planner.scenario_file"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
