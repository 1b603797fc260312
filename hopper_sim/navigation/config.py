"""The configuration tree of a navigation run: every setting once, overridden by name.

:class:`NavigationConfig` is the root; its sections are the dataclasses of the code that uses
them, each default defined once, in its field::

    run                 planner.config.RunConfig             schedule: batch, cap, runs, seed
    planner             planner.config.PlannerConfig   abstraction and synthesis
    planner.switching   planner.policy.SwitchingConfig     P_RL,ee, C, eps, P_sat
    planner.q_learning  planner.qlearning.QLearningConfig  gamma, alpha, epsilon, prior
    env                 hopper_sim.navigation.environment.EnvConfig
                                                             terrain, noise, thrust switches
    gp                  planner.gp.GPConfig fields        changes to the derived GP prior
    map_resolution, torch_threads                            the runner's own

A key is the dotted path of a leaf (``planner.switching.c``); any unique dotted tail of it is
accepted too (``switching.c``, ``c``). Build a tree with :func:`default_config` or from a
scenario (:meth:`NavigationConfig.from_scenario`: its TOML ``[runner]`` table and ``p_sat``,
mapped by :data:`planner.config.RUNNER_KEYS`), then change it with
``config.override({"switching.c": 0.75})`` (``hopnav run --set switching.c=0.75``). Unknown
keys, wrong types and values out of range raise :class:`ConfigError`, one line naming the key.

Not in the tree: the landing noise nu (``planner.noise``, ``gp.noise``; the MJCF's, set by the
runner) and the GP prior's action tables (``gp.n_actions``, ``gp.coupled``); a whole
:class:`~planner.gp.GPConfig` may still be given in Python as ``gp_prior``.
"""

from __future__ import annotations

import difflib
import math
import typing
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields, is_dataclass, replace
from types import MappingProxyType
from typing import Any

from hopper_sim.errors import HopperSimError
from hopper_sim.navigation.environment import EnvConfig
from planner.config import P_SAT_KEY, RUNNER_KEYS, RunConfig
from planner.errors import PlannerError, ScenarioError
from planner.gp.landing import GPConfig
from planner.learning import PlannerConfig
from planner.scenario import RunnerTableConfig, Scenario

#: leaves the runner derives (from the MJCF, the grid): never set by key
DERIVED: frozenset[str] = frozenset({"planner.noise"})
#: the fields of :class:`~planner.gp.GPConfig` that the ``gp`` section may change
GP_KEYS: tuple[str, ...] = tuple(
    f.name for f in fields(GPConfig) if f.name not in ("noise", "n_actions", "coupled")
)
#: field type of the ``gp`` section's leaves (tables may be set to one number)
_GP_TYPES = {"max_data": int, "num_threads": int | None}


class ConfigError(HopperSimError, ValueError):
    """A key, type or value of the configuration tree is wrong (the message names the key)."""


