"""Determinisation of transition-based Büchi automata with compact Safra trees.

Safra's construction ("On the complexity of omega-automata", FOCS 1988) with Piterman's
compact naming ("From nondeterministic Büchi and Streett automata to deterministic parity
automata", LMCS 3(3), 2007), in the transition-based form of Schewe & Varghese ("Tight
bounds for the determinisation and complementation of generalised Büchi automata", ATVA
2012). A Safra tree is an ordered tree of nodes, each labelled with a non-empty set of NBA
states; children's labels are disjoint subsets of their parent's, and their union is a
proper subset of it. Nodes are named ``1..k`` in order of age (older = smaller). On letter
``a`` the successor tree is computed by:

1. every node's label ``L`` becomes ``delta(L, a)``, and the node gets a new youngest child
   labelled with the states reached from ``L`` through an *accepting* transition,
   ``delta_acc(L, a)``, if that set is non-empty;
2. horizontal merge: a state that occurs in a node is removed from every younger sibling and
   its descendants;
3. nodes with empty labels are removed;
4. vertical merge: a node whose label equals the union of its children's labels loses all
   its descendants and is *marked*;
5. the surviving nodes are renamed ``1..k'`` preserving their order.

With ``e`` the smallest name of an old node removed in the step and ``f`` the smallest name
of a marked node, the step has priority ``2e - 1`` if ``e < f``, ``2f`` if ``f < e`` and
``2n + 1`` if neither exists (``n`` NBA states); a run of the NBA's language is one whose
least priority seen infinitely often is even (some node is eventually never removed nor
renamed and is marked infinitely often).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from planner.ltl.interning import intern

Node = tuple  # (name: int, label: int bitmask over NBA states, children: tuple[Node, ...])


@dataclass
class SafraResult:
    """The deterministic automaton: ``table[s][a]``, state descriptions and Rabin pairs."""

    table: list[list[int]]
    names: Sequence[str]
    pairs: list[tuple[set[int], set[int]]]


def _text(tree: Node | None, marks: int) -> str:
    if tree is None:
        return "{}"

    def go(node: Node) -> str:
        name, label, children = node
        states = ",".join(str(q) for q in range(label.bit_length()) if label >> q & 1)
        flag = "!" if marks >> name & 1 else ""
        inner = "".join(go(c) for c in children)
        return f"{name}{flag}{{{states}}}" + (f"[{inner}]" if inner else "")

    return go(tree)


def determinise(
    n_letters: int, initial: int, succ: list[list[int]], succ_acc: list[list[int]]
) -> SafraResult:
    """Determinise a transition-based Büchi automaton to a state-based Rabin automaton.

    The priority of each step (see the module docstring) is stored in the successor state,
    so that the condition is state-based: for every even ``2i`` the Rabin pair ``(G, B)``
    has ``G`` the states entered with priority ``2i`` and ``B`` those entered with a smaller
    priority ("the least priority seen infinitely often is ``2i``").

    Args:
        n_letters: alphabet size.
        initial: initial NBA state.
        succ: ``succ[q][a]``, bitmask of all ``a``-successors of NBA state ``q``.
        succ_acc: ``succ_acc[q][a]``, bitmask of successors through accepting transitions.
    """
    delta_cache: dict[tuple[int, int], tuple[int, int]] = {}

    def delta(label: int, a: int) -> tuple[int, int]:
        key = (label, a)
        hit = delta_cache.get(key)
        if hit is not None:
            return hit
        out = out_acc = 0
        rest = label
        while rest:
            low = rest & -rest
            q = low.bit_length() - 1
            out |= succ[q][a]
            out_acc |= succ_acc[q][a]
            rest ^= low
        delta_cache[key] = (out, out_acc)
        return out, out_acc

    n_nba = max(len(succ), 1)
    top = 2 * n_nba + 1

    def count(node: Node) -> int:
        return 1 + sum(count(c) for c in node[2])

    def step(tree: Node | None, n_old: int, a: int) -> tuple[Node | None, int]:
        if tree is None:
            return None, top
        fresh = n_old

        def grow(node: Node) -> Node:
            nonlocal fresh
            name, label, children = node
            new_label, new_acc = delta(label, a)
            kids = [grow(c) for c in children]
            if new_acc:
                fresh += 1
                kids.append((fresh, new_acc, ()))
            return (name, new_label, tuple(kids))

        marked = top
        removed = top
        survivors: set[int] = set()

        def note_removed(node: Node) -> None:
            nonlocal removed
            survivors.discard(node[0])
            if node[0] <= n_old:
                removed = min(removed, node[0])
            for c in node[2]:
                note_removed(c)

        def prune(node: Node, forbidden: int) -> Node | None:
            nonlocal marked
            name, label, children = node
            label &= ~forbidden
            if not label:
                note_removed(node)
                return None
            kids = []
            covered = 0
            for c in children:
                r = prune(c, forbidden | covered)
                if r is not None:
                    kids.append(r)
                    covered |= r[1]
            if kids and covered == label:
                marked = min(marked, name)
                for k in kids:
                    note_removed(k)
                kids = []
            survivors.add(name)
            return (name, label, tuple(kids))

        result = prune(grow(tree), 0)
        if result is None:
            return None, 2 * removed - 1 if removed < top else top
        rank = {name: i + 1 for i, name in enumerate(sorted(survivors))}

        def rename(node: Node) -> Node:
            return (rank[node[0]], node[1], tuple(rename(c) for c in node[2]))

        if removed < marked:
            prio = 2 * removed - 1
        elif marked < removed:
            prio = 2 * marked
        else:
            prio = top
        return rename(result), prio

    start: tuple[Node | None, int] = ((1, 1 << initial, ()), top)
    index = {start: 0}
    states = [start]
    table: list[list[int]] = []
    i = 0
    rows_by_tree: dict[Node | None, list[int]] = {}  # successors depend on the tree only
    while i < len(states):
        tree = states[i][0]
        row = rows_by_tree.get(tree)
        if row is None:
            row = []
            n_old = count(tree) if tree is not None else 0
            for a in range(n_letters):
                nxt = step(tree, n_old, a)
                j = intern(nxt, index, states)
                row.append(j)
            rows_by_tree[tree] = row
        table.append(row)
        i += 1
    prios = [p for _, p in states]
    pairs = []
    for even in sorted({p for p in prios if p % 2 == 0}):
        good = {s for s, p in enumerate(prios) if p == even}
        bad = {s for s, p in enumerate(prios) if p < even}
        pairs.append((good, bad))
    return SafraResult(table, _Names(states), pairs)


class _Names(Sequence):
    """State names, rendered only for the states that survive reduction."""

    def __init__(self, states: list) -> None:
        self._states = states

    def __len__(self) -> int:
        return len(self._states)

    def __getitem__(self, i):
        tree, prio = self._states[i]
        return f"{_text(tree, 0)} p{prio}"
