"""Language-preserving reduction of deterministic Rabin automata.

:func:`reduce_rabin` applies, in order:

1. restriction to the states reachable from the initial state;
2. acceptance clean-up per strongly connected component ``C`` (the infinitely-often set of a
   run lies inside one SCC): states on no cycle leave every pair; if ``G_i ∩ C ⊆ B_i`` then
   pair ``i`` can accept no run whose infinitely-often set lies in ``C``, so ``C`` leaves
   ``G_i`` and ``B_i``;
3. states with an empty language (they reach no SCC of the graph without ``B_i`` that is a
   cycle through ``G_i``, for any ``i``) are merged into one rejecting sink;
4. the coarsest bisimulation that respects every state's membership in every ``G_i`` and
   ``B_i`` (Moore's partition refinement, vectorised with numpy), then the quotient;
5. removal of pairs with empty ``G``, duplicate pairs and pairs dominated by another
   (``G_i ⊆ G_j`` and ``B_i ⊇ B_j``);
6. every state on no cycle (visited at most once by any run) is redirected to a state with
   the same successors, whatever their acceptance marks; 1-6 repeat until nothing changes.

Each step maps a run to a run with the same acceptance, so the language is unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components


def _scc(table: np.ndarray, keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """SCC labels and a flag "on a cycle" for the graph of ``table`` (restricted to ``keep``)."""
    n, k = table.shape
    src = np.repeat(np.arange(n), k)
    dst = table.reshape(-1)
    if keep is not None:
        ok = keep[src] & keep[dst]
        src, dst = src[ok], dst[ok]
    graph = csr_matrix((np.ones(src.size, dtype=np.int8), (src, dst)), shape=(n, n))
    _, labels = connected_components(graph, directed=True, connection="strong")
    sizes = np.bincount(labels, minlength=labels.max() + 1 if n else 0)
    cyclic = sizes[labels] > 1
    self_loop = np.zeros(n, dtype=bool)
    self_loop[src[src == dst]] = True
    return labels, cyclic | self_loop


def _reach_backward(table: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """States from which some state of ``targets`` is reachable."""
    n, k = table.shape
    src = np.repeat(np.arange(n), k)
    dst = table.reshape(-1)
    reached = targets.copy()
    while True:
        new = reached.copy()
        new[src[reached[dst]]] = True
        if new.sum() == reached.sum():
            return reached
        reached = new


def _reachable(table: np.ndarray, initial: int) -> np.ndarray:
    n = table.shape[0]
    seen = np.zeros(n, dtype=bool)
    seen[initial] = True
    frontier = np.array([initial])
    while frontier.size:
        nxt = np.unique(table[frontier].reshape(-1))
        nxt = nxt[~seen[nxt]]
        seen[nxt] = True
        frontier = nxt
    return seen


def _refine(table: np.ndarray, signature: np.ndarray) -> np.ndarray:
    """Coarsest partition refining ``signature`` (rows) that is stable under ``table``."""
    _, cls = np.unique(signature, axis=0, return_inverse=True)
    cls = cls.reshape(-1)
    count = cls.max() + 1
    while True:
        key = np.concatenate([cls[:, None], cls[table]], axis=1)
        _, new = np.unique(key, axis=0, return_inverse=True)
        new = new.reshape(-1)
        new_count = new.max() + 1
        if new_count == count:
            return new
        cls, count = new, new_count


def _restrict(
    keep: np.ndarray, table: np.ndarray, initial: int, goods, bads, origin
) -> tuple[np.ndarray, int, np.ndarray, np.ndarray, np.ndarray]:
    """Step 1: the automaton restricted to the states ``keep`` (closed under successors)."""
    new_index = np.cumsum(keep) - 1
    return (
        new_index[table[keep]],
        int(new_index[initial]),
        goods[:, keep],
        bads[:, keep],
        origin[keep],
    )


def _clean_per_scc(table: np.ndarray, goods: np.ndarray, bads: np.ndarray) -> None:
    """Step 2, in place: states on no cycle leave every pair; an SCC with no state of
    ``G_i`` outside ``B_i`` leaves ``G_i`` and ``B_i``."""
    labels, cyclic = _scc(table)
    goods &= cyclic
    bads &= cyclic
    n_scc = labels.max() + 1
    for i in range(goods.shape[0]):
        useful = goods[i] & ~bads[i]
        scc_useful = np.bincount(labels[useful], minlength=n_scc) > 0
        dead = ~scc_useful[labels]
        goods[i] &= ~dead
        bads[i] &= ~dead


def _empty_language(table: np.ndarray, goods: np.ndarray, bads: np.ndarray) -> np.ndarray:
    """Step 3: the states that reach no cycle through ``G_i`` avoiding ``B_i``, for any
    ``i``."""
    core = np.zeros(table.shape[0], dtype=bool)
    for i in range(goods.shape[0]):
        allowed = ~bads[i]
        lab, cyc = _scc(table, allowed)
        hit = np.bincount(lab[goods[i] & allowed & cyc], minlength=lab.max() + 1) > 0
        core |= hit[lab] & allowed & cyc
    return ~_reach_backward(table, core)


def _quotient(
    table: np.ndarray, goods: np.ndarray, bads: np.ndarray, empty: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step 4: the class of every state under the coarsest bisimulation respecting the
    pairs (the empty-language states one sink) and the first state of every class."""
    sig = np.concatenate([goods.T, bads.T, empty[:, None]], axis=1).astype(np.int8)
    work = table.copy()
    if empty.any():
        sink = int(np.flatnonzero(empty)[0])
        work[empty] = sink
        work = np.where(empty[work], sink, work)
    cls = _refine(work, sig)
    reps = np.zeros(int(cls.max()) + 1, dtype=np.int64)
    reps[cls[::-1]] = np.arange(table.shape[0])[::-1]  # first state of each class
    return cls, reps, cls[work[reps]]


