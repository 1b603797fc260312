"""A deterministic automaton with marks and a generic acceptance condition as a state-based
Rabin automaton (the second half of :func:`planner.ltl.hoa.from_hoa`).

Input: a successor table ``table[q, letter]`` (``-1``: no edge), the set of acceptance marks
of every edge ``marks[q, letter]`` (a frozenset of set numbers) and an acceptance condition
over ``Inf(n)``, ``Fin(n)`` (either possibly of the complement ``!n``), ``t``, ``f``, ``&``
and ``|``. The steps:

1. **State marks.** If every edge of each state carries the same marks, those are the
   state's marks (one state per state); otherwise a state of the result is a pair (state,
   marks of the edge that entered it), so that marks sit on states.
2. **Disjunctive normal form.** Each disjunct ``Fin(F_1) & .. & Inf(I_1) & .. & Inf(I_k)``
   becomes one Rabin pair ``(G, B)``: ``B`` the states carrying some ``F_j``, ``G`` those
   carrying ``I_1`` (for ``k = 1``), every state (``k = 0``) or, for ``k >= 2``
   (degeneralisation), those where a round-robin counter over ``I_1 .. I_k``, kept in the
   state, has just seen all of them.
3. **Missing edges** go to one rejecting sink; the result is reduced with
   :func:`planner.ltl.reduce.reduce_rabin`.
"""

from __future__ import annotations

import numpy as np

from planner.automaton import RabinAutomaton, RabinPair
from planner.errors import HOAError
from planner.ltl.interning import intern
from planner.ltl.reduce import reduce_rabin

#: Most disjuncts of an acceptance condition in disjunctive normal form (Rabin pairs).
MAX_DISJUNCTS = 4096

Atom = tuple[int, bool]
"""``(n, negated)``: acceptance set ``n``, or its complement when ``negated``."""

_SINK = ("sink",)


def dnf(cond) -> list[list[tuple[str, int, bool]]]:
    """Disjunctive normal form of an acceptance condition: list of conjunctions of atoms."""
    kind = cond[0]
    if kind == "const":
        return [[]] if cond[1] else []
    if kind in ("Inf", "Fin"):
        return [[(kind, cond[1], cond[2])]]
    parts = [dnf(c) for c in cond[1]]
    if kind == "|":
        return [c for p in parts for c in p]
    out: list[list[tuple[str, int, bool]]] = [[]]
    for p in parts:
        if len(out) * len(p) > MAX_DISJUNCTS:
            raise HOAError(
                f"the acceptance condition has more than {MAX_DISJUNCTS} disjuncts in "
                "disjunctive normal form"
            )
        out = [a + b for a in out for b in p]
    return out


def _member(m: frozenset[int], atom: Atom) -> bool:
    return (atom[0] in m) != atom[1]


def _state_marks(table: np.ndarray, marks: np.ndarray) -> list[frozenset[int]] | None:
    """Step 1: the marks of every state when all edges of each state carry the same marks
    (no edges: no marks); ``None`` when some state's edges differ."""
    n_states, n_letters = table.shape
    defined = table >= 0
    own: list[frozenset[int] | None] = []
    for q in range(n_states):
        ms = {marks[q, x] for x in range(n_letters) if defined[q, x]}
        own.append(next(iter(ms)) if len(ms) == 1 else frozenset() if not ms else None)
    return own if all(m is not None for m in own) else None  # type: ignore[return-value]


def _advance(
    counters: tuple[int, ...], m: frozenset[int], infs: list[list[Atom]], gen: list[int]
) -> tuple[int, ...]:
    """The round-robin counters of the generalised disjuncts ``gen`` after marks ``m``: a
    counter ``c`` of disjunct ``d`` moves past every ``Inf`` atom from ``infs[d][c]`` on
    that ``m`` satisfies; a full counter (``len(infs[d])``) starts again from 0."""
    out = []
    for c_i, d in enumerate(gen):
        c = counters[c_i]
        k = len(infs[d])
        if c == k:
            c = 0
        while c < k and _member(m, infs[d][c]):
            c += 1
        out.append(c)
    return tuple(out)


def _explore(
    table: np.ndarray,
    marks: np.ndarray,
    start: int,
    own: list[frozenset[int]] | None,
    infs: list[list[Atom]],
    gen: list[int],
) -> tuple[list, list[list[int]]]:
    """Breadth-first states ``(state, marks, counters)`` (and the sink) reachable from
    ``start``, with their successor rows; ``own``: the state marks of step 1, if any."""
    n_letters = table.shape[1]
    first = own[start] if own is not None else frozenset()
    init = (start, first, tuple(0 for _ in gen))
    index = {init: 0}
    states: list = [init]
    rows: list[list[int]] = []
    i = 0
    while i < len(states):
        key = states[i]
        row = []
        for x in range(n_letters):
            if key == _SINK or table[key[0], x] < 0:
                nxt = _SINK
            else:
                target = int(table[key[0], x])
                m = own[target] if own is not None else marks[key[0], x]
                nxt = (target, m, _advance(key[2], m, infs, gen))
            row.append(intern(nxt, index, states))
        rows.append(row)
        i += 1
    return states, rows


def _pairs(
    states: list, infs: list[list[Atom]], fins: list[list[Atom]], gen: list[int]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Step 2: the Rabin pair ``(good, bad)`` of every disjunct over the explored states."""
    n = len(states)
    pairs = []
    for d in range(len(infs)):
        good = np.zeros(n, dtype=bool)
        bad = np.zeros(n, dtype=bool)
        for s, key in enumerate(states):
            if key == _SINK:
                continue
            _, m, counters = key
            bad[s] = any(_member(m, a) for a in fins[d])
            if d in gen:
                good[s] = counters[gen.index(d)] == len(infs[d])
            elif infs[d]:
                good[s] = _member(m, infs[d][0])
            else:
                good[s] = True
        pairs.append((good, bad))
    return pairs


def _name(key) -> str:
    if key == _SINK:
        return "sink"
    return f"{key[0]}" + (f" {{{' '.join(map(str, sorted(key[1])))}}}" if key[1] else "")


def marks_to_rabin(
    table: np.ndarray, marks: np.ndarray, start: int, acceptance, propositions: list[str]
) -> RabinAutomaton:
    """The reduced state-based Rabin automaton of ``table`` (``(n, n_letters)``, ``-1`` for
    a missing edge) with edge ``marks`` (``(n, n_letters)`` frozensets), initial state
    ``start`` and the parsed ``acceptance`` condition (see the module docstring).

    Raises:
        HOAError: the acceptance condition has more than :data:`MAX_DISJUNCTS` disjuncts.
    """
    conjuncts = dnf(acceptance)
    infs = [[(n, neg) for kind, n, neg in c if kind == "Inf"] for c in conjuncts]
    fins = [[(n, neg) for kind, n, neg in c if kind == "Fin"] for c in conjuncts]
    gen = [i for i, c in enumerate(infs) if len(c) >= 2]
    states, rows = _explore(table, marks, start, _state_marks(table, marks), infs, gen)
    pairs = _pairs(states, infs, fins, gen)
    names = [_name(k) for k in states]
    t, init_s, prs, nm = reduce_rabin(np.array(rows, dtype=np.int64), 0, pairs, names)
    return RabinAutomaton(
        propositions,
        t,
        init_s,
        [
            RabinPair(frozenset(np.flatnonzero(g).tolist()), frozenset(np.flatnonzero(b).tolist()))
            for g, b in prs
        ],
        state_names=nm,
    )
