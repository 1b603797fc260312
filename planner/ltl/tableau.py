"""LTL to transition-based generalised Büchi automata (TGBA) by tableau expansion.

The construction is the on-the-fly tableau of Gerth, Peled, Vardi & Wolper ("Simple
on-the-fly automatic verification of linear temporal logic", PSTV 1995) in Couvreur's
transition-based form ("On-the-fly verification of linear temporal logic", FM 1999):

* a state is a set ``S`` of NNF formulas that must hold from the current position on;
* expanding ``S`` rewrites every formula into what must hold *now* (a conjunction of
  literals) and what must hold *next* (a set of formulas), branching on ``|`` and on the
  expansion laws ``f U g = g | (f & X(f U g))``, ``f R g = g & (f | X(f R g))``,
  ``f W g = g | (f & X(f W g))``, ``f M g = g & (f | X(f M g))``, ``F f = f | X F f``,
  ``G f = f & X G f``;
* for every eventuality ``e`` (a ``U``, ``M`` or ``F`` subformula) the acceptance set
  ``Acc_e`` holds the transitions that do not postpone ``e`` (take the ``X e`` branch); a
  run is accepting iff it takes a transition of every ``Acc_e`` infinitely often.

The language of state ``S`` is exactly the set of words satisfying ``/\\ S``. Options that
are implied by another option of the same state (weaker letter constraint, fewer next
obligations, fewer postponed eventualities) are dropped, as in LTL2BA (Gastin & Oddoux,
CAV 2001).
"""

from __future__ import annotations

from dataclasses import dataclass

from planner.ltl.budget import tick
from planner.ltl.interning import intern
from planner.ltl.syntax import Formula


@dataclass
class TGBA:
    """A transition-based generalised Büchi automaton over letters ``0 .. 2**n_props - 1``.

    ``edges[s]`` lists ``(letters, target, acc)``: ``letters`` is a bitmask over letters,
    ``acc`` a bitmask over the ``n_acc`` acceptance sets the edge belongs to.
    """

    n_props: int
    states: list[frozenset[Formula]]
    edges: list[list[tuple[int, int, int]]]
    n_acc: int
    initial: int = 0


def _letter_masks(n_props: int) -> list[int]:
    """``masks[b]``: the set of letters (as a bitmask over letters) in which bit ``b`` is set."""
    n_letters = 1 << n_props
    return [sum(1 << a for a in range(n_letters) if a >> b & 1) for b in range(n_props)]


#: One branch of an expansion: formulas still to rewrite, formulas already rewritten, the
#: propositions required true (``pos``) and false (``neg``) now (bitmasks over
#: propositions), the formulas required next and the eventualities postponed (a bitmask).
_Branch = tuple[list[Formula], frozenset[Formula], int, int, frozenset[Formula], int]
#: A completed branch: ``(pos, neg, next, postponed)``.
_Option = tuple[int, int, frozenset[Formula], int]


def _split(
    f: Formula, todo: list[Formula], nxt: frozenset[Formula], post: int, ev_bit: dict
) -> list[tuple[list[Formula], frozenset[Formula], int]]:
    """The branches ``(todo, next, postponed)`` of a ``|`` or of a temporal formula ``f`` by
    its expansion law (module docstring); a branch that takes ``X f`` for an eventuality
    ``f`` postpones it."""
    op = f.op
    if op == "|":
        return [([*todo, c], nxt, post) for c in f.children]
    if op == "F":
        return [([*todo, f.children[0]], nxt, post), (todo, nxt | {f}, post | ev_bit[f])]
    g, h = f.children
    if op == "U":
        return [([*todo, h], nxt, post), ([*todo, g], nxt | {f}, post | ev_bit[f])]
    if op == "W":
        return [([*todo, h], nxt, post), ([*todo, g], nxt | {f}, post)]
    if op == "R":
        return [([*todo, g, h], nxt, post), ([*todo, h], nxt | {f}, post)]
    # M
    return [([*todo, g, h], nxt, post), ([*todo, h], nxt | {f}, post | ev_bit[f])]


