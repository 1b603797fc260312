"""Breadth-first layers of a model towards a set of states (:func:`layers`), the order in
which the Gauss-Seidel sweeps visit the states (and, on a chain's own edges, the states
that reach a set: :func:`planner.imdp.evaluate.reaching`).

The search goes level by level, each level in the cheaper direction (Beamer, Asanovic and
Patterson, "Direction-optimizing breadth-first search", SC 2012): *top-down* it scans
the incoming entries of the last level's states; *bottom-up* each state not yet reached
scans its own entries until one leads into a state reached before this level. Top-down
costs the incoming entries of the last level; bottom-up at most the entries of the states
not yet reached, and usually far fewer, as it stops at the first entry that leads in. On
the random 100k-state benchmark model the first level (from 5,010 goal states) reaches
63,030 of the 64,611 states that can be reached at all: top-down the second level would
scan the incoming lists of those 63,030 states (4.5M entries) to find the last 1,581,
bottom-up it scans a few entries of each of those 1,581.
"""

from __future__ import annotations

import numba
import numpy as np

from planner.imdp.model import IMDP


def layers(m: IMDP, free_rows: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """Breadth-first distance (in hops over ``upper > 0`` edges of ``free_rows``, indices
    or a row mask) from each state to ``sources``; ``inf`` where there is no path."""
    if free_rows.dtype == np.bool_:
        row_mask = free_rows
    else:
        row_mask = np.zeros(m.n_rows, dtype=bool)
        row_mask[free_rows] = True
    ptr, inc_row, inc_state, _, inc_upper = m.reverse_index()
    src = np.asarray(sources, dtype=bool)
    forward = (m.state_ptr, m.row_ptr, m.successor, m.upper)
    return layer_distance(src, row_mask, ptr, inc_row, inc_state, inc_upper, *forward)


@numba.njit(cache=True, nogil=True)
def layer_distance(
    sources, row_mask, inc_ptr, inc_row, inc_state, inc_upper, state_ptr, row_ptr, successor, upper
):
    """Breadth-first number of hops from each state to ``sources`` along ``upper > 0``
    entries of the rows in ``row_mask`` (``inf`` where no path), level by level, each
    level top-down (the incoming entries, :meth:`planner.imdp.model.IMDP.reverse_index`;
    ``inc_state`` read in order, so that an entry from a state already reached costs no
    lookup of its row) or, where the incoming entries of the last level outnumber all
    entries of the states not yet reached, bottom-up (the states' own rows). The search
    ends once every state with a row in ``row_mask`` is reached."""
    n = sources.size
    dist = np.full(n, np.inf)
    frontier = np.empty(n, dtype=np.int64)
    reached = np.empty(n, dtype=np.int64)
    n_front = 0
    for s in range(n):
        if sources[s]:
            dist[s] = 0.0
            frontier[n_front] = s
            n_front += 1
    # the states the search can reach besides the sources (those with a row in row_mask),
    # and all their entries: a bound on what a bottom-up level scans
    left = np.empty(n, dtype=np.int64)
    n_left = 0
    left_entries = 0
    for s in range(n):
        if sources[s]:
            continue
        for r in range(state_ptr[s], state_ptr[s + 1]):
            if row_mask[r]:
                left[n_left] = s
                n_left += 1
                left_entries += row_ptr[state_ptr[s + 1]] - row_ptr[state_ptr[s]]
                break
    remaining = n_left
    d = 0.0
    while n_front > 0 and remaining > 0:
        d += 1.0
        incoming = 0
        for i in range(n_front):
            t = frontier[i]
            incoming += inc_ptr[t + 1] - inc_ptr[t]
        n_next = 0
        if incoming > left_entries:
            keep = 0
            for i in range(n_left):
                s = left[i]
                if dist[s] != np.inf:
                    continue  # reached top-down
                found = False
                for r in range(state_ptr[s], state_ptr[s + 1]):
                    if not row_mask[r]:
                        continue
                    for e in range(row_ptr[r], row_ptr[r + 1]):
                        if upper[e] > 0.0 and dist[successor[e]] < d:
                            found = True
                            break
                    if found:
                        break
                if found:
                    dist[s] = d
                    reached[n_next] = s
                    n_next += 1
                else:
                    left[keep] = s
                    keep += 1
            n_left = keep
        else:
            for i in range(n_front):
                t = frontier[i]
                for k in range(inc_ptr[t], inc_ptr[t + 1]):
                    s = inc_state[k]
                    if dist[s] != np.inf or inc_upper[k] <= 0.0 or not row_mask[inc_row[k]]:
                        continue
                    dist[s] = d
                    reached[n_next] = s
                    n_next += 1
                if n_next >= remaining:
                    break
        for i in range(n_next):
            s = reached[i]
            left_entries -= row_ptr[state_ptr[s + 1]] - row_ptr[state_ptr[s]]
        remaining -= n_next
        frontier, reached = reached, frontier
        n_front = n_next
    return dist


@numba.njit(cache=True, nogil=True)
def sweep_order(free_rows, row_state, key, model_row_ptr, row_lower_sum):
    """The index of the sweeps' layout (:class:`planner.imdp.kernels.sweeps.ReachSweeper`)
    in one pass after a stable sort of the states: the states of ``free_rows`` (sorted) in
    increasing ``key`` (ties in index order), each with its run of rows in order.

    Returns ``(states, state_rows, position, rows, row_ptr, remaining)``: the states in
    sweep order, the first layout row of each (and the end), for each layout row its
    position in ``free_rows``, its model row, its first entry in the layout (and the end)
    and its remaining mass ``1 - sum(l)``."""
    n = free_rows.size
    n_states = 0
    for i in range(n):
        if i == 0 or row_state[free_rows[i]] != row_state[free_rows[i - 1]]:
            n_states += 1
    first = np.empty(n_states + 1, dtype=np.int64)
    keys = np.empty(n_states)
    j = 0
    for i in range(n):
        if i == 0 or row_state[free_rows[i]] != row_state[free_rows[i - 1]]:
            first[j] = i
            keys[j] = key[row_state[free_rows[i]]]
            j += 1
    first[n_states] = n
    by_key = np.argsort(keys, kind="mergesort")
    states = np.empty(n_states, dtype=np.int64)
    state_rows = np.empty(n_states + 1, dtype=np.int64)
    position = np.empty(n, dtype=np.int64)
    rows = np.empty(n, dtype=free_rows.dtype)
    row_ptr = np.empty(n + 1, dtype=np.int64)
    remaining = np.empty(n)
    p = 0
    e = 0
    for j in range(n_states):
        b = by_key[j]
        states[j] = row_state[free_rows[first[b]]]
        state_rows[j] = p
        for i in range(first[b], first[b + 1]):
            r = free_rows[i]
            position[p] = i
            rows[p] = r
            row_ptr[p] = e
            e += model_row_ptr[r + 1] - model_row_ptr[r]
            remaining[p] = 1.0 - row_lower_sum[r]
            p += 1
    state_rows[n_states] = p
    row_ptr[n] = e
    return states, state_rows, position, rows, row_ptr, remaining
