import numpy as np
import pytest

from planner.errors import ModelFormatError
from planner.imdp import Problem, ReachAvoid, Specification, ValueIteration, solve
from planner.imdp.io import TERMINAL, read_model, write_model
from tests.planner.imdp.reference import random_imdp


def values(m, target, avoid=None, sat="pessimistic"):
    spec = Specification(ReachAvoid(target, avoid), sat)
    return solve(Problem(m, spec), ValueIteration(1e-12)).values


@pytest.mark.parametrize("fmt,name", [("prism", "m.tra"), ("drn", "m.drn")])
def test_round_trip_with_labels(tmp_path, fmt, name):
    m = random_imdp(np.random.default_rng(4), n_states=20).with_initial([3, 5])
    path = tmp_path / name
    write_model(m, path, fmt)
    back = read_model(path)
    assert back.n_states == m.n_states and back.n_entries == m.n_entries
    assert back.initial.tolist() == [3, 5]
    assert back.labels == m.labels
    assert np.array_equal(back.lower, m.lower) and np.array_equal(back.upper, m.upper)
    for sat in ("pessimistic", "optimistic"):
        assert np.array_equal(values(back, "goal", "bad", sat), values(m, "goal", "bad", sat))
    # no temporary files are left behind
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        {name, "m.lab"} if fmt == "prism" else {name}
    )


def test_round_trip_bmdp(tmp_path):
    m = random_imdp(np.random.default_rng(5), n_states=20)
    goal = m.states_labelled("goal")
    path = tmp_path / "m.txt"
    write_model(m, path, "bmdp", terminal=goal)
    back = read_model(path, "bmdp")
    assert back.states_labelled(TERMINAL).tolist() == goal.tolist()
    assert np.array_equal(values(back, TERMINAL), values(m, "goal"))


def test_bmdp_terminal_states_without_rows_become_absorbing(tmp_path):
    path = tmp_path / "m.bmdp"
    path.write_text("3\n1\n1\n2\n0 0 1 0.2 0.6\n0 0 2 0.4 0.8\n1 0 1 1 1\n")
    m = read_model(path, "bmdp")
    assert values(m, TERMINAL).tolist() == pytest.approx([0.4, 0.0, 1.0])


def test_point_values_and_storm_style_annotations(tmp_path):
    path = tmp_path / "m.drn"
    path.write_text(
        "@type: MDP\n@value_type: double\n@parameters\n\n@reward_models\nr\n@nr_states\n2\n"
        "@nr_choices\n2\n@model\nstate 0 [0] init\n\taction 0 [0]\n\t\t0 : 0.5\n\t\t1 : 0.5\n"
        "state 1 [1] goal\n\taction 0 [0]\n\t\t1 : 1\n"
    )
    m = read_model(path)
    assert m.labels[1] == frozenset({"goal"})
    assert values(m, "goal").tolist() == [1.0, 1.0]


@pytest.mark.parametrize(
    "name,text,match",
    [
        ("a.tra", "2 1 1\n0 0 1 [0.5;0.6]\n", "line 2"),
        ("a.tra", "x\n", "line 1"),
        ("a.tra", "2 1 2\n0 0 1 [1,1]\n", "announces 2"),
        ("a.drn", "@nr_states\n1\n@model\nstate 0\n\taction a\n\t\t0 : [1, x]\n", "line 6"),
        ("a.drn", "@type: CTMC\n", "unsupported model type"),
        ("a.txt", "2\n1\n", "terminal states"),
        ("a.txt", "2\n1\n0\n0 0 1 0.5\n", "line 4"),
    ],
)
def test_malformed_files_name_the_line(tmp_path, name, text, match):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ModelFormatError, match=match):
        read_model(path)


def test_missing_file(tmp_path):
    with pytest.raises(ModelFormatError, match="cannot open"):
        read_model(tmp_path / "nope.drn")
