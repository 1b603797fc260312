"""Graph searches over the rows of an interval MDP, compiled: the attractors (of a
controller that wants to reach a set, or to stay away from it), the
breadth-first distances, forward reachability and a counting sort (the rows that stay in
a set and the pruning cascade: :mod:`.pruning`)."""

from __future__ import annotations

import numba
import numpy as np

from planner._util.threads import in_halves
from planner.imdp.kernels.exact import near_one, sum_sign
from planner.imdp.kernels.rows import longest_row
from planner.imdp.model import entries_of_rows


@numba.njit(cache=True, nogil=True)
def attractor(
    start,
    cand,
    row_state,
    row_ptr,
    successor,
    lower,
    upper,
    inc_ptr,
    inc_row,
    inc_state,
    inc_lower,
    inc_upper,
    every_row,
    forced,
):
    """The attractor of ``start`` with the candidate rows ``cand`` (work list).

    A candidate row *leads into* the set when it puts positive mass into it under every
    adversary (``forced``: an entry with ``lower > 0`` into the set, or an ``upper > 0``
    entry into it while the upper bounds of the entries outside sum to less than 1,
    decided exactly where rounding could tip it), or under some adversary (an
    ``upper > 0`` entry into it). A state joins when one of its candidate rows leads
    into the set (a controller that wants to get there) or, with ``every_row``, when all
    of them do (one that wants to stay away; states without candidate rows then never
    join). Each state that joins
    updates only the rows with an entry into it, so the whole attractor costs ``O(entries
    of the candidate rows + their incoming lists)``; an incoming entry of a row whose state
    (``inc_state``, read in order) has joined is skipped without looking at the row.
    Returns ``(mask, choice, led)``: ``choice[s]`` is the row by which ``s`` joined (-1 for
    ``start`` and outside; a joining row only counts states that joined before), ``led``
    the candidate rows found leading into the set (with ``every_row``, the others of a
    state outside the mask keep every run, under some or every adversary, outside it).
    """
    n_rows = row_ptr.size - 1
    x = start.copy()
    choice = np.full(x.size, -1, dtype=np.int64)
    left = np.zeros(x.size, dtype=np.int64)
    led = np.zeros(n_rows, dtype=np.bool_)
    must = np.zeros(n_rows, dtype=np.bool_)
    touches = np.zeros(n_rows, dtype=np.bool_)
    outside_up = np.zeros(n_rows)
    queue = np.empty(x.size, dtype=np.int64)
    longest = longest_row(row_ptr)
    terms = np.empty(longest + 1)
    scratch = np.empty(longest + 1)
    tail = 0
    if not every_row:
        _forward_passes(
            x, choice, cand, row_state, row_ptr, successor, lower, upper, forced, terms, scratch
        )
    for r in range(n_rows):
        if not cand[r] or x[row_state[r]]:
            continue
        if every_row:
            left[row_state[r]] += 1
        for e in range(row_ptr[r], row_ptr[r + 1]):
            if x[successor[e]]:
                if lower[e] > 0.0:
                    must[r] = True
                if upper[e] > 0.0:
                    touches[r] = True
            else:
                outside_up[r] += upper[e]
    for r in range(n_rows):
        s = row_state[r]
        if (
            cand[r]
            and not x[s]
            and touches[r]
            and (
                not forced
                or must[r]
                or _outside_below_one(
                    r, outside_up[r], x, row_ptr, successor, upper, terms, scratch
                )
            )
        ):
            tail = _lead(r, s, every_row, led, left, x, choice, queue, tail)
    head = 0
    while head < tail:
        t = queue[head]
        head += 1
        for k in range(inc_ptr[t], inc_ptr[t + 1]):
            s = inc_state[k]
            if x[s]:
                continue  # the row's state has joined: its counts no longer matter
            r = inc_row[k]
            if not cand[r] or (every_row and led[r]):
                continue
            if inc_lower[k] > 0.0:
                must[r] = True
            if inc_upper[k] > 0.0:
                touches[r] = True
            outside_up[r] -= inc_upper[k]
            if touches[r] and (
                not forced
                or must[r]
                or _outside_below_one(
                    r, outside_up[r], x, row_ptr, successor, upper, terms, scratch
                )
            ):
                tail = _lead(r, s, every_row, led, left, x, choice, queue, tail)
    return x, choice, led