def _prune_pairs(goods: np.ndarray, bads: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Step 5: the pairs without those with empty ``G``, duplicates and those dominated by
    another (``G_i ⊆ G_j`` and ``B_i ⊇ B_j``)."""
    uniq: list[tuple[np.ndarray, np.ndarray]] = []
    seen_keys: set[tuple[bytes, bytes]] = set()
    for g, b in zip(goods, bads, strict=True):
        key = (g.tobytes(), b.tobytes())
        if g.any() and key not in seen_keys:
            seen_keys.add(key)
            uniq.append((g, b))
    return [
        (g, b)
        for i, (g, b) in enumerate(uniq)
        if not any(
            j != i and not (g & ~g2).any() and not (b2 & ~b).any()
            for j, (g2, b2) in enumerate(uniq)
        )
    ]


def _redirect_transient(table: np.ndarray) -> np.ndarray:
    """Step 6: for every state, the state it is redirected to. A state on no cycle is
    visited at most once, so its acceptance marks are irrelevant: it goes to the first state
    with the same successors (states on a cycle first)."""
    _, cyc_q = _scc(table)
    owner: dict[bytes, int] = {}
    for c in np.concatenate([np.flatnonzero(cyc_q), np.flatnonzero(~cyc_q)]).tolist():
        owner.setdefault(table[c].tobytes(), c)
    redirect = np.arange(table.shape[0])
    for c in np.flatnonzero(~cyc_q).tolist():
        redirect[c] = owner[table[c].tobytes()]
    return redirect


def _masks(pairs: Sequence[tuple[np.ndarray, np.ndarray]], n: int) -> tuple[np.ndarray, ...]:
    """``(goods, bads)``: the pairs' masks as two ``(n_pairs, n)`` boolean arrays."""
    goods = np.array([g for g, _ in pairs], dtype=bool).reshape(len(pairs), n)
    bads = np.array([b for _, b in pairs], dtype=bool).reshape(len(pairs), n)
    return goods, bads


def reduce_rabin(
    table: np.ndarray,
    initial: int,
    pairs: Sequence[tuple[np.ndarray, np.ndarray]],
    names: Sequence[str],
) -> tuple[np.ndarray, int, list[tuple[np.ndarray, np.ndarray]], list[str]]:
    """Reduce a complete deterministic state-based Rabin automaton (steps 1-6 of the module
    docstring, repeated until nothing changes).

    Args:
        table: ``(n, n_letters)`` successor table.
        initial: initial state.
        pairs: ``(good, bad)`` boolean masks of length ``n``.
        names: state names.

    Returns:
        ``(table, initial, pairs, names)`` of an equivalent, usually smaller, automaton.
    """
    table = np.asarray(table, dtype=np.int64)
    goods, bads = _masks(pairs, table.shape[0])
    origin = np.arange(table.shape[0])  # original index of each current state
    while True:
        keep = _reachable(table, initial)
        if not keep.all():
            table, initial, goods, bads, origin = _restrict(
                keep, table, initial, goods, bads, origin
            )
        n = table.shape[0]
        _clean_per_scc(table, goods, bads)
        empty = _empty_language(table, goods, bads)
        goods &= ~empty
        bads &= ~empty
        cls, reps, new_table = _quotient(table, goods, bads, empty)
        n_cls = reps.shape[0]
        kept = _prune_pairs(goods[:, reps], bads[:, reps])
        redirect = _redirect_transient(new_table)
        merged = bool((redirect != np.arange(n_cls)).any())
        changed = merged or n_cls != n or len(kept) != goods.shape[0]
        table = redirect[new_table]
        initial = int(redirect[cls[initial]])
        origin = origin[reps]
        goods, bads = _masks(kept, n_cls)
        if not changed:
            break
    return table, initial, list(zip(goods, bads, strict=True)), [names[i] for i in origin.tolist()]
