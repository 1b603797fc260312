"""The outcome rule (planner/verdict.py) agrees with the independent lasso semantics of
tests/planner/ltl_oracle.py: a prefix is accepted iff every continuation satisfies the
formula, rejected iff none does; a window repeated forever is accepted iff the lasso is."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from planner.ltl.translate import translate
from planner.verdict import ACCEPTED, OPEN, REJECTED, AutomatonVerdicts, window_accepts
from tests.planner import ltl_oracle


def ap(p: str) -> tuple:
    return ("ap", p)


def neg(f: tuple) -> tuple:
    return ("!", f)


# the issue's five formulas (props a, b, goal, haz; haz excluded as the world's hazard)
ISSUE = [
    ("&", ("G", neg(ap("haz"))), ("&", ("F", ap("a")), ("&", ("F", ap("b")), ("F", ap("goal"))))),
    ("&", ("F", ("&", ap("a"), ("F", ap("goal")))), ("G", neg(ap("haz")))),
    ("U", neg(ap("haz")), ("&", ap("a"), ("U", neg(ap("haz")), ap("goal")))),
    ("&", ("G", neg(ap("haz"))), ("&", ("G", ("F", ap("a"))), ("G", ("F", ap("goal"))))),
    ("&", ("G", ("->", ap("a"), ("F", ap("b")))), ("G", neg(ap("haz")))),
]

# class templates over two regions; random_formulas fills them with a, b, c and negations
TEMPLATES = {
    "safety": [
        lambda p, q: ("G", p),
        lambda p, q: ("G", ("->", p, ("X", q))),
        lambda p, q: ("W", p, q),
    ],
    "co-safe": [
        lambda p, q: ("F", p),
        lambda p, q: ("U", p, q),
        lambda p, q: ("F", ("&", p, ("F", q))),
    ],
    "recurrence": [lambda p, q: ("G", ("F", p)), lambda p, q: ("G", ("->", p, ("F", q)))],
    "persistence": [
        lambda p, q: ("F", ("G", p)),
        lambda p, q: ("->", ("G", ("F", p)), ("F", ("G", q))),
    ],
    "obligation": [lambda p, q: ("|", ("F", p), ("G", q)), lambda p, q: ("&", ("F", p), ("G", q))],
}


def random_formulas(n: int, seed: int) -> list[tuple[str, tuple]]:
    """``n`` formulas over a, b, c, cycling through the classes (seeded)."""
    rng = np.random.default_rng(seed)
    classes = list(TEMPLATES)
    out = []
    for k in range(n):
        cls = classes[k % len(classes)]
        tmpl = TEMPLATES[cls][int(rng.integers(len(TEMPLATES[cls])))]
        p, q = rng.choice(ltl_oracle.PROPS, size=2, replace=False)
        lits = [ap(str(x)) if rng.random() < 0.7 else neg(ap(str(x))) for x in (p, q)]
        out.append((cls, tmpl(*lits)))
    return out


def oracle_letters(props: tuple[str, ...], automaton) -> np.ndarray:
    """Automaton letter of every oracle letter (bit i: props[i])."""
    ol = np.arange(1 << len(props))
    out = np.zeros_like(ol)
    for j, p in enumerate(automaton.propositions):
        out |= (ol >> props.index(p) & 1) << j
    return out


def judge_by_oracle(f, props, excluded, prefixes, monkeypatch):
    """Per prefix (rows of oracle letters): (all continuations satisfy, none does), over the
    continuations ``w v^omega`` with |w| <= 1, 1 <= |v| <= 2 that avoid ``excluded``."""
    monkeypatch.setattr(ltl_oracle, "PROPS", props)
    letters = np.arange(1 << len(props))
    if excluded is not None:
        letters = letters[(letters >> props.index(excluded) & 1) == 0]
    n, p = prefixes.shape
    every = np.ones(n, dtype=bool)
    some = np.zeros(n, dtype=bool)
    for w, v in itertools.product(range(2), range(1, 3)):
        conts = np.array(list(itertools.product(letters, repeat=w + v)), dtype=np.int64)
        words = np.concatenate(
            [np.repeat(prefixes, len(conts), axis=0), np.tile(conts, (n, 1))], axis=1
        )
        sat = ltl_oracle.evaluate(f, words, p + w)[:, 0].reshape(n, len(conts))
        every &= sat.all(axis=1)
        some |= sat.any(axis=1)
    return every, some


def check_formula(f, props, excluded, monkeypatch, max_prefix=3):
    aut = translate(ltl_oracle.render(f))
    v = AutomatonVerdicts(aut, excluded=excluded)
    to_aut = oracle_letters(props, aut)
    letters = np.arange(1 << len(props))
    if excluded is not None:
        letters = letters[(letters >> props.index(excluded) & 1) == 0]
    seen = set()
    for length in range(1, max_prefix + 1):
        prefixes = np.array(list(itertools.product(letters, repeat=length)), dtype=np.int64)
        every, some = judge_by_oracle(f, props, excluded, prefixes, monkeypatch)
        for row, all_sat, any_sat in zip(prefixes, every, some, strict=True):
            q = aut.initial
            for letter in row:
                q = int(aut.transitions[q, to_aut[letter]])
            verdict = v.verdict(q)
            seen.add(verdict)
            assert (verdict == ACCEPTED) == bool(all_sat), (ltl_oracle.render(f), row)
            assert (verdict == REJECTED) == (not any_sat), (ltl_oracle.render(f), row)
    return seen


@pytest.mark.parametrize("f", ISSUE, ids=[ltl_oracle.render(f) for f in ISSUE])
def test_issue_formulas_prefix_verdicts_match_the_oracle(f, monkeypatch):
    check_formula(f, ("a", "b", "goal", "haz"), "haz", monkeypatch, max_prefix=2)


@pytest.mark.parametrize("cls,f", random_formulas(20, seed=13))
def test_random_formulas_prefix_verdicts_match_the_oracle(cls, f, monkeypatch):
    check_formula(f, ltl_oracle.PROPS, None, monkeypatch)


def test_classes_reach_every_verdict(monkeypatch):
    seen = set()
    for _, f in random_formulas(20, seed=13):
        seen |= check_formula(f, ltl_oracle.PROPS, None, monkeypatch, max_prefix=1)
    assert seen == {ACCEPTED, REJECTED, OPEN}


@pytest.mark.parametrize("cls,f", random_formulas(20, seed=13))
def test_window_acceptance_matches_the_lasso(cls, f):
    aut = translate(ltl_oracle.render(f))
    to_aut = oracle_letters(ltl_oracle.PROPS, aut)
    rng = np.random.default_rng(5)
    for _ in range(40):
        u = rng.integers(8, size=int(rng.integers(0, 4)))
        w = rng.integers(8, size=int(rng.integers(1, 4)))
        q = aut.initial
        for letter in u:
            q = int(aut.transitions[q, to_aut[letter]])
        word = np.concatenate([u, w])[None, :]
        expected = bool(ltl_oracle.evaluate(f, word, len(u))[0, 0])
        assert window_accepts(aut, q, to_aut[w]) == expected


def test_obligations_of_the_gallery():
    v = AutomatonVerdicts(translate("GF a & GF b & G !haz"), excluded="haz")
    assert v.obligation(v.automaton.initial) == "recurrence"
    v = AutomatonVerdicts(translate("F(a & F goal) & G !haz"), excluded="haz")
    q = v.automaton.step(v.automaton.step(v.automaton.initial, {"a"}), {"goal"})
    assert v.verdict(q) == ACCEPTED  # only hazard-free continuations are judged
    assert v.obligation(v.automaton.initial) == "guarantee"
    v = AutomatonVerdicts(translate("G !c"))
    assert v.obligation(v.automaton.initial) == "safety"