@numba.njit(cache=True, nogil=True)
def _forward_passes(
    x, choice, cand, row_state, row_ptr, successor, lower, upper, forced, terms, scratch
):
    """The start of :func:`attractor` for a controller that wants to get there: passes over
    the candidate rows of the states outside ``x`` in index order, a state joining (in
    ``x``, with its ``choice``) as soon as a row of it leads into the set as it stands, a
    row's scan ending at its first entry that settles it. Passes run while they pay: a
    pass ends once ``_PASS_CHECK`` states scanned in it have let fewer than a
    ``_PASS_YIELD`` of them join, and none follows a pass that did so. What is left is the
    work list's, from the set the passes reached (on the random 100k-state benchmark
    model nearly every state joins in the first two passes, at a few entries each, where
    the work list alone walks all 7.2M entries twice; on a grid whose targets lie in a
    corner the first pass ends after ``_PASS_CHECK`` states). ``terms``, ``scratch``: the
    attractor's scratch arrays for :func:`_outside_below_one`."""
    n_rows = row_ptr.size - 1
    while True:
        scanned = 0
        joined = 0
        last = -1
        paid = True
        for r in range(n_rows):
            s = row_state[r]
            if x[s] or not cand[r]:
                continue
            if s != last:
                last = s
                scanned += 1
                if scanned % _PASS_CHECK == 0 and joined * _PASS_YIELD < scanned:
                    paid = False
                    break
            touch = False
            out = 0.0
            lead = False
            for e in range(row_ptr[r], row_ptr[r + 1]):
                if x[successor[e]]:
                    if lower[e] > 0.0 or (not forced and upper[e] > 0.0):
                        lead = True
                        break
                    if upper[e] > 0.0:
                        touch = True
                else:
                    out += upper[e]
            if not lead and touch and forced:
                lead = _outside_below_one(r, out, x, row_ptr, successor, upper, terms, scratch)
            if lead:
                x[s] = True
                choice[s] = r
                joined += 1
        if not paid or joined == 0 or joined * _PASS_YIELD < scanned:
            return


_PASS_CHECK = 1024
_PASS_YIELD = 4


def attractor_of_rows(start, rows, row_state, row_ptr, successor, lower, upper):
    """The forced :func:`attractor` of ``start`` (a controller that wants to get there)
    through the model rows ``rows`` alone (sorted indices; the model's ``row_state``,
    ``row_ptr``, ``successor``, ``lower``, ``upper``): their entries are gathered and
    given a reverse index of their own, so that a state that joins walks only the
    incoming entries of these rows, not every incoming entry of the model (a strategy of
    the 100 x 100 benchmark grid's product, 9,900 of 236,403 rows: 8 ms a search on the
    model's index). Returns ``(mask, choice)``, ``choice`` in model rows."""
    if rows.size == 0:
        return start.copy(), np.full(start.size, -1, dtype=np.int64)
    ent, ptr = entries_of_rows(row_ptr, rows)
    entry_row = np.repeat(np.arange(rows.size), np.diff(ptr))
    arrays = (row_state[rows], ptr, successor[ent], lower[ent], upper[ent], entry_row)
    for a in arrays:
        a.setflags(write=False)  # as the model's: the kernels' compiled signatures
    states, ptr, succ, lo, up, entry_row = arrays
    index = incoming_index(succ, entry_row, states, lo, up, start.size)
    for a in index:
        a.setflags(write=False)
    every = np.ones(rows.size, dtype=np.bool_)
    x, choice, _ = attractor(start, every, states, ptr, succ, lo, up, *index, False, True)
    return x, np.where(choice >= 0, rows[np.maximum(choice, 0)], -1)


@numba.njit(cache=True, nogil=True)
def _outside_below_one(r, approx, x, row_ptr, successor, upper, terms, scratch) -> bool:
    """Whether the upper bounds of row ``r``'s entries outside ``x`` sum to less than 1,
    exactly (``approx``: their float sum, kept up to date by subtraction)."""
    a, b = row_ptr[r], row_ptr[r + 1]
    if not near_one(approx, b - a):
        return approx < 1.0
    terms[0] = -1.0
    k = 1
    for e in range(a, b):
        if not x[successor[e]]:
            terms[k] = upper[e]
            k += 1
    return sum_sign(terms, k, scratch) < 0


