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


def build_tgba(formula: Formula, propositions: tuple[str, ...]) -> TGBA:
    """Tableau TGBA of NNF ``formula`` with letters over ``propositions``."""
    bit = {p: 1 << i for i, p in enumerate(propositions)}
    eventualities = [g for g in formula.subformulas() if g.op in ("U", "M", "F")]
    ev_bit = {g: 1 << i for i, g in enumerate(eventualities)}
    all_acc = (1 << len(eventualities)) - 1
    n_letters = 1 << len(propositions)
    all_letters = (1 << n_letters) - 1
    with_bit = _letter_masks(len(propositions))

    def expand(start: frozenset[Formula]) -> list[tuple[int, int, frozenset[Formula], int]]:
        results: list[tuple[int, int, frozenset[Formula], int]] = []
        # Depth-first over the branches, with an explicit stack (a formula with many
        # disjunctions branches deeply); a branch pushed later is expanded first, so the
        # second branch of a split is pushed before the first.
        stack: list[tuple[list[Formula], frozenset, int, int, frozenset, int]] = [
            (list(start), frozenset(), 0, 0, frozenset(), 0)
        ]
        while stack:
            todo, done, pos, neg, nxt, post = stack.pop()
            alive = True
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
                    alive = False
                    break
                if op == "ap":
                    b = bit[f.name]
                    if neg & b:
                        alive = False
                        break
                    pos |= b
                elif op == "!":
                    b = bit[f.children[0].name]
                    if pos & b:
                        alive = False
                        break
                    neg |= b
                elif op == "&":
                    todo.extend(f.children)
                elif op == "X":
                    nxt = nxt | {f.children[0]}
                elif op == "G":
                    todo.append(f.children[0])
                    nxt = nxt | {f}
                else:
                    if op == "|":
                        branches = [([*todo, c], nxt, post) for c in f.children]
                    elif op == "F":
                        branches = [
                            ([*todo, f.children[0]], nxt, post),
                            (todo, nxt | {f}, post | ev_bit[f]),
                        ]
                    else:
                        g, h = f.children
                        if op == "U":
                            branches = [
                                ([*todo, h], nxt, post),
                                ([*todo, g], nxt | {f}, post | ev_bit[f]),
                            ]
                        elif op == "W":
                            branches = [([*todo, h], nxt, post), ([*todo, g], nxt | {f}, post)]
                        elif op == "R":
                            branches = [([*todo, g, h], nxt, post), ([*todo, h], nxt | {f}, post)]
                        else:  # M
                            branches = [
                                ([*todo, g, h], nxt, post),
                                ([*todo, h], nxt | {f}, post | ev_bit[f]),
                            ]
                    for t, x, q in reversed(branches):
                        stack.append((list(t), done, pos, neg, x, q))
                    alive = False  # this branch continues in the pushed ones
                    break
            if alive:
                results.append((pos, neg, nxt, post))

        # Drop options implied by another one (LTL2BA's transition simplification).
        unique = list(dict.fromkeys(results))
        kept = []
        for i, (p, n, x, q) in enumerate(unique):
            tick(len(unique))
            if not any(
                j != i and p2 & p == p2 and n2 & n == n2 and q2 & q == q2 and x2 <= x
                for j, (p2, n2, x2, q2) in enumerate(unique)
            ):
                kept.append((p, n, x, q))
        return kept

    start = frozenset({formula})
    index = {start: 0}
    states = [start]
    edges: list[list[tuple[int, int, int]]] = []
    i = 0
    while i < len(states):
        out: dict[tuple[int, int], int] = {}
        for pos, neg, nxt, post in expand(states[i]):
            letters = all_letters
            for b in range(len(propositions)):
                if pos >> b & 1:
                    letters &= with_bit[b]
                elif neg >> b & 1:
                    letters &= ~with_bit[b]
            if not letters:
                continue
            j = intern(nxt, index, states)
            key = (j, all_acc & ~post)
            out[key] = out.get(key, 0) | letters
        edges.append([(letters, j, acc) for (j, acc), letters in out.items()])
        i += 1
    return TGBA(len(propositions), states, edges, len(eventualities))
