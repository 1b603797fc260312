"""``hopnav imdp check``: LTL on model files. On point intervals (an ordinary MDP) the value
must be the MDP's maximal satisfaction probability, checked against the independent
product-MDP solver of tests/planner/imdp/rabin_reference.py."""

import json

import numpy as np
import pytest

from hopper_sim.cli import main
from planner.imdp import IMDP
from planner.imdp.io import write_model
from planner.ltl.translate import translate
from tests.planner.imdp import rabin_reference as ref


def random_mdp(rng: np.random.Generator, n: int = 6) -> IMDP:
    """An MDP as an IMDP with point intervals; labels a, b, c each on some state."""
    s, a, t, p = [], [], [], []
    for q in range(n):
        for act in range(int(rng.integers(1, 3))):
            k = int(rng.integers(1, 4))
            succ = rng.choice(n, size=k, replace=False)
            s += [q] * k
            a += [act] * k
            t += succ.tolist()
            p += rng.dirichlet(np.ones(k)).tolist()
    labels = [set() for _ in range(n)]
    for name in ("a", "b", "c"):
        for q in rng.choice(n, size=int(rng.integers(1, 3)), replace=False):
            labels[q].add(name)
    return IMDP(n, s, a, t, p, p, labels=labels, propositions=("a", "b", "c"))


def mdp_value(model: IMDP, formula: str) -> float:
    aut = translate(formula, [x for x in ("a", "b", "c") if x in formula])
    prod = ref.Product(model, aut)
    dist = {}
    for ps in range(len(prod.states)):
        dist[ps] = {}
        for act, row in prod.rows[ps].items():
            d: dict[int, float] = {}
            for t, lo, _ in row:
                d[t] = d.get(t, 0.0) + lo
            dist[ps][act] = d
    return ref.mdp_satisfaction(prod, dist)


FORMULAS = [
    "!c U a",  # reach-avoid
    "F (a & F b)",  # sequencing
    "G F a",
    "F G b",
    "(G F a) -> (G F b)",
    "a U (b U c)",  # until chain
    "(!c U a) & F b",
]


@pytest.mark.parametrize("fmt", ["m.drn", "m.tra"])
@pytest.mark.parametrize("formula", FORMULAS)
def test_point_intervals_give_the_mdp_value(tmp_path, capsys, fmt, formula):
    rng = np.random.default_rng(sum(map(ord, formula + fmt)))
    for _ in range(3):
        m = random_mdp(rng)
        path = tmp_path / fmt
        write_model(m, path)
        assert main(["imdp", "check", str(path), "--ltl", formula, "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        assert set(out) == {"initial", "values", "lower", "upper", "automaton_states"}
        assert (
            out["automaton_states"]
            == translate(formula, [x for x in ("a", "b", "c") if x in formula]).n_states
        )
        for s in (0, 3):
            assert out["values"][s] == pytest.approx(
                mdp_value(m.with_initial([s]), formula), abs=1e-8
            )
        assert out["initial"] == [out["values"][0]]
        assert all(0 <= hi - lo < 1e-8 for lo, hi in zip(out["lower"], out["upper"], strict=True))
        # the adversary has no choice: the optimistic value is the same
        assert main(["imdp", "check", str(path), "--ltl", formula, "--json", "--optimistic"]) == 0
        best = json.loads(capsys.readouterr().out)
        assert best["values"] == pytest.approx(out["values"], abs=1e-8)


def test_interval_worst_case_below_best_case(tmp_path, capsys):
    from tests.planner.imdp.reference import random_imdp

    m = random_imdp(np.random.default_rng(3), n_states=12)
    path = tmp_path / "m.drn"
    write_model(m, path)
    assert main(["imdp", "check", str(path), "--ltl", "!bad U goal"]) == 0
    text = capsys.readouterr()
    worst = [float(line.split()[1]) for line in text.out.splitlines()]
    assert "initial" in text.err and "certified" in text.err
    assert main(["imdp", "check", str(path), "--ltl", "!bad U goal", "--optimistic"]) == 0
    best = [float(line.split()[1]) for line in capsys.readouterr().out.splitlines()]
    assert len(worst) == m.n_states and all(
        w <= b + 1e-12 for w, b in zip(worst, best, strict=True)
    )


def test_errors_name_what_and_where(tmp_path, capsys):
    m = random_mdp(np.random.default_rng(1))
    path = tmp_path / "m.drn"
    write_model(m, path)
    assert main(["imdp", "check", str(path), "--ltl", "F zebra"]) == 2
    err = capsys.readouterr().err
    assert "'zebra'" in err and "not a label" in err and len(err.strip().splitlines()) == 1
    assert main(["imdp", "check", str(path), "--ltl", "F (a &"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hopnav imdp check:") and "position" in err
    assert main(["imdp", "check", str(tmp_path / "missing.drn"), "--ltl", "F a"]) == 2
    assert "missing.drn" in capsys.readouterr().err
