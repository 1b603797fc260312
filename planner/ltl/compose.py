"""Compositional constructions on deterministic Rabin automata (raw table form).

A *raw* automaton is ``(table, initial, pairs, names)``: an ``(n, n_letters)`` integer
successor table, the initial state, Rabin pairs ``(good, bad)`` as boolean masks, and state
names. All letters are over the same proposition order.

* :func:`delay` builds ``X f`` from ``f``: a fresh initial state that moves to ``f``'s
  initial state on every letter.
* :func:`product` builds ``f_1 | ... | f_k`` or ``f_1 & ... & f_k`` from the automata of the
  ``f_i`` by the synchronous product. For ``|`` the pairs are the lifted pairs of the
  operands. For ``&`` the condition ``/\\_i \\/_j (Fin B_ij & Inf G_ij)`` is multiplied out
  into generalised Rabin pairs ``Fin(B_1j1 | ... | B_kjk) & Inf G_1j1 & ... & Inf G_kjk``;
  each is made a Rabin pair with a round-robin counter over its ``Inf`` sets
  (degeneralisation). Operands that are *weak* (one pair, every cycle-carrying SCC either
  inside ``G \\ B`` or disjoint from ``G``) contribute ``Fin(states outside accepting SCCs)``
  only, so that safety and co-safety operands need no counter.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

from planner.ltl.interning import intern
from planner.ltl.reduce import _scc

Raw = tuple  # (table, initial, pairs, names)

#: Products needing more counters than this are refused (the caller falls back).
MAX_COUNTERS = 3


def delay(raw: Raw) -> Raw:
    """Automaton of ``X f`` from the automaton of ``f``."""
    table, initial, pairs, names = raw
    n_letters = table.shape[1]
    head = np.full((1, n_letters), initial + 1, dtype=np.int64)
    new_table = np.vstack([head, table + 1])
    pad = np.zeros(1, dtype=bool)
    new_pairs = [(np.concatenate([pad, g]), np.concatenate([pad, b])) for g, b in pairs]
    return new_table, 0, new_pairs, ["X", *names]


def _conditions(raw: Raw) -> list[tuple[np.ndarray | None, np.ndarray]]:
    """Pairs as ``(good or None for "every state", bad)``, weak automata as Fin only."""
    table, _, pairs, _ = raw
    if len(pairs) == 1:
        g, b = pairs[0]
        labels, cyclic = _scc(table)
        n_scc = labels.max() + 1
        in_good = np.bincount(labels[g & cyclic], minlength=n_scc)
        in_bad = np.bincount(labels[b & cyclic], minlength=n_scc)
        size = np.bincount(labels[cyclic], minlength=n_scc)
        accepting = (in_good == size) & (in_bad == 0) & (size > 0)
        rejecting = in_good == 0
        if np.all(accepting | rejecting):
            return [(None, ~accepting[labels])]
    return [(None if g.all() else g, b) for g, b in pairs]


def product(raws: Sequence[Raw], conjunction: bool) -> Raw | None:
    """Automaton of the conjunction (or disjunction) of the operands' languages.

    Returns ``None`` if a conjunction would need more than :data:`MAX_COUNTERS` counters.
    """
    tables = [r[0].tolist() for r in raws]
    n_letters = raws[0][0].shape[1]
    k = len(raws)
    if conjunction:
        conds = [_conditions(r) for r in raws]
        disjuncts = []
        for choice in itertools.product(*conds):
            infs = [(i, g) for i, (g, _) in enumerate(choice) if g is not None]
            fins = [(i, b) for i, (_, b) in enumerate(choice) if b.any()]
            disjuncts.append((infs, fins))
        counted = [d for d, (infs, _) in enumerate(disjuncts) if len(infs) >= 2]
        if len(counted) > MAX_COUNTERS:
            return None
    else:
        disjuncts = [
            ([(i, g)], [(i, b)] if b.any() else []) for i, r in enumerate(raws) for g, b in r[2]
        ]
        counted = []
    inf_lists = [[(i, g.tolist()) for i, g in infs] for infs, _ in disjuncts]

    start = (tuple(r[1] for r in raws), tuple(0 for _ in counted))
    index = {start: 0}
    keys = [start]
    rows: list[list[int]] = []
    j = 0
    while j < len(keys):
        states, counters = keys[j]
        row = []
        for a in range(n_letters):
            nxt = tuple(tables[i][states[i]][a] for i in range(k))
            new_counters = []
            for c_i, d in enumerate(counted):
                infs = inf_lists[d]
                c = counters[c_i]
                if c == len(infs):
                    c = 0
                while c < len(infs) and infs[c][1][nxt[infs[c][0]]]:
                    c += 1
                new_counters.append(c)
            key = (nxt, tuple(new_counters))
            t = intern(key, index, keys)
            row.append(t)
        rows.append(row)
        j += 1
    comp = np.array([s for s, _ in keys], dtype=np.int64).reshape(len(keys), k)
    cnt = np.array([c for _, c in keys], dtype=np.int64).reshape(len(keys), len(counted))
    pairs = []
    for d, (infs, fins) in enumerate(disjuncts):
        bad = np.zeros(len(keys), dtype=bool)
        for i, b in fins:
            bad |= b[comp[:, i]]
        if d in counted:
            good = cnt[:, counted.index(d)] == len(infs)
        elif infs:
            i, g = infs[0]
            good = g[comp[:, i]]
        else:
            good = np.ones(len(keys), dtype=bool)
        pairs.append((good, bad))
    names = ["(" + ", ".join(raws[i][3][s] for i, s in enumerate(st)) + ")" for st, _ in keys]
    return np.array(rows, dtype=np.int64), 0, pairs, names
