"""Abstract syntax of LTL formulas.

A :class:`Formula` is an immutable, *interned* tree node: two structurally equal formulas are
the same Python object, so equality is identity and hashing is O(1). Hashing is by identity,
so the iteration order of a set of formulas depends on memory addresses and differs from
process to process; wherever that order can reach a result, iterate in :meth:`Formula.sort_key`
order, a structural total order. Build formulas with the
constructor functions of this module (:func:`ap`, :func:`land`, :func:`until`, ...) or with
:func:`planner.ltl.parser.parse`.

Semantics over an infinite word ``w = w_0 w_1 ...`` of letters (sets of true propositions),
with ``w^i`` the suffix from position ``i``:

* ``X f``: ``w^1 |= f``; ``F f``: some ``i`` with ``w^i |= f``; ``G f``: every ``i``.
* ``f U g``: some ``i`` with ``w^i |= g`` and ``w^j |= f`` for all ``j < i``.
* ``f R g`` (release): ``g`` holds up to and including the first position where ``f``
  holds, or forever; ``f R g = !(!f U !g)``.
* ``f W g`` (weak until): ``f U g`` or ``G f``.
* ``f M g`` (strong release): ``f R g`` and ``F f``.
"""

from __future__ import annotations

from collections.abc import Iterator

#: Operator tags. Leaves: ``true``, ``false``, ``ap``. Unary: ``!``, ``X``, ``F``, ``G``.
#: Binary: ``->``, ``<->``, ``xor``, ``U``, ``R``, ``W``, ``M``. N-ary: ``&``, ``|``.
LEAVES = frozenset({"true", "false", "ap"})
UNARY = frozenset({"!", "X", "F", "G"})
BINARY = frozenset({"->", "<->", "xor", "U", "R", "W", "M"})
NARY = frozenset({"&", "|"})
TEMPORAL = frozenset({"X", "F", "G", "U", "R", "W", "M"})

_INTERN: dict[tuple, Formula] = {}


class Formula:
    """An interned LTL formula node.

    Attributes:
        op: the operator tag (see :data:`LEAVES`, :data:`UNARY`, :data:`BINARY`,
            :data:`NARY`).
        children: the operands (empty for leaves; two or more for ``&``/``|``).
        name: the proposition name for ``op == "ap"``, else ``None``.
        size: the number of nodes of the tree.
        depth: the temporal/boolean nesting depth (leaves have depth 0).
    """

    __slots__ = ("__weakref__", "_key", "_props", "children", "depth", "name", "op", "size")

    op: str
    children: tuple[Formula, ...]
    name: str | None
    size: int
    depth: int

    def __new__(cls, op: str, children: tuple[Formula, ...] = (), name: str | None = None):
        key = (op, children, name)
        node = _INTERN.get(key)
        if node is not None:
            return node
        node = object.__new__(cls)
        object.__setattr__(node, "op", op)
        object.__setattr__(node, "children", children)
        object.__setattr__(node, "name", name)
        object.__setattr__(node, "size", 1 + sum(c.size for c in children))
        object.__setattr__(node, "depth", 1 + max((c.depth for c in children), default=-1))
        object.__setattr__(node, "_props", None)
        sort_key = (node.size, op, name or "", tuple(c._key for c in children))
        object.__setattr__(node, "_key", sort_key)
        _INTERN[key] = node
        return node

    def __setattr__(self, key, value):
        raise AttributeError("Formula is immutable")

    def __reduce__(self):
        return (Formula, (self.op, self.children, self.name))

    def propositions(self) -> frozenset[str]:
        """The atomic propositions occurring in the formula."""
        if self._props is None:
            if self.op == "ap":
                props = frozenset((self.name,))
            else:
                props = frozenset().union(*(c.propositions() for c in self.children))
            object.__setattr__(self, "_props", props)
        return self._props

    def subformulas(self) -> Iterator[Formula]:
        """All distinct subformulas, children before parents (post-order)."""
        seen: set[int] = set()
        stack: list[tuple[Formula, bool]] = [(self, False)]
        while stack:
            node, expanded = stack.pop()
            if id(node) in seen:
                continue
            if expanded:
                seen.add(id(node))
                yield node
            else:
                stack.append((node, True))
                stack.extend((c, False) for c in reversed(node.children))

    def __str__(self) -> str:
        return to_string(self)

    def __repr__(self) -> str:
        return f"Formula({to_string(self)!r})"

    def sort_key(self) -> tuple:
        """``(size, op, name, children's keys)``: a structural key, so distinct formulas have
        distinct keys and the order does not depend on the process (it sorts the operands of
        ``&``/``|`` and the formulas of a tableau state). Computed once, at creation; equal
        subtrees share their key, so comparing two keys stops at the first difference."""
        return self._key


TRUE = Formula("true")
FALSE = Formula("false")


def ap(name: str) -> Formula:
    """The atomic proposition ``name``."""
    return Formula("ap", (), str(name))


def lnot(f: Formula) -> Formula:
    return Formula("!", (f,))


def land(*fs: Formula) -> Formula:
    if len(fs) == 1:
        return fs[0]
    if not fs:
        return TRUE
    return Formula("&", tuple(fs))


def lor(*fs: Formula) -> Formula:
    if len(fs) == 1:
        return fs[0]
    if not fs:
        return FALSE
    return Formula("|", tuple(fs))


def implies(f: Formula, g: Formula) -> Formula:
    return Formula("->", (f, g))


def equiv(f: Formula, g: Formula) -> Formula:
    return Formula("<->", (f, g))


def xor(f: Formula, g: Formula) -> Formula:
    return Formula("xor", (f, g))


def nxt(f: Formula) -> Formula:
    return Formula("X", (f,))


def eventually(f: Formula) -> Formula:
    return Formula("F", (f,))


def always(f: Formula) -> Formula:
    return Formula("G", (f,))


def until(f: Formula, g: Formula) -> Formula:
    return Formula("U", (f, g))


def release(f: Formula, g: Formula) -> Formula:
    return Formula("R", (f, g))


def weak_until(f: Formula, g: Formula) -> Formula:
    return Formula("W", (f, g))


def strong_release(f: Formula, g: Formula) -> Formula:
    return Formula("M", (f, g))


_SIMPLE_NAME = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_")
_KEYWORDS = frozenset({"X", "F", "G", "U", "R", "W", "M", "V", "xor", "true", "false"})


def _name(name: str) -> str:
    if (
        name
        and name not in _KEYWORDS
        and not name[0].isdigit()
        and all(ch in _SIMPLE_NAME for ch in name)
    ):
        return name
    return '"' + name + '"'


def to_string(f: Formula) -> str:
    """Spot-compatible text of ``f``, fully parenthesised below the top level."""

    def go(g: Formula, top: bool) -> str:
        op = g.op
        if op == "true":
            return "true"
        if op == "false":
            return "false"
        if op == "ap":
            return _name(g.name or "")
        if op in UNARY:
            return f"{op}{'' if op == '!' else ' '}{go(g.children[0], False)}"
        sep = f" {op} "
        text = sep.join(go(c, False) for c in g.children)
        return text if top else f"({text})"

    return go(f, True)