@dataclass(frozen=True)
class NavigationConfig:
    """The root of the run's configuration tree (see the module docstring).

    Attributes:
        run: when the run re-synthesises and stops, its seed and number of runs.
        planner: the abstraction, synthesis and exploration settings, with the switching
            policy's (``planner.switching``, ``P_sat`` among them) and the reward's Q-learning
            settings (``planner.q_learning``, the one ``discount``).
        env: physics switches (terrain, noise, thrust, terrain seed, CoM paths).
        gp: changes (field name -> value) to the landing-error model's prior, which is
            derived from the scene and the controller
            (:func:`hopper_sim.controller.error_prior.error_prior`) or is ``gp_prior``.
        gp_prior: a whole prior instead of the derived one (Python only; ``None``: derived).
        map_resolution: GP map points per cell and axis in :class:`SynthesisEvent`.
        torch_threads: torch intra-op threads during a run (the controller's and the GPs'
            small batches run fastest on one thread; restored after the run).
    """

    run: RunConfig = field(default_factory=RunConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    env: EnvConfig = field(default_factory=EnvConfig)
    gp: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    gp_prior: GPConfig | None = None
    map_resolution: int = 2
    torch_threads: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "gp", MappingProxyType(dict(self.gp)))
        for name in ("map_resolution", "torch_threads"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"{name}: must be a whole number >= 1, got {value!r}")
        if self.env.terrain_seed < 0:
            raise ConfigError(f"env.terrain_seed: must be >= 0, got {self.env.terrain_seed}")
        unknown = sorted(set(self.gp) - set(GP_KEYS))
        if unknown:
            raise ConfigError(f"gp.{unknown[0]}: unknown key ({_allowed('gp.', GP_KEYS)})")
        _check_scenario_range(self)

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        # the mapping proxy does not pickle; rebuild from a plain dict (for worker processes)
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values["gp"] = dict(self.gp)
        return (_settings_from_kwargs, (values,))

    # ------------------------------------------------------------------ building
    @classmethod
    def from_scenario(
        cls, scenario: Scenario, base: NavigationConfig | None = None
    ) -> NavigationConfig:
        """``base`` (default: :func:`default_config`) with the scenario's ``[runner]`` table
        and ``p_sat`` (:data:`planner.config.RUNNER_KEYS`)."""
        base = cls() if base is None else base
        rp = scenario.runner
        values = {RUNNER_KEYS[f.name]: getattr(rp, f.name) for f in fields(rp)}
        values[P_SAT_KEY] = scenario.p_sat
        return base.override(values, source=f"scenario {scenario.name}")

    def apply_to(self, scenario: Scenario) -> Scenario:
        """``scenario`` with its ``[runner]`` table and ``p_sat`` set from this tree (what the
        runner runs, recordings and figures show)."""
        return replace(scenario, runner=self.runner_params(), p_sat=self.planner.switching.p_sat)

    def runner_params(self) -> RunnerTableConfig:
        """This tree's values of the scenario's ``[runner]`` keys."""
        leaves = self.leaves()
        return RunnerTableConfig(**{k: leaves[key] for k, key in RUNNER_KEYS.items()})

    # ------------------------------------------------------------------ keys
    def leaves(self) -> dict[str, Any]:
        """Every settable key -> its value (``gp`` keys: the change, or ``None`` for the
        prior's own value)."""
        out = dict(_walk(self, ""))
        for name in GP_KEYS:
            out[f"gp.{name}"] = self.gp.get(name)
        return out

    def override(
        self, changes: Mapping[str, Any], *, text: bool = False, source: str | None = None
    ) -> NavigationConfig:
        """A copy with ``changes`` (key -> value) applied, checked.

        Args:
            changes: keys (full or a unique dotted tail) and values; with ``text`` the values
                are strings, parsed by the type of their field (``true``/``false``,
                whole numbers, numbers, ``none`` for an optional one, else a string).
            source: where the changes come from, for the messages (e.g. ``"--set"``).

        Raises:
            ConfigError: one line naming the key: unknown or ambiguous, a wrong type, a
                value out of range.
        """
        where = f"{source}: " if source else ""
        resolved: dict[str, Any] = {}
        for key, value in changes.items():
            full = resolve_key(key, where)
            if full in resolved:
                raise ConfigError(f"{where}{full}: given twice ({key!r})")
            resolved[full] = _typed(full, value, text, where)
        config = self
        for full, value in resolved.items():
            try:
                config = _set(config, full.split("."), value)
            except ConfigError as err:
                raise ConfigError(f"{where}{err}") from None
            except (PlannerError, ValueError, TypeError) as err:
                raise ConfigError(f"{where}{full}: {' '.join(str(err).split())}") from None
        return config


def default_config() -> NavigationConfig:
    """The shipped defaults (each the default of its dataclass field)."""
    return NavigationConfig()


def _settings_from_kwargs(values: dict[str, Any]) -> NavigationConfig:
    return NavigationConfig(**values)


def _walk(node: Any, prefix: str) -> Iterator[tuple[str, Any]]:
    for f in fields(node):
        key, value = f"{prefix}{f.name}", getattr(node, f.name)
        if key in DERIVED or (not prefix and f.name in ("gp", "gp_prior")):
            continue
        if is_dataclass(value):
            yield from _walk(value, f"{key}.")
        else:
            yield key, value


def _all_keys() -> tuple[str, ...]:
    return tuple(default_config().leaves())


def _allowed(prefix: str, names: Sequence[str]) -> str:
    return f"keys here: {', '.join(prefix + n for n in names)}"


def resolve_key(key: str, where: str = "") -> str:
    """The full key of ``key`` (a full key or a unique dotted tail of one).

    Raises:
        ConfigError: no key or several keys match, or ``key`` is derived (not settable).
    """
    if not isinstance(key, str) or not key:
        raise ConfigError(f"{where}expected a key such as switching.c, got {key!r}")
    if key in DERIVED or (key.endswith(".noise") and key.split(".")[0] in ("planner", "gp")):
        raise ConfigError(
            f"{where}{key}: derived from the MJCF's landing noise, not settable (see "
            "models/README.md)"
        )
    keys = _all_keys()
    if key in keys:
        return key
    matches = [k for k in keys if k.endswith("." + key)]
    if len(matches) == 1:
        return matches[0]
    if matches:
        raise ConfigError(f"{where}{key}: ambiguous, name one of {', '.join(matches)}")
    near = difflib.get_close_matches(key, keys, n=3, cutoff=0.6) or [
        k
        for k in keys
        if k.rpartition(".")[2]
        in difflib.get_close_matches(
            key.rpartition(".")[2], [k.rpartition(".")[2] for k in keys], n=3, cutoff=0.6
        )
    ]
    hint = f"did you mean {' or '.join(near[:3])}? " if near else ""
    raise ConfigError(f"{where}{key}: unknown key ({hint}`hopnav config` lists the keys)")


