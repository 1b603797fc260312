"""The configuration tree: every default defined once, every setting used, errors by key."""

from __future__ import annotations

import ast
import dataclasses
import sys
import typing
from pathlib import Path

import numpy as np
import pytest

import hopper_sim.navigation.runner as runner_module
from hopper_sim.navigation.config import (
    DERIVED,
    GP_KEYS,
    ConfigError,
    NavigationConfig,
    default_config,
    describe,
    parse_assignments,
    resolve_key,
)
from hopper_sim.navigation.environment import HopperGridEnv
from hopper_sim.navigation.runner import NavigationRunner, run_single
from planner.errors import ScenarioError
from planner.gp.landing import GPConfig, LandingErrorGP
from planner.policy import SwitchingPolicy
from planner.scenario import load_scenario, parse_scenario

ROOT = Path(__file__).resolve().parents[3]
PACKAGES = ("hopnav", "hopper_sim", "planner")

#: Definitions of a leaf's *name* that are other settings (or results), not that leaf.
OTHER_SETTINGS = {
    ("hopper_sim/physics/batch.py", "simulate_hops()", "thrust"): "a bare hop batch's switch, off",
    ("hopper_sim/physics/hop.py", "simulate_hop()", "thrust"): "a bare hop's switch, off",
    ("hopper_sim/controller/tracking.py", "track_random_actions()", "noise"): "tracking study",
    ("hopper_sim/controller/optimizer.py", "CostWeights", "eps"): "a cost weight",
    ("hopper_sim/controller/training.py", "TrainConfig", "batch_size"): "training batches",
    ("hopper_sim/controller/error_prior.py", "calibrate()", "seed"): "the calibration's seed",
    ("hopper_sim/experiments/sweep_grid.py", "SweepSpec", "runs"): "runs per sweep cell",
    ("hopper_sim/experiments/sweep_grid.py", "SweepSpec", "seed"): "the sweep's base seed",
    ("planner/gp/landing.py", "FitReport", "offset_std"): "a fit's result",
    ("planner/verdict.py", "MissionReport", "window"): "a run's result",
    ("planner/gp/sgpr.py", "rbf_sparse_gp()", "lengthscale"): "a stand-alone GP, not the run's",
}


def _owners() -> dict[str, tuple[str, str]]:
    """Leaf key -> (file, class) of the dataclass field that defines its default."""
    out: dict[str, tuple[str, str]] = {}

    def walk(cls: type, prefix: str) -> None:
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            kind = hints[f.name]
            if f"{prefix}{f.name}" in (*DERIVED, "gp", "gp_prior"):
                continue  # the MJCF's noise; the gp section is GPConfig' (below)
            if dataclasses.is_dataclass(kind):
                walk(kind, f"{prefix}{f.name}.")
            else:
                source = Path(sys.modules[cls.__module__].__file__).relative_to(ROOT)
                out[f"{prefix}{f.name}"] = (str(source), cls.__name__)

    walk(NavigationConfig, "")
    gp_file = str(Path(sys.modules[GPConfig.__module__].__file__).relative_to(ROOT))
    out.update({f"gp.{name}": (gp_file, "GPConfig") for name in GP_KEYS})
    return out


def _literal(node: ast.expr) -> bool:
    """A literal default (``None`` means "not given", not a value, and is left out)."""
    if isinstance(node, ast.UnaryOp):
        node = node.operand
    return isinstance(node, ast.Constant) and node.value is not None


def _definitions(names: set[str]) -> list[tuple[str, str, str]]:
    """(file, class or ``function()``, name) of every dataclass field or keyword default with
    a literal value and one of ``names``, in the packages' source."""
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = str(path.relative_to(ROOT))
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ClassDef):
                    for st in node.body:
                        if (
                            isinstance(st, ast.AnnAssign)
                            and isinstance(st.target, ast.Name)
                            and st.target.id in names
                            and st.value is not None
                            and _literal(st.value)
                        ):
                            found.append((rel, node.name, st.target.id))
                elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    a = node.args
                    pos = a.posonlyargs + a.args
                    pairs = [*zip(pos[len(pos) - len(a.defaults) :], a.defaults, strict=True)]
                    pairs += [(k, d) for k, d in zip(a.kwonlyargs, a.kw_defaults, strict=True)]
                    for arg, default in pairs:
                        if default is not None and arg.arg in names and _literal(default):
                            found.append((rel, f"{node.name}()", arg.arg))
    return found


