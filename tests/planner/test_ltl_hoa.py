"""HOA v1 export/import: round trips keep the language; foreign automata read correctly."""

from __future__ import annotations

import numpy as np
import pytest

from planner.errors import HOAError, NondeterministicAutomatonError
from planner.ltl.hoa import from_hoa, to_hoa
from planner.ltl.translate import translate
from tests.planner.ltl_oracle import automaton_accepts, evaluate, lasso_batches, render
from tests.planner.test_ltl_translate import CORPUS

SHAPES = [(0, 1), (0, 2), (1, 1), (1, 2), (2, 1), (2, 2), (0, 3)]


def raw(aut):
    return aut.transitions, aut.initial, [(p.good, p.bad) for p in aut.pairs]


def same_language(x, y, n_props):
    for letters, start in lasso_batches(SHAPES, n_props):
        assert np.array_equal(
            automaton_accepts(*raw(x), letters, start), automaton_accepts(*raw(y), letters, start)
        )


def matches_formula(aut, f, n_props):
    for letters, start in lasso_batches(SHAPES, n_props):
        want = evaluate(f, letters, start)[:, 0]
        assert np.array_equal(automaton_accepts(*raw(aut), letters, start), want)


@pytest.mark.parametrize("f", CORPUS[::2], ids=render)
def test_round_trip(f):
    aut = translate(render(f), ["a", "b", "c"])
    text = to_hoa(aut, name=render(f))
    back = from_hoa(text)
    assert back.propositions == aut.propositions
    assert back.n_states <= aut.n_states  # state-based input is not split
    same_language(aut, back, 3)


def test_export_header():
    text = to_hoa(translate("!Haz U Goal"))
    assert text.startswith("HOA: v1\n")
    assert 'AP: 2 "Goal" "Haz"' in text
    assert "Acceptance: 2 (Fin(0)&Inf(1))" in text
    assert text.rstrip().endswith("--END--")


A, B = ("ap", "a"), ("ap", "b")

BUCHI_TRANS = """HOA: v1
name: "GFa" tool: "spot"
States: 1
Start: 0
AP: 1 "a"
acc-name: Buchi
Acceptance: 1 Inf(0)
properties: trans-labels explicit-labels trans-acc complete deterministic
--BODY--
State: 0
[0] 0 {0}
[!0] 0
--END--
"""

COBUCHI_IMPLICIT = """HOA: v1 /* FG a, implicit labels */
States: 1
Start: 0
AP: 1 "a"
acc-name: co-Buchi
Acceptance: 1 Fin(0)
properties: implicit-labels trans-acc
--BODY--
State: 0
0 {0}
0
--END--
"""

PARITY = """HOA: v1
States: 1
Start: 0
AP: 2 "a" "b"
acc-name: parity min even 3
Acceptance: 3 Inf(0) | (Fin(1) & Inf(2))
--BODY--
State: 0
[0] 0 {0}
[!0 & !1] 0 {1}
[!0 & 1] 0 {2}
--END--
"""

GEN_BUCHI = """HOA: v1
States: 1
Start: 0
AP: 2 "a" "b"
acc-name: generalized-Buchi 2
Acceptance: 2 Inf(0)&Inf(1)
--BODY--
State: 0
[0&1] 0 {0 1}
[0&!1] 0 {0}
[!0&1] 0 {1}
[!0&!1] 0
--END--
"""

STATE_BASED_ALIAS = """HOA: v1
States: 2
Start: 0
AP: 2 "a" "b"
Alias: @goal 0
Alias: @haz 1
Acceptance: 1 Inf(0)
--BODY--
State: 0 "waiting"
[!@goal & !@haz] 0
[@goal] 1
State: 1 "done" {0}
[t] 1
--END--
"""

FIN_NEG = """HOA: v1
States: 2
Start: 0
AP: 1 "a"
Acceptance: 1 Fin(!0)
--BODY--
State: 0 {0}
[0] 0
[!0] 1
State: 1
[0] 0
[!0] 1
--END--
"""

RABIN_2 = """HOA: v1
States: 2
Start: 0
AP: 2 "a" "b"
acc-name: Rabin 2
Acceptance: 4 (Fin(0)&Inf(1)) | (Fin(2)&Inf(3))
--BODY--
State: 0 {0}
[0] 1
[!0] 0
State: 1 {1 2}
[0] 1
[!0] 0
--END--
"""


@pytest.mark.parametrize(
    ("text", "formula", "n_props"),
    [
        (BUCHI_TRANS, ("G", ("F", A)), 1),
        (COBUCHI_IMPLICIT, ("F", ("G", A)), 1),
        (PARITY, ("|", ("G", ("F", A)), ("F", ("G", B))), 2),
        (GEN_BUCHI, ("&", ("G", ("F", A)), ("G", ("F", B))), 2),
        (STATE_BASED_ALIAS, ("U", ("!", B), A), 2),
        (FIN_NEG, ("F", ("G", A)), 1),  # eventually always in state 0, i.e. reading a
        # pair 0 (Fin 0 & Inf 1): eventually always in state 1, i.e. reading a -> F G a;
        # pair 1 (Fin 2 & Inf 3): set 3 marks nothing, so it accepts nothing.
        (RABIN_2, ("F", ("G", A)), 2),
    ],
    ids=[
        "buchi-trans",
        "cobuchi-implicit",
        "parity",
        "gen-buchi",
        "alias-state",
        "fin-neg",
        "rabin",
    ],
)
def test_import_foreign(text, formula, n_props):
    aut = from_hoa(text)
    matches_formula(aut, formula, n_props)
    same_language(aut, from_hoa(to_hoa(aut)), n_props)


@pytest.mark.parametrize(
    ("text", "error", "match"),
    [
        (BUCHI_TRANS.replace("[!0] 0", "[t] 0"), NondeterministicAutomatonError, "line 12"),
        (
            BUCHI_TRANS.replace("Start: 0", "Start: 0\nStart: 0"),
            NondeterministicAutomatonError,
            "Start",
        ),
        (
            BUCHI_TRANS.replace("[0] 0 {0}", "[0] 0&0 {0}"),
            NondeterministicAutomatonError,
            "universal",
        ),
        (BUCHI_TRANS.replace("--END--", ""), HOAError, "--END--"),
        (BUCHI_TRANS.replace("[0] 0 {0}", "[0] 3 {0}"), HOAError, "target 3"),
        (BUCHI_TRANS.replace("[0] 0 {0}", "[0] 0 {4}"), HOAError, "set 4"),
        (BUCHI_TRANS.replace("[!0]", "[!1]"), HOAError, "proposition 1"),
        (BUCHI_TRANS.replace("Acceptance: 1 Inf(0)\n", ""), HOAError, "Acceptance"),
        (BUCHI_TRANS.replace("HOA: v1", "HOA: v2"), HOAError, "version"),
        (BUCHI_TRANS.replace('AP: 1 "a"', 'AP: 2 "a"'), HOAError, "lists 1"),
        ("States: 1", HOAError, "HOA:"),
        (BUCHI_TRANS.replace("--END--", "--ABORT--"), HOAError, "aborted"),
        (BUCHI_TRANS.replace("[0] 0 {0}", "[0] 0 {0} %"), HOAError, "line 11"),
    ],
)
def test_import_errors(text, error, match):
    with pytest.raises(error, match=match):
        from_hoa(text)


def test_incomplete_input_is_completed_with_rejecting_sink():
    aut = from_hoa(STATE_BASED_ALIAS)
    assert aut.accepts([], [["a"]])
    assert not aut.accepts([["b"]], [["a"]])