@numba.njit(cache=True, nogil=True, inline="always")
def _lead(r, s, every_row, led, left, x, choice, queue, tail):
    """Row ``r`` of state ``s`` leads into the set: ``s`` joins (queued) if that is
    enough; the new queue length."""
    led[r] = True
    left[s] -= 1
    if not every_row or left[s] == 0:
        x[s] = True
        choice[s] = r
        queue[tail] = s
        tail += 1
    return tail


@numba.njit(cache=True, nogil=True)
def counting_order(keys, n_keys):
    """Stable order of ``keys`` (integers in ``[0, n_keys)``) by counting sort, and the
    start of each key's run: ``(order, ptr)``."""
    ptr = np.zeros(n_keys + 1, dtype=np.int64)
    for k in keys:
        ptr[k + 1] += 1
    for i in range(n_keys):
        ptr[i + 1] += ptr[i]
    fill = ptr[:-1].copy()
    order = np.empty(keys.size, dtype=np.int64)
    for i in range(keys.size):
        k = keys[i]
        order[fill[k]] = i
        fill[k] += 1
    return order, ptr


@numba.njit(cache=True, nogil=True)
def forward_reach(sources, row_mask, state_ptr, row_ptr, successor, upper, allowed):
    """The ``allowed`` states reachable from ``sources & allowed`` along ``upper > 0``
    entries of the rows in ``row_mask`` of allowed states (breadth-first, a mask)."""
    seen = sources & allowed
    queue = np.flatnonzero(seen)
    tail = queue.size
    queue = np.concatenate((queue, np.empty(seen.size - tail, dtype=queue.dtype)))
    head = 0
    while head < tail:
        s = queue[head]
        head += 1
        for r in range(state_ptr[s], state_ptr[s + 1]):
            if not row_mask[r]:
                continue
            for e in range(row_ptr[r], row_ptr[r + 1]):
                t = successor[e]
                if upper[e] > 0.0 and allowed[t] and not seen[t]:
                    seen[t] = True
                    queue[tail] = t
                    tail += 1
    return seen


SPLIT_ENTRIES = 1_000_000
"""Models with at least this many entries write their reverse index (and products their
layout, :mod:`planner.imdp.product`) on two threads, each filling one half
(:func:`planner._util.threads.in_halves`): writes and first-touch page faults dominate
both, while the second core is idle before the synthesis splits. On the product of
``bench_vi.py`` (4.3M entries) the index takes 0.065-0.08 s instead of 0.11 s and the
product 0.044 s instead of 0.085 s (its row of every entry and row sums included)."""


def incoming_index(successor, entry_row, row_state, lower, upper, n_states):
    """The reverse index of the entries, grouped by successor (stable): ``(ptr, rows,
    states, lower, upper)``, positions ``ptr[s]:ptr[s + 1]`` for the entries into ``s``
    (``states``: the state of each entry's row; one counting pass, then scattering passes
    over the entries read in order, one per range of successors). ``rows`` and ``states``
    are 32-bit integers where every row and state index fits: the index is written once
    and read by every graph search, which on the product of ``bench_vi.py`` (4.3M
    entries) are bound by memory traffic; it took 56-76 ms instead of 65-79 ms to write,
    and the almost-sure region 56-57 ms instead of 60-63 ms to find."""
    ptr = _incoming_ptr(successor, n_states)
    narrow = max(row_state.size, n_states) <= np.iinfo(np.int32).max
    out = (_incoming_arrays32 if narrow else _incoming_arrays)(successor.size)
    fields = (successor, entry_row, row_state, lower, upper, ptr)
    if successor.size < SPLIT_ENTRIES:
        _incoming_scatter(*fields, 0, n_states, *out)
    else:
        in_halves(lambda first, last: _incoming_scatter(*fields, first, last, *out), ptr, "index")
    return (ptr, *out)


@numba.njit(cache=True, nogil=True)
def _incoming_ptr(successor, n_states):
    ptr = np.zeros(n_states + 1, dtype=np.int64)
    for t in successor:
        ptr[t + 1] += 1
    for i in range(n_states):
        ptr[i + 1] += ptr[i]
    return ptr


@numba.njit(cache=True, nogil=True)
def _incoming_arrays(k):
    # numba's allocator: numpy would advise huge pages for these (see entries.py)
    return np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k), np.empty(k)


