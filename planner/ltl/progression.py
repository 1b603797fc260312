"""Formula progression (the "after" function) on positive Boolean combinations of formulas.

For an NNF formula ``f`` and a letter ``a``, ``af(f, a)`` is a formula with
``a w |= f  iff  w |= af(f, a)`` (Esparza, Křetínský & Sickert, "One theorem to rule them
all", LICS 2018, Def. 3; also Bacchus & Kabanza's progression):

    af(p, a) = true iff p in a        af(X f, a) = f
    af(F f, a) = af(f, a) | F f       af(G f, a) = af(f, a) & G f
    af(f U g, a) = af(g, a) | (af(f, a) & f U g)
    af(f R g, a) = af(g, a) & (af(f, a) | f R g)
    af(f W g, a) = af(g, a) | (af(f, a) & f W g)
    af(f M g, a) = af(g, a) & (af(f, a) | f M g)

Formulas are kept as minimal monotone DNFs over *atoms* (the subformulas whose top operator
is temporal or a literal): a DNF is a frozenset of terms, a term is a bitmask over atom
indices, and no term contains another. This normal form is canonical for propositional
equivalence over the atoms, so iterating ``af`` from a formula reaches finitely many DNFs.
A DNF equal to :data:`TT` is ``true``, one equal to :data:`FF` is ``false``.
"""

from __future__ import annotations

from planner.ltl.budget import tick
from planner.ltl.interning import intern
from planner.ltl.syntax import FALSE, TRUE, Formula

DNF = frozenset
TT: frozenset[int] = frozenset({0})
FF: frozenset[int] = frozenset()


def minimal(terms) -> frozenset[int]:
    """Drop every term that contains (as a bitmask superset) another term."""
    kept: list[int] = []
    for t in sorted(set(terms), key=int.bit_count):
        tick(1 + len(kept))
        if not any(k & t == k for k in kept):
            kept.append(t)
    return frozenset(kept)


def dnf_or(a: frozenset[int], b: frozenset[int]) -> frozenset[int]:
    if a == TT or b == TT:
        return TT
    if not a:
        return b
    if not b:
        return a
    return minimal(a | b)


def dnf_and(a: frozenset[int], b: frozenset[int]) -> frozenset[int]:
    if not a or not b:
        return FF
    if a == TT:
        return b
    if b == TT:
        return a
    return minimal(x | y for x in a for y in b)


class Progression:
    """Atoms, DNFs and the after-function for formulas over ``propositions``.

    Letters are bitmasks over ``propositions`` (bit ``i`` = ``propositions[i]`` true).
    """

    def __init__(self, propositions: tuple[str, ...]) -> None:
        self.propositions = propositions
        self._bit = {p: i for i, p in enumerate(propositions)}
        self.atoms: list[Formula] = []
        self._atom_index: dict[Formula, int] = {}
        self._dnf_cache: dict[Formula, frozenset[int]] = {}
        self._af_atom: dict[tuple[int, int], frozenset[int]] = {}
        self._af: dict[tuple[frozenset[int], int], frozenset[int]] = {}

    def atom(self, f: Formula) -> int:
        i = self._atom_index.get(f)
        if i is None:
            i = len(self.atoms)
            self.atoms.append(f)
            self._atom_index[f] = i
        return i

    def dnf(self, f: Formula) -> frozenset[int]:
        """The DNF of NNF formula ``f`` over its maximal non-Boolean subformulas."""
        cached = self._dnf_cache.get(f)
        if cached is not None:
            return cached
        if f is TRUE:
            out = TT
        elif f is FALSE:
            out = FF
        elif f.op == "&":
            out = TT
            for c in f.children:
                out = dnf_and(out, self.dnf(c))
        elif f.op == "|":
            out = FF
            for c in f.children:
                out = dnf_or(out, self.dnf(c))
        else:
            out = frozenset({1 << self.atom(f)})
        self._dnf_cache[f] = out
        return out

    def af_atom(self, index: int, letter: int) -> frozenset[int]:
        key = (index, letter)
        cached = self._af_atom.get(key)
        if cached is not None:
            return cached
        f = self.atoms[index]
        op = f.op
        if op == "ap":
            out = TT if letter >> self._bit[f.name] & 1 else FF
        elif op == "!":
            out = FF if letter >> self._bit[f.children[0].name] & 1 else TT
        elif op == "X":
            out = self.dnf(f.children[0])
        else:
            me = frozenset({1 << index})
            if op == "F":
                out = dnf_or(self.af_formula(f.children[0], letter), me)
            elif op == "G":
                out = dnf_and(self.af_formula(f.children[0], letter), me)
            else:
                left = self.af_formula(f.children[0], letter)
                right = self.af_formula(f.children[1], letter)
                if op in ("U", "W"):
                    out = dnf_or(right, dnf_and(left, me))
                else:  # R, M
                    out = dnf_and(right, dnf_or(left, me))
        self._af_atom[key] = out
        return out

    def af_formula(self, f: Formula, letter: int) -> frozenset[int]:
        return self.af(self.dnf(f), letter)

    def af(self, dnf: frozenset[int], letter: int) -> frozenset[int]:
        """``af`` of a DNF: substitute every atom by its progression."""
        key = (dnf, letter)
        cached = self._af.get(key)
        if cached is not None:
            return cached
        out = FF
        for term in dnf:
            acc = TT
            t = term
            while t and acc:
                low = t & -t
                acc = dnf_and(acc, self.af_atom(low.bit_length() - 1, letter))
                t ^= low
            out = dnf_or(out, acc)
            if out == TT:
                break
        self._af[key] = out
        return out

    def text(self, dnf: frozenset[int]) -> str:
        """Readable text of a DNF."""
        if dnf == TT:
            return "true"
        if not dnf:
            return "false"
        terms = []
        for term in sorted(dnf):
            parts = [str(self.atoms[i]) for i in range(term.bit_length()) if term >> i & 1]
            terms.append(" & ".join(parts) if len(parts) == 1 else "(" + " & ".join(parts) + ")")
        return " | ".join(terms)


def explore(
    prog: Progression, start: frozenset[int]
) -> tuple[list[frozenset[int]], list[list[int]]]:
    """All DNFs reachable from ``start`` by ``af``; returns (states, successor table)."""
    n_letters = 1 << len(prog.propositions)
    index = {start: 0}
    states = [start]
    table: list[list[int]] = []
    i = 0
    while i < len(states):
        row = []
        for letter in range(n_letters):
            nxt = prog.af(states[i], letter)
            j = intern(nxt, index, states)
            row.append(j)
        table.append(row)
        i += 1
    return states, table