def test_no_default_is_defined_twice():
    owners = _owners()
    assert set(owners) == set(default_config().leaves())
    canonical = {(file, cls, key.rpartition(".")[2]) for key, (file, cls) in owners.items()}
    found = _definitions({key.rpartition(".")[2] for key in owners})
    twice = [d for d in found if d not in canonical and d not in OTHER_SETTINGS]
    assert twice == [], twice
    # every leaf's own field is among the definitions found (the scan sees them)
    missing = {c for c in canonical if c not in found}
    assert all(name in ("beta",) for _, _, name in missing), missing  # beta's default: None
    # the known repetitions of the issue are gone: p_sat and discount defined once
    for name in ("p_sat", "discount", "c", "eps", "delta", "samples_per_axis", "candidates"):
        mine = [d for d in found if d[2] == name and d not in OTHER_SETTINGS]
        assert len(mine) == 1, mine


def test_a_planted_duplicate_is_found(tmp_path, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    (tmp_path / "planner").mkdir()
    (tmp_path / "planner" / "x.py").write_text(
        "def f(*, p_sat=0.65, delta=None):\n    pass\n\nclass S:\n    discount: float = 0.9\n"
    )
    found = _definitions({"p_sat", "delta", "discount"})
    assert found == [("planner/x.py", "f()", "p_sat"), ("planner/x.py", "S", "discount")]


# --------------------------------------------------------------------------- every leaf used


def _changed(key: str, value: object) -> object:
    """A valid value other than ``value`` for ``key``."""
    special = {
        "planner.candidates": "accepting",
        "planner.tour": "coverage",
        "planner.beta": 3.5,
        "gp.num_threads": 2,
        "gp.max_data": 1500,
        "gp.field_correlation": 0.5,
        "gp.scale": 0.5,
    }
    if key in special:
        return special[key]
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 3
    if key.startswith("gp."):
        return 0.37
    assert isinstance(value, float), key
    return value * 0.5 if value > 0 else 0.25


class _Stop(Exception):
    """Ends a spied run once the settings have reached their consumers."""


@pytest.fixture(scope="module")
def scenario_c():
    return load_scenario("c")  # an unknown reward: the Q-learner is built too


@pytest.fixture(scope="module")
def env_c(scenario_c):
    return HopperGridEnv(scenario_c)


def _observe(scenario, settings, env, monkeypatch) -> dict[str, object]:
    """Build the runner and start a run, recording what reaches each consumer: the
    re-synthesis settings passed to ``resynthesise``, the switching policy's settings, the
    GP's prior, the torch threads, the Q-learner's settings, the environment's, the loop's
    schedule and the map of the synthesis events."""
    seen: dict[str, object] = {}

    def spy_resynthesise(*args, settings=None, **kwargs):
        seen["synthesis"] = settings
        return RESULT[0]

    def spy_policy(self, settings, rl=None):
        seen["switching"] = settings
        raise _Stop

    real_gp_init = LandingErrorGP.__init__

    def spy_gp(self, settings=None):
        seen["gp"] = settings
        real_gp_init(self, settings)

    monkeypatch.setattr(runner_module, "resynthesise", spy_resynthesise)
    monkeypatch.setattr(SwitchingPolicy, "__init__", spy_policy)
    monkeypatch.setattr(LandingErrorGP, "__init__", spy_gp)
    monkeypatch.setattr(runner_module, "torch_threads", _Threads(seen))
    runner = NavigationRunner(scenario, env=env, settings=settings)
    with pytest.raises(_Stop):
        runner.run(0)
    seen["learner"] = runner.learner.settings
    seen["env"] = runner.env.settings
    seen["schedule"] = runner.scenario.runner
    seen["p_sat_shown"] = runner.scenario.p_sat
    seen["map_points"] = runner.map_x.size // scenario.world.nx
    return seen


class _Threads:
    """Stands in for :func:`planner._util.torch_threads.torch_threads`, recording ``n``."""

    def __init__(self, seen: dict) -> None:
        self.seen = seen

    def __call__(self, n):
        from planner._util.torch_threads import torch_threads

        self.seen["torch_threads"] = n
        return torch_threads(n)


RESULT: list = []


@pytest.fixture(scope="module")
def prior_synthesis(scenario_c, env_c):
    """One real re-synthesis (the spied runs reuse it)."""
    runner = NavigationRunner(scenario_c, env=env_c)
    gp = LandingErrorGP(runner.gp_settings)
    RESULT[:] = [runner._synthesise(gp, [], [], [], None)]
    yield
    RESULT.clear()


def _consumer_value(key: str, seen: dict) -> object:
    section, _, name = key.partition(".")
    if section == "run":
        return getattr(seen["schedule"], name)
    if key.startswith("planner.switching."):
        return getattr(seen["switching"], key.rpartition(".")[2])
    if key.startswith("planner.q_learning."):
        return getattr(seen["learner"], key.rpartition(".")[2])
    if section == "planner":
        return getattr(seen["synthesis"], name)
    if section == "env":
        return getattr(seen["env"], name)
    if section == "gp":
        value = getattr(seen["gp"], name)
        return value[0][0] if isinstance(value, tuple) else value
    if key == "map_resolution":
        return seen["map_points"]
    return seen[key]


@pytest.mark.parametrize("key", sorted(default_config().leaves()))
def test_every_setting_reaches_its_consumer(key, scenario_c, env_c, prior_synthesis, monkeypatch):
    base = NavigationConfig.from_scenario(scenario_c)
    default = base.leaves()[key]
    if key.startswith("gp."):
        default = _consumer_value(key, _observe(scenario_c, base, env_c, monkeypatch))
        monkeypatch.undo()
    value = _changed(key, default)
    assert value != default
    settings = base.override({key: value})
    env = None if key.startswith("env.") else env_c
    seen = _observe(scenario_c, settings, env, monkeypatch)
    assert _consumer_value(key, seen) == value, key
    # the shared settings are one object: the synthesis' P_sat and discount are the policy's
    # and the learner's
    assert seen["synthesis"].switching == seen["switching"]
    assert seen["synthesis"].q_learning == seen["learner"]
    assert seen["p_sat_shown"] == seen["switching"].p_sat


def test_the_schedule_and_discount_drive_a_real_run(scenario_c, env_c):
    settings = NavigationConfig.from_scenario(scenario_c).override(
        {"run.max_steps": 5, "run.batch_size": 2, "run.window": 3, "discount": 0.5}
    )
    runner = NavigationRunner(scenario_c, env=env_c, settings=settings)
    end = runner.run(0)
    assert end.steps <= 5
    assert [r.step for r in end.resyntheses] == [s for s in (0, 2, 4) if s <= end.steps][
        : len(end.resyntheses)
    ]
    if end.outcome in ("timeout", "satisfying"):
        assert end.steps == 5 and end.mission.window == 3
    assert runner.learner.settings.discount == 0.5


def test_runs_and_seed_drive_run_many(scenario_c, env_c, monkeypatch):
    settings = NavigationConfig.from_scenario(scenario_c).override({"runs": 3, "run.seed": 7})
    runner = NavigationRunner(scenario_c, env=env_c, settings=settings)
    seeds = []
    monkeypatch.setattr(runner, "run", lambda seed, run_index=0: seeds.append(seed))
    runner.run_many()
    assert seeds == [7, 8, 9]


def test_python_callers_set_p_sat_once():
    from planner.learning import PlannerConfig
    from planner.policy import SwitchingConfig

    s = PlannerConfig(switching=SwitchingConfig(p_sat=0.8))
    assert s.p_sat == 0.8 and SwitchingPolicy(s.switching).settings.p_sat == 0.8
    c = default_config().override({"p_sat": 0.8})
    assert c.planner.p_sat == c.planner.switching.p_sat == 0.8


# --------------------------------------------------------------------------- building


def test_default_and_scenario_trees(scenario_c):
    d = default_config()
    assert d == NavigationConfig() and d.planner.p_sat == 0.65 and d.planner.discount == 0.95
    c = NavigationConfig.from_scenario(scenario_c)
    assert c.run.runs == scenario_c.runner.runs == 10
    assert c.apply_to(scenario_c) == scenario_c
    text = (ROOT / "planner" / "scenarios" / "a.toml").read_text()
    text = text.replace("c = 0.5", "c = 0.3").replace("p_sat = 0.65", "p_sat = 0.7")
    sc = parse_scenario(text)
    t = NavigationConfig.from_scenario(sc)
    assert t.planner.switching.c == 0.3 and t.planner.switching.p_sat == 0.7


def test_override_by_full_key_or_unique_tail():
    c = default_config()
    assert c.override({"switching.c": 0.75}).planner.switching.c == 0.75
    assert c.override({"planner.switching.c": 0.75}) == c.override({"c": 0.75})
    assert resolve_key("q_learning.discount") == "planner.q_learning.discount"
    o = c.override({"beta": "none", "keep_goal_plan": "false", "run.seed": "7"}, text=True)
    assert o.planner.beta is None and o.planner.switching.keep_goal_plan is False
    assert o.run.seed == 7
    assert c.override({"gp.lengthscale": "1.5"}, text=True).gp == {"lengthscale": 1.5}
    assert c == default_config()  # frozen: override returns a copy


@pytest.mark.parametrize(
    "changes,text,needle",
    [
        ({"switching.cc": 1.0}, False, "switching.cc: unknown key (did you mean"),
        ({"zzz": 1}, False, "zzz: unknown key"),
        ({"planner.noise": 1.0}, False, "planner.noise: derived from the MJCF"),
        ({"c": "x"}, False, "planner.switching.c: must be a number, got str 'x'"),
        ({"c": "x"}, True, "planner.switching.c: expected a number, got 'x'"),
        ({"c": 2.0}, False, "planner.switching.c: c must lie in [0, 1], got 2.0"),
        ({"discount": 1.0}, False, "planner.q_learning.discount:"),
        ({"discount": 0.0}, False, "planner.q_learning.discount: must be in (0, 1)"),
        ({"p_sat": 0.0}, False, "planner.switching.p_sat: must be in (0, 1]"),
        ({"run.batch_size": 0}, False, "run.batch_size: batch_size must be >= 1"),
        ({"run.max_steps": 2.5}, False, "run.max_steps: must be a whole number"),
        ({"env.noise": 1}, False, "env.noise: must be a boolean"),
        ({"env.terrain_seed": -1}, False, "env.terrain_seed: must be >= 0"),
        ({"tour": "x"}, False, "planner.tour: tour must be one of"),
        ({"beta": -1.0}, False, "planner.beta: beta must be finite and >= 0"),
        ({"delta": float("nan")}, False, "planner.delta: must be a finite number"),
        ({"gp.lengthscale": -1.0}, False, "gp.lengthscale: GPConfig.lengthscale"),
        ({"map_resolution": 0}, False, "map_resolution: must be a whole number >= 1"),
        ({"c": 0.1, "switching.c": 0.2}, False, "planner.switching.c: given twice"),
    ],
)
def test_bad_overrides_are_one_line_errors_naming_the_key(changes, text, needle):
    with pytest.raises(ConfigError) as info:
        default_config().override(changes, text=text, source="--set")
    message = str(info.value)
    assert message.startswith("--set: ") and needle in message and "\n" not in message


def test_assignments():
    assert parse_assignments(["a.b=1", " c = x "]) == {"a.b": "1", "c": "x"}
    for bad in (["c"], ["=1"], ["c=1", "c=2"]):
        with pytest.raises(ConfigError, match="--set"):
            parse_assignments(bad)


def test_toml_runner_errors_name_the_key_line_and_file(tmp_path):
    text = (ROOT / "planner" / "scenarios" / "a.toml").read_text()
    path = tmp_path / "s.toml"
    for old, new, key in (
        ("eps = 0.005", "eps = -1.0", "runner.eps"),
        ("eps = 0.005", 'eps = "x"', "runner.eps"),
        ("eps = 0.005", "epsilon = 0.1", "runner.epsilon"),
    ):
        path.write_text(text.replace(old, new))
        with pytest.raises(ScenarioError) as info:
            load_scenario(path)
        err = info.value
        assert err.key == key and err.source == str(path) and err.line is not None
        assert "\n" not in str(err)


def test_a_given_environment_must_match_the_settings(scenario_c, env_c):
    settings = NavigationConfig.from_scenario(scenario_c).override({"env.thrust": False})
    with pytest.raises(ValueError, match=r"settings\.env"):
        NavigationRunner(scenario_c, env=env_c, settings=settings)


def test_settings_pickle_and_run_single_takes_overrides(scenario_c, monkeypatch):
    import pickle

    c = default_config().override({"gp.bias_std": 0.3, "switching.c": 0.6})
    assert pickle.loads(pickle.dumps(c)) == c
    seen = {}

    def spy(self, seed, run_index=0):
        seen["settings"] = self.settings
        return "end"

    monkeypatch.setattr(NavigationRunner, "run", spy)
    assert run_single(scenario_c, 0, 0, {"planner.delta": "0.05"}) == "end"
    assert seen["settings"].planner.delta == 0.05
    assert seen["settings"].run.runs == 10  # the scenario's table is kept
    assert np.isclose(seen["settings"].planner.q_learning.discount, 0.95)


def test_readme_lists_the_keys_with_their_defaults():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    table = text.split("| keys | defaults | what |")[1].split("\n\n")[0]
    listed: dict[str, str] = {}
    for row in table.strip().splitlines()[1:]:
        keys_cell, defaults_cell = row.split(" | ")[:2]
        keys = [k.strip(" `|") for k in keys_cell.split(",")]
        defaults = [d.strip() for d in defaults_cell.split(",")]
        if keys[-1] == "...":
            assert defaults == ["(prior)"]
            keys, defaults = keys[:-1], defaults * (len(keys) - 1)
        prefix = keys[0].rpartition(".")[0]
        keys = [f"{prefix}{k}" if k.startswith(".") else k for k in keys]
        assert len(keys) == len(defaults), row
        listed.update(zip(keys, defaults, strict=True))
    shown = dict(describe(default_config()))
    for key, value in listed.items():
        assert key in shown, key
        if key.startswith("gp."):
            assert shown[key] == value, key
        else:
            assert str(default_config().leaves()[key]).lower() in (value, value + ".0") or float(
                value
            ) == float(shown[key]), key
    assert {k for k in shown if not k.startswith("gp.")} <= set(listed)


def test_hopnav_config_prints_the_tree(capsys):
    from hopnav.cli import main

    assert main(["config", "--scenario", "c", "--set", "switching.c=0.7"]) == 0
    lines = dict(
        (k.strip(), v.strip())
        for k, v in (x.split("=") for x in capsys.readouterr().out.splitlines())
    )
    assert lines["planner.switching.c"] == "0.7" and lines["run.runs"] == "10"
    assert set(lines) == set(default_config().leaves())


def test_hopnav_run_set_reaches_the_runner(tmp_path, monkeypatch):
    from hopnav.cli import main

    seen = {}

    def spy(self, runs=None, seed=None):
        seen.update(
            settings=self.settings, runs=runs, seed=seed, max_steps=self.scenario.runner.max_steps
        )
        return []

    monkeypatch.setattr(NavigationRunner, "run_many", spy)
    argv = ["run", "--no-rrd", "--no-png", "--quiet", "--max-steps", "7", "--seed", "3"]
    argv += ["--set", "switching.c=0.8", "--set", "planner.beta=2.5", "--set", "gp.bias_std=0.3"]
    assert main(argv) == 0
    s = seen["settings"]
    assert s.planner.switching.c == 0.8 and s.planner.beta == 2.5 and s.gp == {"bias_std": 0.3}
    assert (seen["runs"], seen["seed"], seen["max_steps"]) == (1, 3, 7)