@numba.njit(cache=True, nogil=True)
def _incoming_arrays32(k):
    return np.empty(k, np.int32), np.empty(k, np.int32), np.empty(k), np.empty(k)


@numba.njit(cache=True, nogil=True)
def _incoming_scatter(
    successor, entry_row, row_state, lower, upper, ptr, first, last, rows, states, lo, up
):
    """Write the entries whose successor lies in ``[first, last)`` to their places."""
    fill = ptr[:-1].copy()
    for e in range(successor.size):
        t = successor[e]
        if t < first or t >= last:
            continue
        k = fill[t]
        fill[t] = k + 1
        r = entry_row[e]
        rows[k] = r
        states[k] = row_state[r]
        lo[k] = lower[e]
        up[k] = upper[e]


@numba.njit(cache=True, nogil=True, inline="always")
def _put(heap, where, i, s):
    """State ``s`` at position ``i`` of the heap (and its position recorded)."""
    heap[i] = s
    where[s] = i


@numba.njit(cache=True, nogil=True)
def _sift_up(key, heap, where, i):
    """Move the state at heap position ``i`` of the max-heap ``heap`` (states, keyed by
    ``key``; ``where``: each state's position, -1 outside) up to its place."""
    s = heap[i]
    k = key[s]
    while i > 0 and key[heap[(i - 1) // 2]] < k:
        _put(heap, where, i, heap[(i - 1) // 2])
        i = (i - 1) // 2
    _put(heap, where, i, s)


@numba.njit(cache=True, nogil=True)
def _pop_top(key, heap, where, size):
    """Remove the top state of the max-heap (see :func:`_sift_up`); ``(state, new size)``."""
    top = heap[0]
    where[top] = -1
    size -= 1
    if size == 0:
        return top, size
    s = heap[size]
    k = key[s]
    i = 0
    while 2 * i + 1 < size:
        a = 2 * i + 1
        if a + 1 < size and key[heap[a + 1]] > key[heap[a]]:
            a += 1
        if key[heap[a]] <= k:
            break
        _put(heap, where, i, heap[a])
        i = a
    _put(heap, where, i, s)
    return top, size


@numba.njit(cache=True, nogil=True)
def surest_exit_choice(row_state, leak, n_states, inc_ptr, inc_row, inc_p):
    """One row per state, chosen so that the chain of the choice leaves the states from
    every state that can leave them, each row with a large one-step mass into the states
    placed before it.

    Rows ``r`` (of state ``row_state[r]``) are substochastic distributions over
    ``n_states`` states, ``leak[r]`` the mass leaving them; ``inc_ptr``/``inc_row``/
    ``inc_p`` list the entries by column. States are placed greedily, as in Dijkstra's
    search: next the state whose best row puts the most mass into the placed states plus
    its leak, with that row. Every chosen row has positive mass out or into states placed
    before it, so its chain leaves from every placed state; a state without a path out
    gets ``-1``. Returns the chosen row of every state.

    The unplaced states wait in a max-heap keyed by their best row's mass, raised in
    place when it grows (at most ``n_states`` entries, one pop per placed state)."""
    n_rows = row_state.size
    acc = leak.copy()
    best = np.zeros(n_states)
    choice = np.full(n_states, -1, dtype=np.int64)
    placed = np.zeros(n_states, dtype=np.bool_)
    heap = np.empty(n_states, dtype=np.int64)
    where = np.full(n_states, -1, dtype=np.int64)
    size = 0
    for r in range(n_rows):
        s = row_state[r]
        if acc[r] > best[s]:
            best[s] = acc[r]
            choice[s] = r
    for s in range(n_states):
        if choice[s] >= 0:
            heap[size] = s
            _sift_up(best, heap, where, size)
            size += 1
    while size > 0:
        t, size = _pop_top(best, heap, where, size)
        placed[t] = True
        for e in range(inc_ptr[t], inc_ptr[t + 1]):
            q = inc_row[e]
            s = row_state[q]
            if placed[s]:
                continue
            acc[q] += inc_p[e]
            if acc[q] > best[s]:
                best[s] = acc[q]
                choice[s] = q
                i = where[s]
                if i < 0:
                    i = size
                    heap[size] = s
                    size += 1
                _sift_up(best, heap, where, i)
    for s in range(n_states):
        if not placed[s]:
            choice[s] = -1
    return choice