def _field_type(full: str) -> Any:
    parts = full.split(".")
    if parts[0] == "gp":
        return _GP_TYPES.get(parts[1], float)
    node: Any = NavigationConfig
    for name in parts:
        hints = typing.get_type_hints(node)
        node = hints[name]
    return node


def _typed(full: str, value: Any, text: bool, where: str) -> Any:
    kind = _field_type(full)
    optional = typing.get_origin(kind) in (typing.Union, _union_type()) and type(None) in (
        typing.get_args(kind)
    )
    base = next((t for t in typing.get_args(kind) if t is not type(None)), kind)
    if text:
        value = _parse(full, str(value), base, optional, where)
    if value is None and optional:
        return None
    ok = {
        bool: isinstance(value, bool),
        int: isinstance(value, int) and not isinstance(value, bool),
        float: isinstance(value, int | float) and not isinstance(value, bool),
        str: isinstance(value, str),
    }.get(base, True)
    if not ok:
        want = {bool: "a boolean", int: "a whole number", float: "a number", str: "a string"}
        none = " or none" if optional else ""
        raise ConfigError(
            f"{where}{full}: must be {want[base]}{none}, got {type(value).__name__} {value!r}"
        )
    if base is float:
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"{where}{full}: must be a finite number, got {value}")
    return value


def _union_type() -> Any:
    import types

    return types.UnionType


def _parse(full: str, text: str, base: Any, optional: bool, where: str) -> Any:
    low = text.strip().lower()
    if optional and low in ("none", "null"):
        return None
    try:
        if base is bool:
            if low in ("true", "yes", "on", "1"):
                return True
            if low in ("false", "no", "off", "0"):
                return False
            raise ValueError
        if base is int:
            return int(text)
        if base is float:
            return float(text)
    except ValueError:
        want = {bool: "true or false", int: "a whole number", float: "a number"}[base]
        none = " or none" if optional else ""
        raise ConfigError(f"{where}{full}: expected {want}{none}, got {text!r}") from None
    return text


def _set(node: Any, path: list[str], value: Any) -> Any:
    if path[0] == "gp":
        return replace(node, gp={**node.gp, path[1]: _check_gp(path[1], value)})
    if len(path) == 1:
        return replace(node, **{path[0]: value})
    return replace(node, **{path[0]: _set(getattr(node, path[0]), path[1:], value)})


def _check_gp(name: str, value: Any) -> Any:
    GPConfig(**{name: value})  # the prior's own checks (on its defaults otherwise)
    return value


def _check_scenario_range(config: NavigationConfig) -> None:
    """The scenario's rules for its keys (they must hold for :meth:`apply_to`)."""
    try:
        config.runner_params()
    except ScenarioError as err:
        name = (err.key or "").removeprefix("runner.")
        raise ConfigError(f"{RUNNER_KEYS.get(name, name)}: {err.problem}") from None
    p_sat = config.planner.switching.p_sat
    if not 0.0 < p_sat <= 1.0:
        raise ConfigError(f"{P_SAT_KEY}: must be in (0, 1], got {p_sat}")


def parse_assignments(items: Sequence[str], what: str = "--set") -> dict[str, str]:
    """``["key=value", ...]`` -> ``{key: value}`` (values as text, for
    :meth:`NavigationConfig.override` with ``text=True``).

    Raises:
        ConfigError: an item without ``=`` or with an empty key, or a key given twice.
    """
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"{what} {item!r}: expected KEY=VALUE, e.g. switching.c=0.75")
        if key in out:
            raise ConfigError(f"{what} {key}: given twice")
        out[key] = value.strip()
    return out


def describe(config: NavigationConfig) -> list[tuple[str, str]]:
    """(key, value as text) of every leaf, in tree order (``gp`` keys: ``(prior)`` where
    unchanged)."""
    rows = []
    for key, value in config.leaves().items():
        if key.startswith("gp.") and value is None:
            text = "(prior)"
        elif isinstance(value, bool):
            text = str(value).lower()
        elif value is None:
            text = "none"
        else:
            text = str(value)
        rows.append((key, text))
    return rows
