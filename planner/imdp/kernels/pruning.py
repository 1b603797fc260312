"""The rows that stay in a set and the pruning cascade of removed states, compiled: a row
goes when it may (``upper > 0``) enter a removed state, and a state goes when it has no
row left (Jiang et al. 2023, Alg. 1), for the pruning of unsafe states, the shrinking
candidate set of the almost-sure search and the states that may hold end components; and
whether no row leaves a set (:func:`closed_under`)."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def rows_staying_in(u, rows, row_state, row_ptr, successor, upper, exclude):
    """Rows of ``rows`` at states of ``u`` outside ``exclude`` whose every ``upper > 0``
    successor lies in ``u`` (one pass of :func:`_drop_entering`, the states outside ``u``
    removed)."""
    kept = rows & ~exclude[row_state]
    live = np.zeros(u.size, dtype=np.int64)
    none = np.empty(0, dtype=np.int64)
    _drop_entering(none, ~u, kept, live, row_state, row_ptr, successor, upper)
    return kept


@numba.njit(cache=True, nogil=True)
def prune_kernel(
    removed,
    rows_ok,
    row_state,
    state_ptr,
    row_ptr,
    successor,
    upper,
    inc_ptr,
    inc_row,
    inc_upper,
    keep,
):
    """Remove the rows that may (``upper > 0``) enter a removed state and the states left
    without rows (except those of ``keep``), in a cascade through the incoming entries
    (Jiang et al. 2023, Alg. 1): ``(removed states, rows kept, kept rows per state)``; the
    last three continue the cascade (:func:`drop_states`)."""
    n = removed.size
    bad = removed.copy()
    rows = rows_ok.copy()
    live = np.zeros(n, dtype=np.int64)
    empty = np.empty(0, dtype=np.int64)
    while True:
        # a pass over the rows still kept while it costs less than the cascade through the
        # incoming entries of the states left without rows (on the random benchmark model
        # nearly every row leaves at once: one more pass instead of 4.6M incoming entries)
        entries = _drop_entering(empty, bad, rows, live, row_state, row_ptr, successor, upper)
        empty = np.flatnonzero(~bad & ~keep & (live == 0))
        incoming = 0
        for s in empty:
            incoming += inc_ptr[s + 1] - inc_ptr[s]
        if empty.size == 0 or incoming <= entries:
            break
    drop_states(empty, bad, rows, live, row_state, state_ptr, inc_ptr, inc_row, inc_upper, keep)
    return bad, rows, live


@numba.njit(cache=True, nogil=True)
def _drop_entering(states, bad, rows, live, row_state, row_ptr, successor, upper) -> int:
    """``states`` marked removed, then one pass over the kept rows: a row at a removed state
    or with an ``upper > 0`` entry into one goes; ``live`` counts the rows kept per state.
    Returns the entries of the rows kept."""
    bad[states] = True
    live[:] = 0
    entries = 0
    for r in range(row_ptr.size - 1):
        if not rows[r]:
            continue
        if bad[row_state[r]]:
            rows[r] = False
            continue
        for e in range(row_ptr[r], row_ptr[r + 1]):
            if upper[e] > 0.0 and bad[successor[e]]:
                rows[r] = False
                break
        if rows[r]:
            live[row_state[r]] += 1
            entries += row_ptr[r + 1] - row_ptr[r]
    return entries


@numba.njit(cache=True, nogil=True)
def drop_states(
    states, bad, rows, live, row_state, state_ptr, inc_ptr, inc_row, inc_upper, keep
) -> None:
    """Continue :func:`prune_kernel`'s cascade, in place, with ``states`` removed too: their
    rows and the rows that may enter them go, then the states (outside ``keep``) left
    without rows, and so on (``O(rows and incoming entries of the states removed)``)."""
    queue = np.empty(bad.size, dtype=np.int64)
    tail = 0
    for s in states:
        if not bad[s]:
            bad[s] = True
            queue[tail] = s
            tail += 1
    head = 0
    while head < tail:
        t = queue[head]
        head += 1
        for r in range(state_ptr[t], state_ptr[t + 1]):
            if rows[r]:
                rows[r] = False
                live[t] -= 1
        for k in range(inc_ptr[t], inc_ptr[t + 1]):
            r = inc_row[k]
            if rows[r] and inc_upper[k] > 0.0:
                rows[r] = False
                s = row_state[r]
                live[s] -= 1
                if live[s] == 0 and not bad[s] and not keep[s]:
                    bad[s] = True
                    queue[tail] = s
                    tail += 1


@numba.njit(cache=True, nogil=True)
def closed_under(states, rows, state_ptr, row_ptr, successor, upper) -> bool:
    """Whether every row of ``rows`` at a state of ``states`` keeps every ``upper > 0``
    successor in ``states`` (the first entry that leaves ends the search)."""
    for s in range(states.size):
        if not states[s]:
            continue
        for r in range(state_ptr[s], state_ptr[s + 1]):
            if not rows[r]:
                continue
            for e in range(row_ptr[r], row_ptr[r + 1]):
                if upper[e] > 0.0 and not states[successor[e]]:
                    return False
    return True
