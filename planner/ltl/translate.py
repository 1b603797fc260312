r"""Translation of LTL formulas to complete deterministic state-based Rabin automata.

Pipeline (:func:`translate`):

1. :func:`planner.ltl.simplify.simplify`: negation normal form and rewrite rules.
2. Fast paths, by the shape of the simplified formula ``g`` (each exact):

   * ``g`` *syntactically co-safe* (temporal operators ``X F U M`` only) or *safe* (``X G R
     W`` only): the DFA whose states are the formulas reached by progression
     (:mod:`planner.ltl.progression`; Esparza, Křetínský & Sickert, LICS 2018), minimised.
     A co-safe formula holds iff progression reaches ``true`` (pair ``({true}, {})``), a
     safe one iff it never reaches ``false`` (pair ``(S \ {false}, {false})``).
     ``!Haz U Goal`` gives 3 states.
   * ``g = g_1 & ... & g_k`` or ``g_1 | ... | g_k`` (also ``G(g_1 & ..)``, ``F(g_1 | ..)``):
     the co-safe operands, and the safe ones, are grouped into one formula each; the
     operands are translated recursively and combined by synchronous products
     (:mod:`planner.ltl.compose`).
   * ``g = X h``: the automaton of ``h`` behind a fresh initial state.
   * ``G F h`` / ``F G h`` with ``F h`` co-safe / ``G h`` safe: restart monitors (a
     deterministic Büchi / co-Büchi automaton).
   * ``G h`` with ``h`` co-safe / ``F h`` with ``h`` safe: breakpoint construction on
     progressed formulas (Miyano & Hayashi 1984), a deterministic Büchi / co-Büchi automaton.

3. Every other formula: tableau to a transition-based generalised Büchi automaton
   (Gerth, Peled, Vardi & Wolper 1995; Couvreur 1999; :mod:`planner.ltl.tableau`),
   SCC-aware counter degeneralisation to a transition-based Büchi automaton, removal of NBA
   states with an empty language, then Safra's determinisation with Piterman's compact
   trees to a parity condition made state-based Rabin (:mod:`planner.ltl.safra`).
4. After every construction, :func:`planner.ltl.reduce.reduce_rabin`: reachable part,
   SCC-local acceptance clean-up, merge of empty-language states, bisimulation quotient,
   pair clean-up.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from planner.automaton import RabinAutomaton, RabinPair
from planner.errors import AutomatonError, LTLSyntaxError
from planner.ltl.budget import TranslationLimits, count_state, limited, set_letters, tick
from planner.ltl.compose import delay, product
from planner.ltl.interning import intern
from planner.ltl.parser import MAX_DEPTH, is_plain_name, parse
from planner.ltl.progression import FF, TT, Progression, dnf_and, explore
from planner.ltl.reduce import reduce_rabin
from planner.ltl.safra import determinise
from planner.ltl.simplify import is_cosafe, is_safe, mk_and, mk_F, mk_G, mk_or, negate, simplify
from planner.ltl.syntax import Formula
from planner.ltl.tableau import build_tgba


def _alphabet(formula: Formula, propositions: Sequence[str] | None) -> tuple[str, ...]:
    used = formula.propositions()
    if propositions is None:
        return tuple(sorted(used))
    props = tuple(propositions)
    for p in props:
        if not isinstance(p, str) or not (is_plain_name(p) or p in used):
            raise AutomatonError(
                f"proposition name {p!r} is not a plain name (a letter or _, then letters, "
                "digits or _; not an operator such as U, X, GF, true)"
            )
    if len(set(props)) != len(props):
        raise AutomatonError(f"duplicate propositions in {props}")
    missing = sorted(used - set(props))
    if missing:
        raise AutomatonError(
            f"the formula uses proposition {missing[0]!r}, which is not in the given "
            f"alphabet {props}"
        )
    return props


def _progression_dfa(f: Formula, props: tuple[str, ...], cosafe: bool):
    prog = Progression(props)
    states, table = explore(prog, prog.dnf(f))
    tt = np.array([s == TT for s in states])
    ff = np.array([s == FF for s in states])
    pairs = [(tt, np.zeros_like(tt))] if cosafe else [(~ff, ff)]
    return np.array(table, dtype=np.int64), 0, pairs, [prog.text(s) for s in states]


def _safra(f: Formula, props: tuple[str, ...]):
    tgba = build_tgba(f, props)
    n_letters = 1 << len(props)
    k = tgba.n_acc
    # SCC-aware degeneralisation: inside each SCC of the TGBA the round-robin counter only
    # visits the acceptance sets that some inner edge misses; edges between SCCs reset it.
    n_q = len(tgba.states)
    src = [q for q, edges in enumerate(tgba.edges) for _ in edges]
    dst = [t for edges in tgba.edges for _, t, _ in edges]
    graph = csr_matrix(
        (
            np.ones(len(src), dtype=np.int8),
            (np.array(src, dtype=np.int64), np.array(dst, dtype=np.int64)),
        ),
        shape=(n_q, n_q),
    )
    _, scc = connected_components(graph, directed=True, connection="strong")
    scc = scc.tolist()
    inner_all = {}
    for q, edges in enumerate(tgba.edges):
        for _, t, acc in edges:
            if scc[q] == scc[t]:
                inner_all[scc[q]] = inner_all.get(scc[q], (1 << k) - 1) & acc
    relevant = {c: [j for j in range(k) if not m >> j & 1] for c, m in inner_all.items()}
    offset = []
    n = 0
    for q in range(n_q):
        offset.append(n)
        n += max(1, len(relevant.get(scc[q], [])))
    count_state(n, n_letters)  # before the tables are allocated
    succ = [[0] * n_letters for _ in range(n)]
    succ_acc = [[0] * n_letters for _ in range(n)]
    for q, edges in enumerate(tgba.edges):
        rel = relevant.get(scc[q], [])
        for lvl in range(max(1, len(rel))):
            row, row_acc = succ[offset[q] + lvl], succ_acc[offset[q] + lvl]
            for letters, target, acc in edges:
                tick()
                if scc[target] != scc[q]:
                    j, accepting = 0, False
                else:
                    j = lvl
                    while j < len(rel) and acc >> rel[j] & 1:
                        j += 1
                    accepting = j >= len(rel)
                    if accepting:
                        j = 0
                bit = 1 << (offset[target] + j)
                rest = letters
                while rest:
                    low = rest & -rest
                    a = low.bit_length() - 1
                    row[a] |= bit
                    if accepting:
                        row_acc[a] |= bit
                    rest ^= low
    # Keep only states from which an accepting cycle is reachable.
    useful = _nonempty_states(succ, succ_acc, n, n_letters)
    mask = sum(1 << q for q in range(n) if useful[q])
    succ = [[m & mask for m in row] for row in succ]
    succ_acc = [[m & mask for m in row] for row in succ_acc]
    res = determinise(n_letters, 0, succ, succ_acc)
    size = len(res.table)
    pairs = []
    for good, bad in res.pairs:
        g = np.zeros(size, dtype=bool)
        b = np.zeros(size, dtype=bool)
        g[list(good)] = True
        b[list(bad)] = True
        pairs.append((g, b))
    return np.array(res.table, dtype=np.int64), 0, pairs, res.names


def _nonempty_states(succ, succ_acc, n: int, n_letters: int) -> np.ndarray:
    src, dst, acc_src, acc_dst = [], [], [], []
    for q in range(n):
        tick(n_letters)
        for a in range(n_letters):
            m, ma = succ[q][a], succ_acc[q][a]
            while m:
                low = m & -m
                t = low.bit_length() - 1
                src.append(q)
                dst.append(t)
                if ma & low:
                    acc_src.append(q)
                    acc_dst.append(t)
                m ^= low
    src_a, dst_a = np.array(src, dtype=np.int64), np.array(dst, dtype=np.int64)
    graph = csr_matrix((np.ones(src_a.size, dtype=np.int8), (src_a, dst_a)), shape=(n, n))
    _, labels = connected_components(graph, directed=True, connection="strong")
    a_src, a_dst = np.array(acc_src, dtype=np.int64), np.array(acc_dst, dtype=np.int64)
    good_scc = np.zeros(labels.max() + 1, dtype=bool)
    same = labels[a_src] == labels[a_dst]
    good_scc[labels[a_src[same]]] = True
    reached = good_scc[labels]
    while True:
        new = reached.copy()
        new[src_a[reached[dst_a]]] = True
        if new.sum() == reached.sum():
            return reached
        reached = new


def _monitor(f: Formula, props: tuple[str, ...], recurrence: bool):
    """Restart monitors: ``G F h`` (``F h`` co-safe) as a deterministic Büchi automaton and
    ``F G h`` (``G h`` safe) as a deterministic co-Büchi automaton.

    The monitor progresses ``m = F h`` (resp. ``G h``); when the progression reaches
    ``true`` (resp. ``false``) it restarts from ``m`` in a state flagged good (resp. bad).
    ``G F h`` holds iff ``F h`` is discharged infinitely often; ``F G h`` iff ``G h`` fails
    finitely often.
    """
    prog = Progression(props)
    start_dnf = prog.dnf(f)
    done = TT if recurrence else FF
    start = (start_dnf, False)
    index = {start: 0}
    keys = [start]
    rows = []
    i = 0
    while i < len(keys):
        row = []
        for a in range(1 << len(props)):
            nxt = prog.af(keys[i][0], a)
            key = (start_dnf, True) if nxt == done else (nxt, False)
            j = intern(key, index, keys)
            row.append(j)
        rows.append(row)
        i += 1
    flag = np.array([k[1] for k in keys])
    pair = (flag, np.zeros_like(flag)) if recurrence else (np.ones_like(flag), flag)
    names = [prog.text(d) + (" !" if fl else "") for d, fl in keys]
    return np.array(rows, dtype=np.int64), 0, [pair], names


def _breakpoint(psi: Formula, props: tuple[str, ...], complement: bool):
    """``G psi`` for co-safe ``psi`` as a deterministic Büchi automaton (or, with
    ``complement``, its complement ``F !psi`` as a deterministic co-Büchi automaton).

    Breakpoint construction (Miyano & Hayashi, TCS 32, 1984) on progressed formulas: a state
    ``(X, Y)`` holds ``X``, the conjunction of the obligations ``psi`` started since the
    previous breakpoint and before the current batch, progressed so far, and ``Y``, those
    of the current batch. Reading ``a``: ``X' = af(X, a)``, ``Y' = af(Y, a) & psi``. If
    either becomes ``false`` an obligation failed (rejecting sink). If ``X'`` is ``true``,
    the batch is discharged: the next state is ``(Y', true)`` and is flagged. Each batch is
    finite and every co-safe obligation that holds is discharged after finitely many
    letters, so ``G psi`` holds iff flagged states recur.
    """
    prog = Progression(props)
    d_psi = prog.dnf(psi)
    start = (d_psi, TT, False)
    sink = (FF, FF, False)
    index = {start: 0}
    keys = [start]
    rows = []
    i = 0
    while i < len(keys):
        x, y, _ = keys[i]
        row = []
        for a in range(1 << len(props)):
            if x == FF:
                key = sink
            else:
                x1 = prog.af(x, a)
                y1 = dnf_and(prog.af(y, a), d_psi)
                if x1 == FF or y1 == FF:
                    key = sink
                elif x1 == TT:
                    key = (y1, TT, True)
                else:
                    key = (x1, y1, False)
            j = intern(key, index, keys)
            row.append(j)
        rows.append(row)
        i += 1
    flag = np.array([k[2] for k in keys])
    pair = (np.ones_like(flag), flag) if complement else (flag, np.zeros_like(flag))
    names = [f"[{prog.text(x)}] [{prog.text(y)}]" + (" !" if f else "") for x, y, f in keys]
    return np.array(rows, dtype=np.int64), 0, [pair], names


def _translate(g: Formula, own: tuple[str, ...]):
    """Reduced raw automaton of NNF formula ``g`` over ``own`` (see the module docstring)."""
    if is_cosafe(g):
        return reduce_rabin(*_progression_dfa(g, own, cosafe=True))
    if is_safe(g):
        return reduce_rabin(*_progression_dfa(g, own, cosafe=False))
    op = g.op
    parts = None
    conj = op == "&"
    if op in ("&", "|"):
        parts = list(g.children)
    elif op == "G" and g.children[0].op == "&":
        parts, conj = [mk_G(c) for c in g.children[0].children], True
    elif op == "F" and g.children[0].op == "|":
        parts, conj = [mk_F(c) for c in g.children[0].children], False
    if parts is not None:
        # Group the co-safe and the safe operands: each group is one (DFA) operand.
        groups = {"cosafe": [], "safe": [], "other": []}
        for c in parts:
            kind = "cosafe" if is_cosafe(c) else "safe" if is_safe(c) else "other"
            groups[kind].append(c)
        mk = mk_and if conj else mk_or
        operands = [mk(*groups[k]) for k in ("cosafe", "safe") if groups[k]] + groups["other"]
        if len(operands) > 1:
            raws = [_translate(c, own) for c in operands]
            result = _product_reduced(raws, conj)
            if result is not None:
                return result
    if op == "X":
        return reduce_rabin(*delay(_translate(g.children[0], own)))
    if op == "G" and g.children[0].op == "F" and is_cosafe(g.children[0]):
        return reduce_rabin(*_monitor(g.children[0], own, recurrence=True))
    if op == "F" and g.children[0].op == "G" and is_safe(g.children[0]):
        return reduce_rabin(*_monitor(g.children[0], own, recurrence=False))
    if op == "G" and is_cosafe(g.children[0]):
        return reduce_rabin(*_breakpoint(g.children[0], own, complement=False))
    if op == "F" and is_safe(g.children[0]):
        return reduce_rabin(*_breakpoint(negate(g.children[0]), own, complement=True))
    return reduce_rabin(*_safra(g, own))


def _product_reduced(raws, conj: bool):
    """Pairwise products, reducing after each; ``None`` if a product is refused."""
    raws = sorted(raws, key=lambda r: r[0].shape[0])
    acc = raws[0]
    for r in raws[1:]:
        p = product([acc, r], conj)
        if p is None:
            return None
        acc = reduce_rabin(*p)
    return acc


def _expand_alphabet(table: np.ndarray, own: tuple[str, ...], props: tuple[str, ...]):
    """Re-index letters from the formula's own propositions to the full alphabet."""
    if own == props:
        return table
    letters = np.arange(1 << len(props))
    proj = np.zeros_like(letters)
    for i, p in enumerate(own):
        proj |= ((letters >> props.index(p)) & 1) << i
    return table[:, proj]


def translate(
    formula: str | Formula,
    propositions: Sequence[str] | None = None,
    limits: TranslationLimits | None = None,
) -> RabinAutomaton:
    """Translate an LTL formula to an equivalent complete deterministic Rabin automaton.

    Args:
        formula: LTL text (see :func:`planner.ltl.parser.parse`) or a parsed formula.
        propositions: the alphabet, in letter-bit order; must contain every proposition of
            the formula and may add others, each a plain name
            (:func:`planner.ltl.parser.is_plain_name`) unless the formula uses it. Default:
            the formula's propositions, sorted.
        limits: letters, states, table entries and seconds the translation may use
            (default :class:`~planner.ltl.budget.TranslationLimits`).

    Raises:
        LTLSyntaxError: if ``formula`` does not parse, or a given formula nests deeper than
            :data:`planner.ltl.parser.MAX_DEPTH`.
        AutomatonError: if ``propositions`` has duplicates, a malformed name or misses a
            proposition.
        TranslationLimitError: a limit of ``limits`` was exceeded.
    """
    limits = TranslationLimits() if limits is None else limits
    f = parse(formula) if isinstance(formula, str) else formula
    if f.depth > MAX_DEPTH:
        raise LTLSyntaxError(
            f"formula nested {f.depth} operators deep, more than the limit of {MAX_DEPTH}", 0
        )
    props = _alphabet(f, propositions)
    limits.check_letters(len(props))
    with limited(limits):
        g = simplify(f)
        own = tuple(p for p in props if p in g.propositions())
        set_letters(1 << len(own))
        table, initial, pairs, names = _translate(g, own)
        count_state(table.shape[0], 1 << len(props))
        table = _expand_alphabet(table, own, props)
    return RabinAutomaton(
        props,
        table,
        initial,
        [
            RabinPair(
                frozenset(np.flatnonzero(gd).tolist()), frozenset(np.flatnonzero(bd).tolist())
            )
            for gd, bd in pairs
        ],
        state_names=names,
    )
