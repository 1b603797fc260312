"""Parser for Spot-compatible LTL.

Grammar (lowest to highest precedence, as in Spot's ``ltlparse.yy``)::

    ->  =>  <->  <=>       right associative
    |  ||  \\/              left associative
    xor  ^                 left associative
    &  &&  /\\              left associative
    U  R  V  W  M          right associative (V is R)
    X  F  G  []  <>        prefix
    !  ~                   prefix
    atoms: true false 1 0, identifiers [A-Za-z_][A-Za-z0-9_.]*, "double-quoted names",
           parenthesised formulas

Identifiers are read by maximal munch, so ``Goal`` and ``GFa`` are propositions; an
identifier made only of the letters ``F G X`` (``GF``, ``XX``, ``FG``) is a run of prefix
operators, so ``GF a`` is ``G F a``. (Spot also reads some glued forms such as ``GFa`` as
operators; write them with a space here.) A keyword (``X F G U R V W M xor true false``) is
never a proposition unless double-quoted.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from planner.errors import LTLSyntaxError, UnknownPropositionError
from planner.ltl import syntax as s
from planner.ltl.syntax import Formula

_TOKEN = re.compile(
    r"""
    (?P<ws>\s+)
  | (?P<op><->|<=>|->|=>|&&|\|\||/\\|\\/|\[\]|<>|[!~&|^()])
  | (?P<ident>[A-Za-z_][A-Za-z0-9_.]*)
  | (?P<num>[0-9]+)
  | (?P<quoted>"[^"]*")
  """,
    re.VERBOSE,
)

_CANON = {
    "<=>": "<->",
    "=>": "->",
    "&&": "&",
    "/\\": "&",
    "||": "|",
    "\\/": "|",
    "^": "xor",
    "~": "!",
    "[]": "G",
    "<>": "F",
    "V": "R",
}
_KEYWORDS = frozenset({"X", "F", "G", "U", "R", "V", "W", "M", "xor", "true", "false"})
_PREFIX_RUN = re.compile(r"[FGX]{2,}")

# (precedence, right-associative) of binary operators.
_BINARY = {
    "->": (1, True),
    "<->": (1, True),
    "|": (2, False),
    "xor": (3, False),
    "&": (4, False),
    "U": (5, True),
    "R": (5, True),
    "W": (5, True),
    "M": (5, True),
}
_PREFIX = frozenset({"!", "X", "F", "G"})


class _Token:
    __slots__ = ("kind", "pos", "text", "value")

    def __init__(self, kind: str, value: str, pos: int, text: str) -> None:
        self.kind, self.value, self.pos, self.text = kind, value, pos, text


def _tokens(text: str) -> list[_Token]:
    out: list[_Token] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            if text[pos] == '"':
                raise LTLSyntaxError(f"unterminated quoted name starting at position {pos}", pos)
            raise LTLSyntaxError(f"unexpected character {text[pos]!r} at position {pos}", pos)
        kind = m.lastgroup or ""
        raw = m.group()
        if kind == "op":
            out.append(_Token("op", _CANON.get(raw, raw), pos, raw))
        elif kind == "ident":
            if raw in _KEYWORDS:
                out.append(_Token("op", _CANON.get(raw, raw), pos, raw))
            elif _PREFIX_RUN.fullmatch(raw):
                out.extend(_Token("op", ch, pos + k, ch) for k, ch in enumerate(raw))
            else:
                out.append(_Token("ap", raw, pos, raw))
        elif kind == "num":
            if raw not in ("0", "1"):
                raise LTLSyntaxError(
                    f"unexpected number {raw!r} at position {pos} (only 0 and 1 are constants)",
                    pos,
                )
            out.append(_Token("op", "true" if raw == "1" else "false", pos, raw))
        elif kind == "quoted":
            if len(raw) == 2:
                raise LTLSyntaxError(f"empty quoted proposition name at position {pos}", pos)
            out.append(_Token("ap", raw[1:-1], pos, raw))
        pos = m.end()
    out.append(_Token("end", "", len(text), "end of formula"))
    return out


class _Parser:
    def __init__(self, text: str) -> None:
        self.toks = _tokens(text)
        self.i = 0

    def peek(self) -> _Token:
        return self.toks[self.i]

    def take(self) -> _Token:
        tok = self.toks[self.i]
        self.i += 1
        return tok

    def fail(self, tok: _Token, expected: str) -> LTLSyntaxError:
        found = "end of formula" if tok.kind == "end" else repr(tok.text)
        return LTLSyntaxError(f"expected {expected} at position {tok.pos}, found {found}", tok.pos)

    def formula(self, min_prec: int = 1) -> Formula:
        left = self.unary()
        while True:
            tok = self.peek()
            if tok.kind != "op" or tok.value not in _BINARY:
                return left
            prec, right = _BINARY[tok.value]
            if prec < min_prec:
                return left
            self.take()
            rhs = self.formula(prec if right else prec + 1)
            left = _make_binary(tok.value, left, rhs)

    def unary(self) -> Formula:
        tok = self.peek()
        if tok.kind == "op" and tok.value in _PREFIX:
            self.take()
            arg = self.unary()
            return Formula(tok.value, (arg,))
        return self.atom()

    def atom(self) -> Formula:
        tok = self.take()
        if tok.kind == "ap":
            return s.ap(tok.value)
        if tok.kind == "op":
            if tok.value == "true":
                return s.TRUE
            if tok.value == "false":
                return s.FALSE
            if tok.value == "(":
                inner = self.formula()
                close = self.take()
                if close.kind != "op" or close.value != ")":
                    raise self.fail(close, "')' or a binary operator")
                return inner
        raise self.fail(tok, "a proposition, constant, unary operator or '('")


def _make_binary(op: str, left: Formula, right: Formula) -> Formula:
    if op in ("&", "|"):
        return Formula(op, (left, right))
    return Formula(op, (left, right))


def parse(formula: str) -> Formula:
    """Parse a Spot-compatible LTL formula.

    Raises:
        LTLSyntaxError: with the 0-based position and what was expected there.
    """
    if not isinstance(formula, str):
        raise TypeError(f"parse expects a string, got {type(formula).__name__}")
    p = _Parser(formula)
    if p.peek().kind == "end":
        raise LTLSyntaxError("empty formula: expected a formula at position 0", 0)
    result = p.formula()
    tok = p.peek()
    if tok.kind != "end":
        raise p.fail(tok, "a binary operator or end of formula")
    return result


def check_propositions(formula: str | Formula, allowed: Iterable[str]) -> Formula:
    """Check that every proposition of ``formula`` is one of ``allowed``.

    Returns:
        the parsed formula.

    Raises:
        UnknownPropositionError: naming the first (alphabetically) unknown proposition.
        LTLSyntaxError: if ``formula`` is a string that does not parse.
    """
    f = parse(formula) if isinstance(formula, str) else formula
    allowed_set = frozenset(allowed)
    unknown = sorted(f.propositions() - allowed_set)
    if unknown:
        raise UnknownPropositionError(
            f"formula {s.to_string(f)!r} uses proposition {unknown[0]!r}, which is not among "
            f"the provided labels {sorted(allowed_set)}"
        )
    return f
