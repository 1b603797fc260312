"""HOA v1 (Hanoi Omega-Automata format) export and import of deterministic automata.

Format: Babiak, Blahoudek, Duret-Lutz, Klein, Křetínský, Müller, Parker & Strejček, "The
Hanoi Omega-Automata Format", CAV 2015; http://adl.github.io/hoaf/.

:func:`to_hoa` writes a :class:`~planner.automaton.RabinAutomaton` with state-based
acceptance: pair ``i`` becomes ``Fin(2i) & Inf(2i+1)``, state ``s`` carries mark ``2i`` if it
is in ``B_i`` and ``2i+1`` if it is in ``G_i``; edges carry explicit labels (prime implicants
of the letters that lead to each successor).

:func:`from_hoa` reads a *deterministic* automaton (one initial state, pairwise disjoint
edge labels per state, no universal branching) with any acceptance condition (Rabin, Büchi,
co-Büchi, parity, or a generic ``Inf``/``Fin`` formula), state- or transition-based marks,
explicit or implicit labels, aliases. This module parses the text into a successor table
with edge marks; :mod:`planner.ltl.acceptance` makes it state-based Rabin. Missing edges go
to a rejecting sink. Transition marks become state marks by splitting each state by the
marks of the edge that enters it; the acceptance formula is put in disjunctive normal form,
each disjunct ``Fin(..) & .. & Inf(I_1) & .. & Inf(I_k)`` becomes one Rabin pair, with a
round-robin counter over ``I_1 .. I_k`` when ``k >= 2`` (degeneralisation). The result is
reduced with :func:`planner.ltl.reduce.reduce_rabin`.

Reading is bounded as a translation is (:mod:`planner.ltl.budget`): at most 16 propositions
(``2^16`` letters), ``States:`` times letters at most ``2^22`` table entries (checked before
the table is allocated), label and acceptance expressions nested at most
:data:`MAX_NESTING` deep, acceptance conditions of at most
:data:`~planner.ltl.acceptance.MAX_DISJUNCTS` disjuncts, and the default time limit.
"""

from __future__ import annotations

import re

import numpy as np

from planner.automaton import RabinAutomaton
from planner.errors import HOAError, NondeterministicAutomatonError
from planner.ltl.acceptance import marks_to_rabin
from planner.ltl.boolean import cover
from planner.ltl.budget import TranslationLimits, limited, tick


