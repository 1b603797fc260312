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

import itertools
from collections.abc import Iterator, Sequence
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


class _Successors:
    """The NBA's successors of a set of states: ``delta(L, a)`` and ``delta_acc(L, a)``,
    bitmasks over NBA states, cached per ``(L, a)``."""

    def __init__(self, succ: list[list[int]], succ_acc: list[list[int]]) -> None:
        self.succ, self.succ_acc = succ, succ_acc
        self.cache: dict[tuple[int, int], tuple[int, int]] = {}

    def __call__(self, label: int, a: int) -> tuple[int, int]:
        key = (label, a)
        hit = self.cache.get(key)
        if hit is not None:
            return hit
        out = out_acc = 0
        rest = label
        while rest:
            low = rest & -rest
            q = low.bit_length() - 1
            out |= self.succ[q][a]
            out_acc |= self.succ_acc[q][a]
            rest ^= low
        self.cache[key] = (out, out_acc)
        return out, out_acc


def _count(node: Node) -> int:
    return 1 + sum(_count(c) for c in node[2])


def _grow(node: Node, a: int, delta: _Successors, fresh: Iterator[int]) -> Node:
    """Step 1: every label ``L`` becomes ``delta(L, a)``; a node reaching states through
    accepting transitions gets a new youngest child (named from ``fresh``) holding them."""
    name, label, children = node
    new_label, new_acc = delta(label, a)
    kids = [_grow(c, a, delta, fresh) for c in children]
    if new_acc:
        kids.append((next(fresh), new_acc, ()))
    return (name, new_label, tuple(kids))


class _Merge:
    """Steps 2-4 on a grown tree: horizontal merge, removal of empty nodes, vertical merge;
    records the smallest old name removed (``removed``) and marked (``marked``)."""

    def __init__(self, n_old: int, top: int) -> None:
        self.n_old = n_old
        self.marked = top
        self.removed = top
        self.survivors: set[int] = set()

    def _note_removed(self, node: Node) -> None:
        self.survivors.discard(node[0])
        if node[0] <= self.n_old:
            self.removed = min(self.removed, node[0])
        for c in node[2]:
            self._note_removed(c)

    def prune(self, node: Node, forbidden: int) -> Node | None:
        """``node`` without the states in ``forbidden`` (those of the older siblings of the
        node and of its ancestors); ``None`` if its label becomes empty."""
        name, label, children = node
        label &= ~forbidden
        if not label:
            self._note_removed(node)
            return None
        kids = []
        covered = 0
        for c in children:
            r = self.prune(c, forbidden | covered)
            if r is not None:
                kids.append(r)
                covered |= r[1]
        if kids and covered == label:
            self.marked = min(self.marked, name)
            for k in kids:
                self._note_removed(k)
            kids = []
        self.survivors.add(name)
        return (name, label, tuple(kids))


def _rename(node: Node, rank: dict[int, int]) -> Node:
    """Step 5: the names ``rank[name]``."""
    return (rank[node[0]], node[1], tuple(_rename(c, rank) for c in node[2]))


def _step(
    tree: Node | None, n_old: int, a: int, delta: _Successors, top: int
) -> tuple[Node | None, int]:
    """The successor of ``tree`` (``n_old`` nodes) on letter ``a`` and the step's priority
    (module docstring; ``top`` = ``2n + 1``)."""
    if tree is None:
        return None, top
    merge = _Merge(n_old, top)
    result = merge.prune(_grow(tree, a, delta, itertools.count(n_old + 1)), 0)
    removed, marked = merge.removed, merge.marked
    if result is None:
        return None, 2 * removed - 1 if removed < top else top
    rank = {name: i + 1 for i, name in enumerate(sorted(merge.survivors))}
    if removed < marked:
        prio = 2 * removed - 1
    elif marked < removed:
        prio = 2 * marked
    else:
        prio = top
    return _rename(result, rank), prio


def _parity_pairs(prios: list[int]) -> list[tuple[set[int], set[int]]]:
    """For every even priority ``2i`` present, the Rabin pair ``(G, B)``: ``G`` the states
    entered with priority ``2i``, ``B`` those entered with a smaller one."""
    pairs = []
    for even in sorted({p for p in prios if p % 2 == 0}):
        good = {s for s, p in enumerate(prios) if p == even}
        bad = {s for s, p in enumerate(prios) if p < even}
        pairs.append((good, bad))
    return pairs


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
    delta = _Successors(succ, succ_acc)
    top = 2 * max(len(succ), 1) + 1
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
            n_old = _count(tree) if tree is not None else 0
            for a in range(n_letters):
                nxt = _step(tree, n_old, a, delta, top)
                j = intern(nxt, index, states)
                row.append(j)
            rows_by_tree[tree] = row
        table.append(row)
        i += 1
    return SafraResult(table, _Names(states), _parity_pairs([p for _, p in states]))


class _Names(Sequence):
    """State names, rendered only for the states that survive reduction."""

    def __init__(self, states: list) -> None:
        self._states = states

    def __len__(self) -> int:
        return len(self._states)

    def __getitem__(self, i):
        tree, prio = self._states[i]
        return f"{_text(tree, 0)} p{prio}"
