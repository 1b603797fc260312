"""``hopnav automaton``: HOA by default, --dot, --stats, errors."""

from __future__ import annotations

from hopper_sim.cli import main
from planner.ltl.hoa import from_hoa


def test_hoa_output(capsys):
    assert main(["automaton", "!Haz U Goal"]) == 0
    aut = from_hoa(capsys.readouterr().out)
    assert aut.n_states == 3
    assert aut.propositions == ("Goal", "Haz")
    assert aut.accepts([[]], [["Goal"]])


def test_dot_and_stats(capsys):
    assert main(["automaton", "G F a & G F b", "--dot"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("digraph") and "->" in out
    assert main(["automaton", "!Haz U Goal", "--stats", "--ap", "Haz", "Goal", "Home"]) == 0
    out = capsys.readouterr().out
    assert "states: 3" in out and "pairs: 1" in out and "propositions: Haz Goal Home" in out


def test_bad_formula_exit_code(capsys):
    assert main(["automaton", "a U"]) == 2
    assert "position 3" in capsys.readouterr().err
