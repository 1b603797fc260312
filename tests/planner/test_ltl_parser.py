"""Parser: Spot syntax, precedence, associativity, errors, proposition checks."""

from __future__ import annotations

import pytest

from planner.errors import LTLSyntaxError, UnknownPropositionError
from planner.ltl import syntax as s
from planner.ltl.parser import check_propositions, parse

a, b, c = s.ap("a"), s.ap("b"), s.ap("c")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("!Haz U Goal", s.until(s.lnot(s.ap("Haz")), s.ap("Goal"))),
        ("a | b & c", s.lor(a, s.land(b, c))),
        ("a & b | c", s.lor(s.land(a, b), c)),
        ("a xor b | c", s.lor(s.xor(a, b), c)),
        ("a & b xor c", s.xor(s.land(a, b), c)),
        ("a -> b -> c", s.implies(a, s.implies(b, c))),
        ("a <-> b -> c", s.equiv(a, s.implies(b, c))),
        ("a | b -> c", s.implies(s.lor(a, b), c)),
        ("a U b U c", s.until(a, s.until(b, c))),
        ("a U b & c", s.land(s.until(a, b), c)),
        ("F a U b", s.until(s.eventually(a), b)),
        ("!a U b", s.until(s.lnot(a), b)),
        ("X !a", s.nxt(s.lnot(a))),
        ("a R b W c M a", s.release(a, s.weak_until(b, s.strong_release(c, a)))),
        ("a V b", s.release(a, b)),
        ("GF a", s.always(s.eventually(a))),
        ("[]<> a", s.always(s.eventually(a))),
        ("a && b || c", s.lor(s.land(a, b), c)),
        ("a /\\ b \\/ c", s.lor(s.land(a, b), c)),
        ("a => b <=> c", s.implies(a, s.equiv(b, c))),
        ("~a ^ b", s.xor(s.lnot(a), b)),
        ("true & 1 | false & 0", s.lor(s.land(s.TRUE, s.TRUE), s.land(s.FALSE, s.FALSE))),
        ('"x y" U "G"', s.until(s.ap("x y"), s.ap("G"))),
        ("Goal & GFa", s.land(s.ap("Goal"), s.ap("GFa"))),
        ("((a))", a),
    ],
)
def test_parse(text, expected):
    assert parse(text) is expected


def test_to_string_round_trip():
    for text in ["!Haz U Goal", "G (a -> F b)", "(a U b) U c", "X X a W b", '"x y" & G "U"']:
        f = parse(text)
        assert parse(str(f)) is f


@pytest.mark.parametrize(
    ("text", "position", "match"),
    [
        ("a &", 3, "expected a proposition"),
        ("(a | b", 6, "expected '\\)'"),
        ("a b", 2, "found 'b'"),
        ("", 0, "empty formula"),
        ("a & 5", 4, "only 0 and 1"),
        ("a $ b", 2, "unexpected character"),
        ('a & "b', 4, "unterminated"),
        ("a & )", 4, "found '\\)'"),
        ("U a", 0, "found 'U'"),
    ],
)
def test_errors_name_position(text, position, match):
    with pytest.raises(LTLSyntaxError, match=match) as info:
        parse(text)
    assert info.value.position == position
    assert f"position {position}" in str(info.value)


def test_propositions_and_check():
    f = parse("G(!Haz) & F(Goal & F Home)")
    assert f.propositions() == frozenset({"Haz", "Goal", "Home"})
    assert check_propositions(f, ["Goal", "Haz", "Home", "A"]) is f
    with pytest.raises(UnknownPropositionError, match="'Home'"):
        check_propositions("G(!Haz) & F(Goal & F Home)", ["Goal", "Haz"])


@pytest.mark.parametrize(
    "text",
    [
        "(" * 101 + "a" + ")" * 101,
        "!" * 101 + "a",
        "X " * 101 + "a",
        " U ".join(["a"] * 102),
        " xor ".join(["a"] * 102),  # left-deep, built iteratively: the tree is too deep
        "(" * 3000 + "a" + ")" * 3000,
    ],
)
def test_nesting_beyond_the_limit_is_a_syntax_error(text):
    with pytest.raises(LTLSyntaxError, match="nested deeper than 100") as info:
        parse(text)
    assert 0 <= info.value.position < len(text)


def test_nesting_at_the_limit_parses_and_translates():
    from planner.ltl.translate import translate

    for text in ("(" * 99 + "a" + ")" * 99, "X " * 99 + "a", " U ".join(["a", "b"] * 49)):
        f = parse(text)
        assert f.depth <= 100
        assert translate(f).n_states >= 2  # every later stage copes with that depth


def test_chains_of_and_or_are_one_n_ary_node():
    f = parse(" & ".join(["a", "b", "c", "d"]))
    assert f.op == "&" and len(f.children) == 4 and f.depth == 1
    assert parse("a & b | c & d") is s.lor(s.land(a, b), s.land(c, s.ap("d")))
    assert parse(" | ".join(["a"] * 4000)).depth == 1  # long chains stay flat


def test_token_limit():
    with pytest.raises(LTLSyntaxError, match="longer than 10000 tokens"):
        parse(" & ".join(["a"] * 6000))


def test_names_are_plain_identifiers():
    from planner.ltl.parser import is_plain_name

    assert is_plain_name("Goal") and is_plain_name("_a1")
    for bad in ("", "U", "GF", "XX", "true", "a.b", "a b", '"a"', "1a", "a\nb", "é"):
        assert not is_plain_name(bad), bad
    with pytest.raises(LTLSyntaxError, match=r"unexpected character '\.'"):
        parse("a.b")
    with pytest.raises(LTLSyntaxError, match="control character"):
        parse('"a\nb" U c')