def _quote(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _label(letters: list[int], n_props: int) -> str:
    if len(letters) == 1 << n_props:
        return "t"
    parts = []
    for mask, val in cover(letters, n_props):
        lits = [f"{'' if val >> b & 1 else '!'}{b}" for b in range(n_props) if mask >> b & 1]
        parts.append("&".join(lits) if lits else "t")
    return (
        " | ".join(parts)
        if len(parts) == 1
        else " | ".join(f"({p})" if "&" in p else p for p in parts)
    )


def to_hoa(automaton: RabinAutomaton, name: str | None = None) -> str:
    """HOA v1 text of ``automaton`` (state-based Rabin acceptance, explicit labels)."""
    a = automaton
    m = len(a.pairs)
    lines = ["HOA: v1"]
    if name is not None:
        lines.append(f"name: {_quote(name)}")
    lines.append(f"States: {a.n_states}")
    lines.append(f"Start: {a.initial}")
    lines.append(f"AP: {len(a.propositions)}" + "".join(" " + _quote(p) for p in a.propositions))
    lines.append(f"acc-name: Rabin {m}")
    cond = " | ".join(f"(Fin({2 * i})&Inf({2 * i + 1}))" for i in range(m)) if m else "f"
    lines.append(f"Acceptance: {2 * m} {cond}")
    lines.append("properties: trans-labels explicit-labels state-acc complete deterministic")
    lines.append("--BODY--")
    for s in a.states:
        marks = [2 * i for i, p in enumerate(a.pairs) if s in p.bad]
        marks += [2 * i + 1 for i, p in enumerate(a.pairs) if s in p.good]
        acc = " {" + " ".join(str(x) for x in sorted(marks)) + "}" if marks else ""
        lines.append(f"State: {s} {_quote(a.state_names[s])}{acc}")
        groups: dict[int, list[int]] = {}
        for letter, t in enumerate(a.transitions[s].tolist()):
            groups.setdefault(t, []).append(letter)
        for t, letters in sorted(groups.items()):
            lines.append(f"[{_label(letters, len(a.propositions))}] {t}")
    lines.append("--END--")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- import

_TOKEN = re.compile(
    r"""
    (?P<ws>[ \t\r]+)
  | (?P<nl>\n)
  | (?P<comment>/\*(?:.|\n)*?\*/)
  | (?P<marker>--BODY--|--END--|--ABORT--)
  | (?P<header>[A-Za-z_][A-Za-z0-9_-]*:)
  | (?P<string>"(?:[^"\\]|\\.)*")
  | (?P<int>[0-9]+)
  | (?P<alias>@[A-Za-z0-9_-]+)
  | (?P<ident>[A-Za-z_][A-Za-z0-9_-]*)
  | (?P<punct>[\[\]{}()!&|])
  """,
    re.VERBOSE,
)


class _Tok:
    __slots__ = ("kind", "line", "text")

    def __init__(self, kind: str, text: str, line: int) -> None:
        self.kind, self.text, self.line = kind, text, line

    def __repr__(self) -> str:
        return repr(self.text)


def _lex(text: str) -> list[_Tok]:
    toks: list[_Tok] = []
    pos, line = 0, 1
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            raise HOAError(f"line {line}: unexpected character {text[pos]!r}")
        kind = m.lastgroup or ""
        raw = m.group()
        if kind not in ("ws", "nl", "comment"):
            toks.append(_Tok(kind, raw, line))
        line += raw.count("\n")
        pos = m.end()
    toks.append(_Tok("eof", "end of input", line))
    return toks


#: Deepest nesting of a label or acceptance expression (parentheses, negations, aliases).
MAX_NESTING = 100


class _Reader:
    def __init__(self, toks: list[_Tok]) -> None:
        self.toks, self.i = toks, 0
        self.depth = 0

    def enter(self, tok: _Tok) -> None:
        self.depth += 1
        if self.depth > MAX_NESTING:
            raise HOAError(f"line {tok.line}: expression nested deeper than {MAX_NESTING}")

    def peek(self) -> _Tok:
        return self.toks[self.i]

    def take(self) -> _Tok:
        t = self.toks[self.i]
        self.i += 1
        return t

    def expect(self, kind: str, what: str, text: str | None = None) -> _Tok:
        t = self.take()
        if t.kind != kind or (text is not None and t.text != text):
            raise HOAError(f"line {t.line}: expected {what}, found {t.text!r}")
        return t

    def integer(self, what: str) -> int:
        tok = self.expect("int", what)
        try:
            return int(tok.text)
        except ValueError:  # more digits than Python converts
            raise HOAError(f"line {tok.line}: {what}: {len(tok.text)} digits") from None

    def is_punct(self, ch: str) -> bool:
        t = self.peek()
        return t.kind == "punct" and t.text == ch


def _parse_or(r: _Reader, atom):
    left = _parse_and(r, atom)
    items = [left]
    while r.is_punct("|"):
        r.take()
        items.append(_parse_and(r, atom))
    return items[0] if len(items) == 1 else ("|", items)


def _parse_and(r: _Reader, atom):
    items = [_parse_not(r, atom)]
    while r.is_punct("&"):
        r.take()
        items.append(_parse_not(r, atom))
    return items[0] if len(items) == 1 else ("&", items)


def _parse_not(r: _Reader, atom):
    negations = 0
    while r.is_punct("!"):  # a run of negations, iteratively
        r.enter(r.take())
        negations += 1
    if r.is_punct("("):
        r.enter(r.take())
        inner = _parse_or(r, atom)
        r.expect("punct", "')'", ")")
        r.depth -= 1
    else:
        inner = atom(r)
    for _ in range(negations):
        inner = ("!", inner)
    r.depth -= negations
    return inner


def _strip_quotes(raw: str) -> str:
    return re.sub(r"\\(.)", r"\1", raw[1:-1])


def from_hoa(text: str) -> RabinAutomaton:
    """Read a deterministic HOA v1 automaton as a state-based Rabin automaton.

    Raises:
        HOAError: malformed, unsupported or too large input (names the line).
        NondeterministicAutomatonError: several initial states, overlapping edge labels,
            or universal branching.
        TranslationLimitError: reading took longer than the default time limit.
    """
    with limited(TranslationLimits()):
        return _from_hoa(text)


def _from_hoa(text: str) -> RabinAutomaton:
    limits = TranslationLimits()
    r = _Reader(_lex(text))
    first = r.expect("header", "'HOA:' at the start", "HOA:")
    version = r.expect("ident", "a format version after 'HOA:'")
    if version.text != "v1":
        raise HOAError(f"line {first.line}: unsupported HOA version {version.text!r}")
    n_states: int | None = None
    start: int | None = None
    aps: list[str] | None = None
    aliases: dict[str, object] = {}
    acceptance = None
    n_sets = 0
    while r.peek().kind == "header":
        h = r.take()
        if h.text == "States:":
            n_states = r.integer("a state count after 'States:'")
        elif h.text == "Start:":
            s = r.integer("a state number after 'Start:'")
            if r.is_punct("&"):
                raise NondeterministicAutomatonError(
                    f"line {h.line}: conjunctive initial states (alternation) are not supported"
                )
            if start is not None:
                raise NondeterministicAutomatonError(
                    f"line {h.line}: a second 'Start:' line; a deterministic automaton has "
                    f"exactly one initial state"
                )
            start = s
        elif h.text == "AP:":
            count = r.integer("the number of propositions after 'AP:'")
            if (1 << min(count, 63)) > limits.max_letters:
                raise HOAError(
                    f"line {h.line}: {count} propositions, more than the limit of "
                    f"{limits.max_letters.bit_length() - 1} ({limits.max_letters} letters)"
                )
            aps = []
            while r.peek().kind == "string":
                aps.append(_strip_quotes(r.take().text))
            if len(aps) != count:
                raise HOAError(f"line {h.line}: 'AP: {count}' lists {len(aps)} propositions")
            if len(set(aps)) != len(aps):
                raise HOAError(f"line {h.line}: duplicate proposition names in 'AP:'")
        elif h.text == "Alias:":
            name = r.expect("alias", "an @alias name after 'Alias:'").text
            aliases[name] = _parse_or(r, _label_atom)
        elif h.text == "Acceptance:":
            n_sets = r.integer("the number of acceptance sets after 'Acceptance:'")
            acceptance = _parse_or(r, _acc_atom)
        else:  # name:, tool:, acc-name:, properties:, and unknown headers are skipped
            while r.peek().kind not in ("header", "marker", "eof"):
                r.take()
    body = r.expect("marker", "'--BODY--' after the header", "--BODY--")
    if n_states is None:
        raise HOAError(f"line {body.line}: the header lacks 'States:'")
    if start is None:
        raise HOAError(f"line {body.line}: the header lacks 'Start:' (no initial state)")
    if not 0 <= start < n_states:
        raise HOAError(f"line {body.line}: initial state {start} is not in [0, {n_states})")
    if acceptance is None:
        raise HOAError(f"line {body.line}: the header lacks 'Acceptance:'")
    if aps is None:
        aps = []
    _check_sets(acceptance, n_sets, body.line)
    n_props = len(aps)
    n_letters = 1 << n_props
    if n_states * n_letters > limits.max_entries:
        raise HOAError(
            f"line {body.line}: {n_states} states x {n_letters} letters, more than the limit "
            f"of {limits.max_entries} table entries"
        )
    all_letters = (1 << n_letters) - 1
    with_bit = [sum(1 << x for x in range(n_letters) if x >> b & 1) for b in range(n_props)]

    resolving: list[str] = []

    def letters_of(expr, line: int) -> int:
        if isinstance(expr, _Tok):
            if expr.kind == "ident":
                return all_letters if expr.text == "t" else 0
            if expr.kind == "alias":
                if expr.text not in aliases:
                    raise HOAError(f"line {line}: unknown alias {expr.text}")
                if expr.text in resolving:
                    raise HOAError(f"line {line}: alias {expr.text} is defined through itself")
                if len(resolving) >= MAX_NESTING:
                    raise HOAError(f"line {line}: aliases nested deeper than {MAX_NESTING}")
                resolving.append(expr.text)
                try:
                    return letters_of(aliases[expr.text], line)
                finally:
                    resolving.pop()
            b = int(expr.text)
            if b >= n_props:
                raise HOAError(f"line {line}: proposition {b} is not in [0, {n_props})")
            return with_bit[b]
        op, arg = expr
        if op == "!":
            return all_letters & ~letters_of(arg, line)
        vals = [letters_of(x, line) for x in arg]
        out = all_letters if op == "&" else 0
        for v in vals:
            out = out & v if op == "&" else out | v
        return out

    # edges[q][letter] = (target, marks)
    table = np.full((n_states, n_letters), -1, dtype=np.int64)
    marks = np.zeros((n_states, n_letters), dtype=object)
    seen_states: set[int] = set()
    while r.peek().kind == "header" and r.peek().text == "State:":
        st = r.take()
        state_label = None
        if r.is_punct("["):
            r.take()
            state_label = letters_of(_parse_or(r, _label_atom), st.line)
            r.expect("punct", "']'", "]")
        q = r.integer("a state number after 'State:'")
        if not 0 <= q < n_states:
            raise HOAError(f"line {st.line}: state {q} is not in [0, {n_states})")
        if q in seen_states:
            raise HOAError(f"line {st.line}: state {q} is defined twice")
        seen_states.add(q)
        if r.peek().kind == "string":
            r.take()
        state_marks = _acc_sig(r, n_sets)
        implicit = 0
        while r.peek().kind in ("int", "punct") and (r.peek().kind == "int" or r.is_punct("[")):
            e_line = r.peek().line
            if r.is_punct("["):
                r.take()
                letters = letters_of(_parse_or(r, _label_atom), e_line)
                r.expect("punct", "']'", "]")
            elif state_label is not None:
                letters = state_label
            else:
                if implicit >= n_letters:
                    raise HOAError(
                        f"line {e_line}: state {q} has more than {n_letters} implicitly "
                        f"labelled edges"
                    )
                letters = 1 << implicit
                implicit += 1
            target = r.integer("an edge's target state")
            if r.is_punct("&"):
                raise NondeterministicAutomatonError(
                    f"line {e_line}: universal branching (alternation) is not supported"
                )
            if not 0 <= target < n_states:
                raise HOAError(f"line {e_line}: edge target {target} is not in [0, {n_states})")
            edge_marks = state_marks | _acc_sig(r, n_sets)
            tick(n_letters)
            letter_idx = [x for x in range(n_letters) if letters >> x & 1]
            clash = [x for x in letter_idx if table[q, x] >= 0]
            if clash:
                raise NondeterministicAutomatonError(
                    f"line {e_line}: state {q} has two edges on letter "
                    f"{{{', '.join(p for b, p in enumerate(aps) if clash[0] >> b & 1)}}}; "
                    f"the automaton is not deterministic"
                )
            table[q, letter_idx] = target
            for x in letter_idx:
                marks[q, x] = edge_marks
    end = r.take()
    if end.text == "--ABORT--":
        raise HOAError(f"line {end.line}: the automaton was aborted (--ABORT--)")
    if end.kind != "marker" or end.text != "--END--":
        raise HOAError(f"line {end.line}: expected 'State:' or '--END--', found {end.text!r}")
    return marks_to_rabin(table, marks, start, acceptance, aps)


def _label_atom(r: _Reader):
    t = r.take()
    if t.kind == "int" or t.kind == "alias" or (t.kind == "ident" and t.text in ("t", "f")):
        return t
    raise HOAError(
        f"line {t.line}: expected a label (t, f, a proposition number, @alias, "
        f"!, (), &, |), found {t.text!r}"
    )


def _acc_atom(r: _Reader):
    t = r.take()
    if t.kind == "ident" and t.text in ("t", "f"):
        return ("const", t.text == "t")
    if t.kind == "ident" and t.text in ("Inf", "Fin"):
        r.expect("punct", "'(' after " + t.text, "(")
        neg = False
        if r.is_punct("!"):
            r.take()
            neg = True
        n = r.integer("an acceptance set number")
        r.expect("punct", "')'", ")")
        return (t.text, n, neg, t.line)
    raise HOAError(f"line {t.line}: expected Inf(..), Fin(..), t or f, found {t.text!r}")


def _check_sets(cond, n_sets: int, line: int) -> None:
    if cond[0] in ("Inf", "Fin"):
        if cond[1] >= n_sets:
            raise HOAError(f"line {cond[3]}: acceptance set {cond[1]} is not in [0, {n_sets})")
    elif cond[0] in ("&", "|"):
        for c in cond[1]:
            _check_sets(c, n_sets, line)
    elif cond[0] == "!":
        raise HOAError(f"line {line}: '!' is not allowed in an acceptance condition")


def _acc_sig(r: _Reader, n_sets: int) -> frozenset[int]:
    if not r.is_punct("{"):
        return frozenset()
    t = r.take()
    out = set()
    while r.peek().kind == "int":
        n = int(r.take().text)
        if n >= n_sets:
            raise HOAError(f"line {t.line}: acceptance set {n} is not in [0, {n_sets})")
        out.add(n)
    r.expect("punct", "'}'", "}")
    return frozenset(out)


__all__ = ["from_hoa", "to_hoa"]
