"""Negation normal form and rewrite-based simplification of LTL formulas.

:func:`simplify` returns an equivalent formula in negation normal form (NNF): negation only on
atomic propositions, no ``->``/``<->``/``xor``, ``&``/``|`` flattened, deduplicated and
sorted. Negations are pushed with the dualities ``!X f = X !f``, ``!F f = G !f``,
``!(f U g) = !f R !g``, ``!(f W g) = !f M !g``. The rewrite rules (each an LTL equivalence,
see e.g. Somenzi & Bloem, "Efficient Büchi automata from LTL formulae", CAV 2000, and Etessami
& Holzmann, CONCUR 2000) are applied bottom-up by the smart constructors:

* constants: ``f & true = f``, ``f & false = false``, ``p & !p = false`` (duals for ``|``),
  ``X true = true``, ``F false = false``, ``true U g = F g``, ``false R g = G g``,
  ``f W false = G f``, ``f M true = F f``, ``f U false = false``, ``false M g = false``, ...
* idempotence: ``F F f = F f``, ``G G f = G f``, ``f U f = f``, ``F G F f = G F f``,
  ``G F G f = F G f``;
* absorption: ``F(f U g) = F g``, ``F(f M g) = F(f & g)``, ``G(f R g) = G g``,
  ``G(f W g) = G(f | g)``;
* suffix-invariant ``s`` (``G F g``, ``F G g``, and ``& | X F G`` of such): ``X s = F s =
  G s = s``, ``f U s = f R s = s``, ``s U g = g | (s & F g)``, ``s R g = G g | (s & g)``,
  ``s W g = s | g``, ``s M g = s & g``, ``f W s = s | G f``, ``f M s = s & F f``;
* ``f R G g = G g``, ``f M G g = G g & F f``, ``F X f = X F f``, ``G X f = X G f``,
  ``F(f W g) = F G f | F g``, ``F(f R g) = F G g | F(f & g)``, ``G(f U g) = G(f | g) &
  G F g``, ``G(f M g) = G g & G F f``;
* propositional subformulas (no temporal operator, at most 6 propositions) are replaced
  by a prime-implicant cover of their truth table when that is smaller;
* distribution: ``X f & X g = X(f & g)``, ``G f & G g = G(f & g)``, ``X f | X g =
  X(f | g)``, ``F f | F g = F(f | g)``.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

from planner.ltl.boolean import cover
from planner.ltl.syntax import FALSE, TEMPORAL, TRUE, Formula, ap

COSAFE_OPS = frozenset({"true", "false", "ap", "!", "&", "|", "X", "F", "U", "M"})
SAFE_OPS = frozenset({"true", "false", "ap", "!", "&", "|", "X", "G", "R", "W"})


def _neg_literal(f: Formula) -> Formula | None:
    if f.op == "ap":
        return Formula("!", (f,))
    if f.op == "!":
        return f.children[0]
    return None


def _flat(op: str, args) -> list[Formula]:
    out: list[Formula] = []
    for a in args:
        if a.op == op:
            out.extend(a.children)
        else:
            out.append(a)
    return out


def _finish(op: str, items: set[Formula], unit: Formula) -> Formula:
    if not items:
        return unit
    if len(items) == 1:
        return next(iter(items))
    return Formula(op, tuple(sorted(items, key=Formula.sort_key)))


def _mk_junction(
    op: str,
    args: tuple[Formula, ...],
    unit: Formula,
    absorbing: Formula,
    temporal: str,
    mk_temporal: Callable[[Formula], Formula],
) -> Formula:
    """``&`` (unit true, absorbing false, ``X a & X b = X(a & b)``, ``G a & G b = G(a & b)``)
    or, dually, ``|`` (unit false, absorbing true, X and F distribute)."""
    mk = mk_and if op == "&" else mk_or
    items: set[Formula] = set()
    xs: list[Formula] = []
    ts: list[Formula] = []
    for a in _flat(op, args):
        if a is absorbing:
            return absorbing
        if a is unit:
            continue
        if a.op == "X":
            xs.append(a.children[0])
        elif a.op == temporal:
            ts.append(a.children[0])
        else:
            items.add(a)
    if len(xs) > 1:
        items.add(mk_X(mk(*xs)))
    elif xs:
        items.add(Formula("X", (xs[0],)))
    if len(ts) > 1:
        items.add(mk_temporal(mk(*ts)))
    elif ts:
        items.add(Formula(temporal, (ts[0],)))
    if absorbing in items:
        return absorbing
    items.discard(unit)
    for a in items:
        n = _neg_literal(a)
        if n is not None and n in items:
            return absorbing
    if len(items) > 1 and any(a.op == op for a in items):
        return mk(*sorted(items, key=Formula.sort_key))
    return _finish(op, items, unit)


def mk_and(*args: Formula) -> Formula:
    return _mk_junction("&", args, TRUE, FALSE, "G", mk_G)


def mk_or(*args: Formula) -> Formula:
    return _mk_junction("|", args, FALSE, TRUE, "F", mk_F)


def suffix_invariant(f: Formula) -> bool:
    """Syntactic prefix independence: ``w |= f`` iff ``w^1 |= f`` (``G F g``, ``F G g`` and
    ``&``, ``|``, ``X``, ``F``, ``G`` of such formulas, and the constants)."""
    op = f.op
    if op in ("true", "false"):
        return True
    if op in ("F", "G"):
        c = f.children[0]
        return c.op == ("G" if op == "F" else "F") or suffix_invariant(c)
    if op in ("&", "|", "X"):
        return all(suffix_invariant(c) for c in f.children)
    return False


def mk_X(f: Formula) -> Formula:
    if suffix_invariant(f):
        return f
    return Formula("X", (f,))


def mk_F(f: Formula) -> Formula:
    if f.op == "F" or suffix_invariant(f):
        return f
    if f.op == "X":
        return mk_X(mk_F(f.children[0]))
    if f.op == "W":
        return mk_or(mk_F(mk_G(f.children[0])), mk_F(f.children[1]))
    if f.op == "R":
        return mk_or(mk_F(mk_G(f.children[1])), mk_F(mk_and(*f.children)))
    if f.op == "U":
        return mk_F(f.children[1])
    if f.op == "M":
        return mk_F(mk_and(*f.children))
    if f.op == "G" and f.children[0].op == "F":
        return f
    return Formula("F", (f,))


def mk_G(f: Formula) -> Formula:
    if f.op == "G" or suffix_invariant(f):
        return f
    if f.op == "X":
        return mk_X(mk_G(f.children[0]))
    if f.op == "U":
        return mk_and(mk_G(mk_or(*f.children)), mk_G(mk_F(f.children[1])))
    if f.op == "M":
        return mk_and(mk_G(f.children[1]), mk_G(mk_F(f.children[0])))
    if f.op == "R":
        return mk_G(f.children[1])
    if f.op == "W":
        return mk_G(mk_or(*f.children))
    if f.op == "F" and f.children[0].op == "G":
        return f
    return Formula("G", (f,))


def mk_U(f: Formula, g: Formula) -> Formula:
    if g is TRUE or g is FALSE or f is FALSE or f is g or suffix_invariant(g):
        return g
    if suffix_invariant(f):
        return mk_or(g, mk_and(f, mk_F(g)))
    if f is TRUE:
        return mk_F(g)
    return Formula("U", (f, g))


def mk_R(f: Formula, g: Formula) -> Formula:
    if g is TRUE or g is FALSE or f is TRUE or f is g or g.op == "G" or suffix_invariant(g):
        return g
    if suffix_invariant(f):
        return mk_or(mk_G(g), mk_and(f, g))
    if f is FALSE:
        return mk_G(g)
    return Formula("R", (f, g))


def mk_W(f: Formula, g: Formula) -> Formula:
    if g is TRUE or f is TRUE:
        return TRUE
    if g is FALSE:
        return mk_G(f)
    if f is FALSE or f is g:
        return g
    if suffix_invariant(f):
        return mk_or(f, g)
    if suffix_invariant(g):
        return mk_or(g, mk_G(f))
    return Formula("W", (f, g))


def mk_M(f: Formula, g: Formula) -> Formula:
    if g is FALSE or f is FALSE:
        return FALSE
    if g is TRUE:
        return mk_F(f)
    if f is TRUE or f is g:
        return g
    if suffix_invariant(f):
        return mk_and(f, g)
    if suffix_invariant(g) or g.op == "G":
        return mk_and(g, mk_F(f))
    return Formula("M", (f, g))


@lru_cache(maxsize=200_000)
def _nnf(f: Formula, neg: bool) -> Formula:
    op = f.op
    if op == "true":
        return FALSE if neg else TRUE
    if op == "false":
        return TRUE if neg else FALSE
    if op == "ap":
        return Formula("!", (f,)) if neg else f
    if op == "!":
        return _nnf(f.children[0], not neg)
    if op in ("&", "|"):
        parts = [_nnf(c, neg) for c in f.children]
        return mk_or(*parts) if (op == "&") == neg else mk_and(*parts)
    if op == "->":
        a, b = f.children
        return (
            mk_and(_nnf(a, False), _nnf(b, True)) if neg else mk_or(_nnf(a, True), _nnf(b, False))
        )
    if op in ("<->", "xor"):
        a, b = f.children
        same = (op == "<->") != neg
        if same:
            return mk_or(
                mk_and(_nnf(a, False), _nnf(b, False)), mk_and(_nnf(a, True), _nnf(b, True))
            )
        return mk_or(mk_and(_nnf(a, False), _nnf(b, True)), mk_and(_nnf(a, True), _nnf(b, False)))
    if op == "X":
        return mk_X(_nnf(f.children[0], neg))
    if op == "F":
        return mk_G(_nnf(f.children[0], True)) if neg else mk_F(_nnf(f.children[0], False))
    if op == "G":
        return mk_F(_nnf(f.children[0], True)) if neg else mk_G(_nnf(f.children[0], False))
    a, b = (_nnf(c, neg) for c in f.children)
    if op == "U":
        return mk_R(a, b) if neg else mk_U(a, b)
    if op == "R":
        return mk_U(a, b) if neg else mk_R(a, b)
    if op == "W":
        return mk_M(a, b) if neg else mk_W(a, b)
    if op == "M":
        return mk_W(a, b) if neg else mk_M(a, b)
    raise ValueError(f"unknown operator {op!r}")


def _truth(f: Formula, bits: dict[str, int], full: int) -> int:
    """Set of letters (bitmask over letters) on which propositional NNF ``f`` holds."""
    op = f.op
    if op == "true":
        return full
    if op == "false":
        return 0
    if op == "ap":
        return bits[f.name]
    if op == "!":
        return full & ~bits[f.children[0].name]
    vals = [_truth(c, bits, full) for c in f.children]
    out = full if op == "&" else 0
    for v in vals:
        out = out & v if op == "&" else out | v
    return out


@lru_cache(maxsize=100_000)
def _boolmin(f: Formula) -> Formula:
    """Replace maximal propositional subformulas by a minimal-ish DNF when that is smaller."""
    if f.op in ("true", "false", "ap", "!"):
        return f
    if all(g.op not in TEMPORAL for g in f.subformulas()):
        props = sorted(f.propositions())
        if len(props) <= 6:
            n_letters = 1 << len(props)
            bits = {
                p: sum(1 << x for x in range(n_letters) if x >> i & 1) for i, p in enumerate(props)
            }
            table = _truth(f, bits, (1 << n_letters) - 1)
            letters = [x for x in range(n_letters) if table >> x & 1]
            terms = []
            for care, value in cover(letters, len(props)):
                lits = [
                    ap(p) if value >> i & 1 else Formula("!", (ap(p),))
                    for i, p in enumerate(props)
                    if care >> i & 1
                ]
                terms.append(mk_and(*lits))
            g = mk_or(*terms)
            return g if g.size < f.size else f
        return f
    kids = tuple(_boolmin(c) for c in f.children)
    if kids == f.children:
        return f
    return _rebuild(f.op, kids)


def _rebuild(op: str, kids: tuple[Formula, ...]) -> Formula:
    if op == "&":
        return mk_and(*kids)
    if op == "|":
        return mk_or(*kids)
    if op == "X":
        return mk_X(kids[0])
    if op == "F":
        return mk_F(kids[0])
    if op == "G":
        return mk_G(kids[0])
    return {"U": mk_U, "R": mk_R, "W": mk_W, "M": mk_M}[op](*kids)


def simplify(f: Formula) -> Formula:
    """An equivalent, simplified formula in negation normal form."""
    return _boolmin(_nnf(f, False))


def negate(f: Formula) -> Formula:
    """The simplified NNF of ``!f``."""
    return _boolmin(_nnf(f, True))


def is_cosafe(f: Formula) -> bool:
    """Whether NNF ``f`` is syntactically co-safe (only X, F, U, M as temporal operators)."""
    return all(g.op in COSAFE_OPS for g in f.subformulas())


def is_safe(f: Formula) -> bool:
    """Whether NNF ``f`` is syntactically safe (only X, G, R, W as temporal operators)."""
    return all(g.op in SAFE_OPS for g in f.subformulas())
