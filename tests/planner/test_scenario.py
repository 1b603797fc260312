import re
from pathlib import Path

import numpy as np
import pytest

from planner.errors import (
    MissingKeyError,
    PlannerError,
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
from planner.scenario import (
    SHIPPED_SCENARIOS,
    Region,
    RunnerTableConfig,
    Scenario,
    World,
    load_scenario,
    parse_scenario,
)
from tests.planner.scenario_texts import BASE


def test_base_scenario_derived_arrays():
    s = parse_scenario(BASE)
    assert (s.world.nx, s.world.ny, s.world.n_cells) == (4, 3, 12)
    assert s.start_cell == 0 * 3 + 1
    assert s.cell_labels[3 * 3 + 1] == frozenset({"Goal"})
    assert s.cell_labels[2 * 3 + 0] == frozenset({"Haz"})
    assert s.cell_labels[2 * 3 + 1] == frozenset()
    assert s.state_labels[-1] == frozenset({"Haz"})
    assert len(s.state_labels) == 13
    expected = np.zeros((4, 3))
    expected[1, 2] = 20.0
    np.testing.assert_array_equal(s.reward_grid, expected)
    letters = s.state_letters(["Goal", "Haz"])
    assert letters[3 * 3 + 2] == 0b01 and letters[2 * 3 + 2] == 0b10 and letters[-1] == 0b10
    assert letters[0] == 0
    # runner defaults from RunnerTableConfig
    assert s.runner == RunnerTableConfig()
    assert s.p_sat == 0.65 and s.reward_known


def test_cell_of_maps_outside_points_to_out_state():
    w = World(4.0, 3.0, 1.0)
    cells = w.geometry.locate(
        np.array([[0.1, 0.1], [3.99, 2.99], [4.0, 1.0], [-0.01, 1.0], [1.5, 3.0]])
    )
    np.testing.assert_array_equal(cells, [0, 11, 12, 12, 12])


def test_rect_covers_cells_by_centre():
    w = World(4.0, 4.0, 1.0)
    m = Region(rects=((0.6, 0.0, 2.4, 1.0),)).mask(w)
    assert m[:, 0].tolist() == [False, True, False, False]


@pytest.mark.parametrize("name", SHIPPED_SCENARIOS)
def test_shipped_scenarios_load(name):
    s = load_scenario(name)
    assert s.name == name
    assert (s.world.nx, s.world.ny) == (15, 15)
    assert s.start == (1.5, 7.5)
    assert s.rewards["A"] == 20.0 and s.rewards["B"] == 5.0 and s.rewards["weak"] == -0.5
    assert s.reward_known == (name in ("a", "b"))
    assert s.runner.runs == (1 if name in ("a", "b") else 10)
    assert s.formula == "!Haz U Goal" and s.p_sat == 0.65
    # The wall at x = 7 has a gap of 2-3 cells, and the goal is reachable only through it.
    wall = s.hazard_mask[7]
    assert 2 <= int((~wall).sum()) <= 3
    assert not (s.goal_mask & s.hazard_mask).any()
    gap = np.zeros_like(s.hazard_mask)
    gap[7:9][~s.hazard_mask[7:9]] = True
    assert _goal_reachable(s, s.hazard_mask)
    assert not _goal_reachable(s, s.hazard_mask | gap)


def _goal_reachable(s, blocked):
    """Breadth-first search over the 8 hop actions (1 or 2 cells N/E/S/W), never landing
    in a blocked cell."""
    nx, ny = blocked.shape
    seen = np.zeros_like(blocked)
    frontier = [divmod(s.start_cell, ny)]
    seen[frontier[0]] = True
    while frontier:
        nxt = []
        for i, j in frontier:
            for di, dj in [(0, 1), (0, 2), (1, 0), (2, 0), (0, -1), (0, -2), (-1, 0), (-2, 0)]:
                a, b = i + di, j + dj
                if 0 <= a < nx and 0 <= b < ny and not blocked[a, b] and not seen[a, b]:
                    seen[a, b] = True
                    nxt.append((a, b))
        frontier = nxt
    return bool((seen & s.goal_mask).any())


def test_shipped_layouts_place_a_and_b():
    a, b = load_scenario("a"), load_scenario("b")
    ai, aj = np.nonzero(a.region_mask("A"))
    assert ai.mean() < 7.5 and aj.mean() > 7.5  # upper left
    bi, bj = np.nonzero(a.region_mask("B"))
    assert bi.mean() < 7.5 and bj.mean() < 7.5  # lower left
    ai, aj = np.nonzero(b.region_mask("A"))
    assert ai.mean() > 7.5 and aj.mean() < 7.5  # lower right
    bi, bj = np.nonzero(b.region_mask("B"))
    assert bi.mean() < 7.5 and bj.mean() > 7.5  # upper left
    np.testing.assert_array_equal(load_scenario("c").reward_grid, a.reward_grid)
    np.testing.assert_array_equal(load_scenario("d").reward_grid, b.reward_grid)


def test_load_by_path(tmp_path: Path):
    p = tmp_path / "mine.toml"
    p.write_text(BASE)
    assert load_scenario(p).name == "tiny"
    with pytest.raises(ScenarioError, match="no scenario"):
        load_scenario(tmp_path / "missing.toml")


def _error(text: str, cls: type[ScenarioError]) -> ScenarioError:
    with pytest.raises(cls) as info:
        parse_scenario(text, source="s.toml")
    err = info.value
    assert isinstance(err, PlannerError)
    assert str(err).startswith(f"s.toml, line {err.line}:")
    return err


def _line(text: str, needle: str) -> int:
    return next(k for k, line in enumerate(text.splitlines(), 1) if needle in line)


def test_missing_key_names_key_and_line():
    text = BASE.replace("start = [0.5, 1.5]\n", "")
    err = _error(text, MissingKeyError)
    assert err.key == "initial.start" and err.line == _line(text, "[initial]")
    err = _error(BASE.replace('name = "tiny"\n', ""), MissingKeyError)
    assert err.key == "name" and "top-level" in str(err)


def test_wrong_type_names_key_and_line():
    text = BASE.replace("cell = 1.0", 'cell = "one"')
    err = _error(text, ScenarioTypeError)
    assert err.key == "world.cell" and err.line == _line(text, "cell =")
    text = BASE.replace("[2, 2],", "[2, 2.5],")
    err = _error(text, ScenarioTypeError)
    assert err.key == "regions.Haz.cells[1][1]" and err.line == _line(text, "[2, 2.5]")


def test_region_outside_world_names_element_line():
    text = BASE.replace("[2, 2],", "[2, 3],")
    err = _error(text, RegionOutsideWorldError)
    assert err.key == "regions.Haz.cells[1]" and err.line == _line(text, "[2, 3]")
    text = BASE.replace("[[3.0, 0.0, 4.0, 3.0]]", "[[3.0, 0.0, 4.5, 3.0]]")
    err = _error(text, RegionOutsideWorldError)
    assert err.key == "regions.Goal.rects[0]" and "leaves the world" in str(err)


def test_overlapping_goal_and_hazard():
    text = BASE.replace("[2, 2],", "[3, 2],")
    err = _error(text, RegionOverlapError)
    assert err.key == "regions.Goal" and "(3, 2)" in str(err)
    assert err.line == _line(text, "[regions.Goal]")


def test_start_in_hazard_and_outside_initial():
    text = BASE.replace("cells = [[0, 1]]", "cells = [[0, 1], [2, 0]]").replace(
        "start = [0.5, 1.5]", "start = [2.5, 0.5]"
    )
    err = _error(text, StartInHazardError)
    assert err.key == "initial.start" and err.line == _line(text, "start =")
    err = _error(BASE.replace("start = [0.5, 1.5]", "start = [1.5, 1.5]"), ScenarioValueError)
    assert "outside the initial region" in str(err)


def test_malformed_toml_reports_tomllib_line():
    text = BASE.replace("cell = 1.0", "cell = = 1.0")
    err = _error(text, ScenarioSyntaxError)
    assert err.line == _line(text, "cell = =")


def test_unknown_keys_and_reward_labels():
    text = BASE.replace("cell = 1.0", "cel = 1.0")
    err = _error(text, UnknownKeyError)
    assert err.key == "world.cel" and err.line == _line(text, "cel =")
    text = BASE + "C = 3.0\n"
    err = _error(text, UndefinedLabelError)
    assert err.key == "rewards.C" and err.line == _line(text, "C = 3.0")


def test_runner_values_are_validated_with_line():
    text = BASE + "[runner]\ndiscount = 1.5\n"
    err = _error(text, ScenarioValueError)
    assert err.key == "runner.discount" and err.line == _line(text, "discount")
    err = _error(BASE + "[runner]\nruns = 2.5\n", ScenarioTypeError)
    assert err.key == "runner.runs"


def test_world_must_be_whole_cells():
    err = _error(BASE.replace("size = [4.0, 3.0]", "size = [4.5, 3.0]"), ScenarioValueError)
    assert err.key == "world.size" and re.search(r"whole number", str(err))


def test_scenario_validates_when_built_in_code():
    world = World(3.0, 1.0)
    with pytest.raises(RegionOverlapError):
        Scenario(
            name="x",
            world=world,
            regions={"Goal": Region(cells=((2, 0),)), "Haz": Region(cells=((2, 0),))},
            initial=Region(cells=((0, 0),)),
            start=(0.5, 0.5),
        )
    s = Scenario(
        name="x",
        world=world,
        regions={"Goal": Region(cells=((2, 0),))},
        initial=Region(cells=((0, 0),)),
        start=(0.5, 0.5),
    )
    assert s.labels == ("Goal", "Haz")
    assert s.with_runner(runs=3).runner.runs == 3
    with pytest.raises(ScenarioValueError, match=r"runner\.eps"):
        s.with_runner(eps=-1.0)


def test_unknown_label_in_formula_names_formula_line():
    text = BASE.replace('formula = "!Haz U Goal"', 'formula = "!Haz U (Goal & C)"')
    err = _error(text, UndefinedLabelError)
    assert err.key == "formula" and err.line == 2 and "'C'" in str(err)
    assert isinstance(err, UnknownPropositionError)


def test_formula_syntax_error_and_user_formula():
    err = _error(BASE.replace('"!Haz U Goal"', '"!Haz U"'), ScenarioFormulaError)
    assert err.key == "formula" and "position" in str(err)
    s = parse_scenario(BASE.replace('"!Haz U Goal"', '"(F A) & (!Haz U Goal)"'))
    assert s.formula == "(F A) & (!Haz U Goal)"


def test_labels_must_be_propositions():
    err = _error(BASE.replace("[regions.A]", "[regions.F]"), ScenarioValueError)
    assert err.key == "regions.F" and err.line == _line(BASE, "[regions.A]")


def test_scenario_pickles_for_worker_processes():
    import pickle

    s = load_scenario("c")
    t = pickle.loads(pickle.dumps(s))
    assert t == s and t.regions == s.regions
    np.testing.assert_array_equal(t.reward_grid, s.reward_grid)


def test_example_user_scenario_loads():
    from planner.scenario import ascii_map

    root = Path(__file__).resolve().parents[2]
    s = load_scenario(root / "examples" / "scenarios" / "corridor.toml")
    assert (s.world.nx, s.world.ny, s.world.cell) == (16, 8, 1.0)
    assert set(s.labels) == {"Goal", "Haz", "charger", "coin"}
    assert s.reward_grid.sum() == pytest.approx(9.0)
    text = ascii_map(s)
    assert "c charger" in text and "o coin" in text
    rows = text.splitlines()[:8]  # top row first: row 8 - 1 - j holds cells (., j)
    assert rows[8 - 1 - 5][11] == "c" and rows[8 - 1 - 2][3] == "o"


def test_collect_setting():
    assert parse_scenario(BASE).collect == "once"
    text = BASE.replace('formula = "!Haz U Goal"', 'formula = "!Haz U Goal"\ncollect = "every"')
    assert parse_scenario(text).collect == "every"
    bad = BASE.replace('formula = "!Haz U Goal"', 'formula = "!Haz U Goal"\ncollect = "twice"')
    err = _error(bad, ScenarioValueError)
    assert err.key == "collect" and err.line == _line(bad, "collect") and "twice" in str(err)
    assert all(load_scenario(n).collect == "once" for n in SHIPPED_SCENARIOS)