def _rewrite(branch: _Branch, bit: dict, ev_bit: dict, stack: list[_Branch]) -> _Option | None:
    """Rewrite the formulas of ``branch`` until it is complete (returned), contradictory
    (``None``) or splits: then its branches are pushed on ``stack`` (``None``)."""
    todo, done, pos, neg, nxt, post = branch
    while todo:
        tick()
        f = todo.pop()
        if f in done:
            continue
        done = done | {f}
        op = f.op
        if op == "true":
            continue
        if op == "false":
            return None
        if op == "ap":
            b = bit[f.name]
            if neg & b:
                return None
            pos |= b
        elif op == "!":
            b = bit[f.children[0].name]
            if pos & b:
                return None
            neg |= b
        elif op == "&":
            todo.extend(f.children)
        elif op == "X":
            nxt = nxt | {f.children[0]}
        elif op == "G":
            todo.append(f.children[0])
            nxt = nxt | {f}
        else:
            # A branch pushed later is expanded first, so the second branch of a split is
            # pushed before the first.
            for t, x, q in reversed(_split(f, todo, nxt, post, ev_bit)):
                stack.append((list(t), done, pos, neg, x, q))
            return None
    return (pos, neg, nxt, post)


def _drop_implied(options: list[_Option]) -> list[_Option]:
    """The options not implied by another one: weaker letter constraint, fewer next
    obligations and fewer postponed eventualities (LTL2BA's transition simplification)."""
    unique = list(dict.fromkeys(options))
    kept = []
    for i, (p, n, x, q) in enumerate(unique):
        tick(len(unique))
        if not any(
            j != i and p2 & p == p2 and n2 & n == n2 and q2 & q == q2 and x2 <= x
            for j, (p2, n2, x2, q2) in enumerate(unique)
        ):
            kept.append((p, n, x, q))
    return kept


def _expand(start: frozenset[Formula], bit: dict, ev_bit: dict) -> list[_Option]:
    """The options ``(pos, neg, next, postponed)`` of state ``start``: depth-first over the
    branches, with an explicit stack (a formula with many disjunctions branches deeply)."""
    results: list[_Option] = []
    # Structural order (not the set's, which follows memory addresses), so that the options,
    # hence the numbering of the states, are the same in every process.
    todo = sorted(start, key=Formula.sort_key)
    stack: list[_Branch] = [(todo, frozenset(), 0, 0, frozenset(), 0)]
    while stack:
        option = _rewrite(stack.pop(), bit, ev_bit, stack)
        if option is not None:
            results.append(option)
    return _drop_implied(results)


def _letters(pos: int, neg: int, n_props: int, with_bit: list[int]) -> int:
    """The letters (a bitmask over letters) with the propositions ``pos`` true and ``neg``
    false."""
    letters = (1 << (1 << n_props)) - 1
    for b in range(n_props):
        if pos >> b & 1:
            letters &= with_bit[b]
        elif neg >> b & 1:
            letters &= ~with_bit[b]
    return letters


def build_tgba(formula: Formula, propositions: tuple[str, ...]) -> TGBA:
    """Tableau TGBA of NNF ``formula`` with letters over ``propositions``: the states
    reachable from ``{formula}``, an edge per option of a state's expansion, in
    ``Acc_e`` unless it postpones ``e``."""
    bit = {p: 1 << i for i, p in enumerate(propositions)}
    eventualities = [g for g in formula.subformulas() if g.op in ("U", "M", "F")]
    ev_bit = {g: 1 << i for i, g in enumerate(eventualities)}
    all_acc = (1 << len(eventualities)) - 1
    n_props = len(propositions)
    with_bit = _letter_masks(n_props)
    start = frozenset({formula})
    index = {start: 0}
    states = [start]
    edges: list[list[tuple[int, int, int]]] = []
    i = 0
    while i < len(states):
        out: dict[tuple[int, int], int] = {}
        for pos, neg, nxt, post in _expand(states[i], bit, ev_bit):
            letters = _letters(pos, neg, n_props, with_bit)
            if not letters:
                continue
            j = intern(nxt, index, states)
            key = (j, all_acc & ~post)
            out[key] = out.get(key, 0) | letters
        edges.append([(letters, j, acc) for (j, acc), letters in out.items()])
        i += 1
    return TGBA(n_props, states, edges, len(eventualities))
