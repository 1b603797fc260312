"""Parser for Spot-compatible LTL.

Grammar (lowest to highest precedence, as in Spot's ``ltlparse.yy``)::

    ->  =>  <->  <=>       right associative
    |  ||  \\/              left associative
    xor  ^                 left associative
    &  &&  /\\              left associative
    U  R  V  W  M          right associative (V is R)
    X  F  G  []  <>        prefix
    !  ~                   prefix
    atoms: true false 1 0, identifiers [A-Za-z_][A-Za-z0-9_]*, "double-quoted names"
           (printable, no double quote), parenthesised formulas

Identifiers are read by maximal munch, so ``Goal`` and ``GFa`` are propositions; an
identifier made only of the letters ``F G X`` (``GF``, ``XX``, ``FG``) is a run of prefix
operators, so ``GF a`` is ``G F a``. (Spot also reads some glued forms such as ``GFa`` as
operators; write them with a space here.) A keyword (``X F G U R V W M xor true false``) is
never a proposition unless double-quoted.

Limits (checked while parsing, so hostile input fails with an :class:`LTLSyntaxError` naming
the position, never with a ``RecursionError``): at most :data:`MAX_TOKENS` tokens, and
operators nested at most :data:`MAX_DEPTH` deep (parentheses, prefix operators and
right-associative chains each add a level; a chain of ``&`` or ``|`` is one n-ary node and
adds one). Every later stage (simplification, translation, printing) recurses at most that
deep.
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
  | (?P<ident>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<num>[0-9]+)
  | (?P<quoted>"[^"\x00-\x1f\x7f]*")
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

#: Most tokens in a formula.
MAX_TOKENS = 10_000
#: Deepest nesting of operators in a formula (see the module docstring).
MAX_DEPTH = 100
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def is_plain_name(name: str) -> bool:
    """Whether ``name`` is a proposition written without quotes: an identifier
    ``[A-Za-z_][A-Za-z0-9_]*`` that is not a keyword or a run of ``F G X``."""
    return (
        isinstance(name, str)
        and _NAME.fullmatch(name) is not None
        and name not in _KEYWORDS
        and _PREFIX_RUN.fullmatch(name) is None
    )


class _Token:
    __slots__ = ("kind", "pos", "text", "value")

    def __init__(self, kind: str, value: str, pos: int, text: str) -> None:
        self.kind, self.value, self.pos, self.text = kind, value, pos, text


def _tokens(text: str) -> list[_Token]:
    out: list[_Token] = []
    pos = 0
    while pos < len(text):
        if len(out) >= MAX_TOKENS:
            raise LTLSyntaxError(
                f"formula longer than {MAX_TOKENS} tokens (the limit) at position {pos}", pos
            )
        m = _TOKEN.match(text, pos)
        if m is None:
            if text[pos] == '"':
                end = text.find('"', pos + 1)
                if end >= 0:
                    raise LTLSyntaxError(
                        f"quoted name starting at position {pos} holds a control character "
                        "(a newline, tab, ...)",
                        pos,
                    )
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
        self.depth = 0  # operators open around the current position

    def enter(self, tok: _Token) -> None:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise LTLSyntaxError(
                f"formula nested deeper than {MAX_DEPTH} operators (the limit) at position "
                f"{tok.pos}",
                tok.pos,
            )

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
        self.enter(self.peek())
        left = self.unary()
        operands: list[Formula] = []  # of a chain of one n-ary operator (& or |)
        chain = None
        while True:
            tok = self.peek()
            if tok.kind != "op" or tok.value not in _BINARY:
                break
            prec, right = _BINARY[tok.value]
            if prec < min_prec:
                break
            self.take()
            rhs = self.formula(prec if right else prec + 1)
            if tok.value in ("&", "|"):
                if chain != tok.value:
                    left = _close(chain, left, operands)
                    chain, operands = tok.value, [left]
                operands.append(rhs)
                continue
            left = _close(chain, left, operands)
            chain, operands = None, []
            left = Formula(tok.value, (left, rhs))
            if left.depth > MAX_DEPTH:
                raise LTLSyntaxError(
                    f"formula nested deeper than {MAX_DEPTH} operators (the limit) at "
                    f"position {tok.pos}",
                    tok.pos,
                )
        self.depth -= 1
        return _close(chain, left, operands)

    def unary(self) -> Formula:
        opened = []
        while True:  # a run of prefix operators, iteratively
            tok = self.peek()
            if tok.kind != "op" or tok.value not in _PREFIX:
                break
            self.take()
            self.enter(tok)
            opened.append(tok.value)
        f = self.atom()
        for op in reversed(opened):
            f = Formula(op, (f,))
        self.depth -= len(opened)
        return f

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


def _close(chain: str | None, left: Formula, operands: list[Formula]) -> Formula:
    """The n-ary node of a chain ``operands[0] op operands[1] op ...`` (``left`` if none)."""
    if chain is None:
        return left
    return Formula(chain, tuple(operands))


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
