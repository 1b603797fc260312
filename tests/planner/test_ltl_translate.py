"""The translator agrees with an independent lasso evaluator (tests/planner/ltl_oracle.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planner.errors import AutomatonError, LTLSyntaxError
from planner.ltl.parser import parse
from planner.ltl.simplify import simplify
from planner.ltl.syntax import Formula
from planner.ltl.translate import translate
from tests.planner.ltl_oracle import PROPS, automaton_accepts, evaluate, lasso_batches, render

SHAPES = [(0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 1), (2, 2)]
BATCHES = list(lasso_batches(SHAPES))


def a(name="a"):
    return ("ap", name)


A, B, C = ("ap", "a"), ("ap", "b"), ("ap", "c")


def n(f):
    return ("!", f)


def F(f):
    return ("F", f)


def G(f):
    return ("G", f)


def X(f):
    return ("X", f)


def bi(op, f, g):
    return (op, f, g)


CORPUS = [
    bi("U", n(C), A),  # reach-avoid
    bi("&", G(n(C)), F(A)),
    F(bi("&", A, F(B))),  # sequencing
    F(bi("&", A, F(bi("&", B, F(C))))),
    bi("&", bi("U", n(B), A), F(B)),  # ordered visits
    bi("&", G(F(A)), G(F(B))),  # patrolling
    bi("&", bi("&", G(F(A)), G(F(B))), G(n(C))),
    F(G(A)),  # persistence
    bi("|", F(G(A)), G(F(B))),
    G(bi("->", A, F(B))),  # response
    G(bi("->", A, X(bi("U", n(A), B)))),
    bi("U", A, bi("U", B, C)),  # until chains
    bi("U", bi("U", A, B), C),
    X(X(A)),
    X(bi("U", A, X(B))),
    G(bi("->", A, X(X(B)))),
    bi("R", A, B),
    bi("W", A, B),
    bi("M", A, B),
    bi("R", A, bi("|", B, X(C))),
    bi("W", n(C), bi("&", A, B)),
    bi("->", G(F(A)), G(F(B))),
    bi("&", bi("->", G(F(A)), G(F(B))), bi("->", G(F(C)), G(F(A)))),
    bi("<->", F(A), G(B)),
    bi("xor", G(F(A)), F(G(B))),
    bi("&", F(G(A)), G(F(B))),
    G(bi("|", n(A), bi("U", B, C))),
    bi("&", G(n(C)), bi("&", F(A), F(B))),
    ("true",),
    ("false",),
]


def check(f: tuple) -> None:
    aut = translate(render(f), PROPS)
    pairs = [(p.good, p.bad) for p in aut.pairs]
    for letters, start in BATCHES:
        want = evaluate(f, letters, start)[:, 0]
        got = automaton_accepts(aut.transitions, aut.initial, pairs, letters, start)
        if not np.array_equal(want, got):
            k = int(np.flatnonzero(want != got)[0])
            word = [
                sorted(p for i, p in enumerate(PROPS) if x >> i & 1) for x in letters[k].tolist()
            ]
            pytest.fail(
                f"{render(f)}: lasso prefix={word[:start]} loop={word[start:]}: "
                f"formula says {bool(want[k])}, automaton {aut} says {bool(got[k])}"
            )


@pytest.mark.parametrize("f", CORPUS, ids=render)
def test_corpus(f):
    check(f)


LEAVES = st.sampled_from([A, B, C, ("true",), ("false",)])
UNARY = ["!", "X", "F", "G"]
BINARY = ["&", "|", "->", "<->", "xor", "U", "R", "W", "M"]


def formulas(depth: int):
    if depth == 0:
        return LEAVES
    sub = formulas(depth - 1)
    return st.one_of(
        LEAVES,
        st.tuples(st.sampled_from(UNARY), sub),
        st.tuples(st.sampled_from(BINARY), sub, sub),
    )


@settings(
    max_examples=520, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(formulas(4))
def test_random_formulas(f):
    check(f)


def test_reach_avoid_has_three_states():
    assert translate("!Haz U Goal").n_states == 3


def test_alphabet_order_and_extension():
    aut = translate("!Haz U Goal", ["Haz", "Other", "Goal"])
    assert aut.propositions == ("Haz", "Other", "Goal")
    assert aut.n_states == 3
    assert aut.accepts([["Other"]], [["Goal", "Other"]])
    assert not aut.accepts([["Haz", "Other"]], [["Goal"]])
    with pytest.raises(AutomatonError, match="'Goal'"):
        translate("!Haz U Goal", ["Haz"])
    with pytest.raises(AutomatonError, match="duplicate"):
        translate("a", ["a", "a"])


def test_syntax_error_propagates():
    with pytest.raises(LTLSyntaxError):
        translate("G (a ->")


def to_oracle(f: Formula) -> tuple:
    """Test-side view of a library formula as the oracle's tuples."""
    if f.op == "ap":
        return ("ap", f.name)
    if f.op in ("true", "false"):
        return (f.op,)
    kids = [to_oracle(c) for c in f.children]
    if f.op in ("&", "|"):
        out = kids[0]
        for k in kids[1:]:
            out = (f.op, out, k)
        return out
    return (f.op, *kids)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(formulas(4))
def test_simplify_is_equivalent(f):
    g = simplify(parse(render(f)))
    assert all(x.op not in ("->", "<->", "xor") for x in g.subformulas())
    assert all(x.op != "!" or x.children[0].op == "ap" for x in g.subformulas())
    for letters, start in BATCHES[:6]:
        assert np.array_equal(
            evaluate(f, letters, start)[:, 0], evaluate(to_oracle(g), letters, start)[:, 0]
        )


def test_translation_limits_fail_fast():
    import time

    from planner.errors import TranslationLimitError
    from planner.ltl.budget import TranslationLimits

    with pytest.raises(TranslationLimitError, match="2\\^17 letters"):
        translate(" | ".join(f"p{i}" for i in range(17)))
    t0 = time.perf_counter()
    with pytest.raises(TranslationLimitError, match="entries"):
        translate(" & ".join(f"F p{i}" for i in range(12)))  # 4096 states x 4096 letters
    with pytest.raises(TranslationLimitError, match="more than 5 states"):
        translate("G F a & G F b & F G c", limits=TranslationLimits(max_states=5))
    hard = "".join("(a U " if i % 2 else "(b R " for i in range(20)) + "c" + ")" * 20
    with pytest.raises(TranslationLimitError, match=r"longer than 0\.5 s"):
        translate(hard, limits=TranslationLimits(max_seconds=0.5))
    assert time.perf_counter() - t0 < 15
    # the limits apply to one call only
    assert translate("F p0 & F p1").n_states == 4
