import json

import numpy as np
import pytest

from hopper_sim.cli import main
from planner.imdp import Problem, ReachAvoid, Specification, solve
from planner.imdp.analysis import failure_states, labelled_model, satisfaction
from planner.imdp.grid import GridWorld
from planner.imdp.io import read_model, write_model
from planner.imdp.product import ProductIMDP
from tests.planner.imdp.helpers import corridor_intervals, until_automaton
from tests.planner.imdp.reference import random_imdp


@pytest.fixture
def model_file(tmp_path):
    m = random_imdp(np.random.default_rng(9), n_states=15)
    path = tmp_path / "m.drn"
    write_model(m, path)
    return m, path


def test_solve_json(model_file, capsys):
    m, path = model_file
    assert main(["imdp", "solve", str(path), "--target", "goal", "--avoid", "bad", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"values", "lower", "upper", "converged", "residual", "iterations"}
    assert len(out["values"]) == m.n_states and out["residual"] < 1e-8
    assert out["converged"] and out["values"] == out["lower"]
    assert all(0 <= hi - lo < 1e-8 for lo, hi in zip(out["lower"], out["upper"], strict=True))
    assert (
        main(
            [
                "imdp",
                "solve",
                str(path),
                "--target",
                "goal",
                "--avoid",
                "bad",
                "--json",
                "--optimistic",
            ]
        )
        == 0
    )
    best = json.loads(capsys.readouterr().out)["values"]
    assert all(lo <= hi + 1e-12 for lo, hi in zip(out["values"], best, strict=True))


def test_export_to_bmdp_and_solve(model_file, tmp_path, capsys):
    _, path = model_file
    out = tmp_path / "m.bmdp"
    assert (
        main(["imdp", "export", str(path), "--out", str(out), "--to", "bmdp", "--target", "goal"])
        == 0
    )
    assert main(["imdp", "solve", str(out), "--format", "bmdp", "--json"]) == 0
    via_bmdp = json.loads(capsys.readouterr().out)["values"]
    assert main(["imdp", "solve", str(path), "--target", "goal", "--json"]) == 0
    direct = json.loads(capsys.readouterr().out)["values"]
    assert via_bmdp == pytest.approx(direct, abs=1e-12)


def test_errors_go_to_stderr(model_file, capsys):
    _, path = model_file
    assert main(["imdp", "solve", str(path)]) == 2
    assert "--target" in capsys.readouterr().err
    assert main(["imdp", "solve", str(path), "--target", "nope"]) == 2  # bad input, as elsewhere
    assert "'nope'" in capsys.readouterr().err


def test_product_export_round_trip(tmp_path):

    g = GridWorld(4, 1, labels=[(), ("Haz",), (), ("Goal",)])
    p = ProductIMDP(g.imdp_from_intervals(*corridor_intervals(g, 0.3)), until_automaton())
    for name in ("p.tra", "p.drn"):
        write_model(labelled_model(p), tmp_path / name)
        back = read_model(tmp_path / name)
        v = solve(Problem(back, Specification(ReachAvoid("accept")))).values
        assert v == pytest.approx(satisfaction(p).values, abs=1e-12)
        assert back.states_labelled("fail").tolist() == failure_states(p).tolist()


def test_export_scenario_product(tmp_path, capsys):
    out = tmp_path / "a.drn"
    assert main(["imdp", "export", "--scenario", "a", "--out", str(out)]) == 0
    model = read_model(out)
    # 15 x 15 cells + out, times the 3-state automaton of !Haz U Goal
    assert model.n_states == 226 * 3
    assert "accept" in model.propositions and "fail" in model.propositions
    assert main(["imdp", "solve", str(out), "--target", "accept", "--avoid", "fail", "--json"]) == 0
    values = json.loads(capsys.readouterr().out)["values"]
    acc = model.states_labelled("accept")
    assert all(values[s] == 1.0 for s in np.flatnonzero(acc))
    assert all(values[s] == 0.0 for s in np.flatnonzero(model.states_labelled("fail")))
