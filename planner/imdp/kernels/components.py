"""End components, compiled: strongly connected components (Tarjan), maximal end
components by iterated SCC decomposition, and the best exit of each component."""

from __future__ import annotations

import numba
import numpy as np

from planner.imdp.kernels.exact import near_one, sum_sign
from planner.imdp.kernels.rows import rounding_bound, scratch, sorted_value, threshold_value


@numba.njit(cache=True, nogil=True)
def _tarjan(n, active, adj_ptr, adj):
    """Strongly connected components (iterative Tarjan) of the graph ``adj`` restricted to
    the ``active`` states; ``comp[s] = -1`` for inactive states."""
    index = np.full(n, -1, dtype=np.int64)
    low = np.zeros(n, dtype=np.int64)
    on = np.zeros(n, dtype=np.bool_)
    comp = np.full(n, -1, dtype=np.int64)
    stack = np.empty(n, dtype=np.int64)
    call_v = np.empty(n, dtype=np.int64)
    call_i = np.empty(n, dtype=np.int64)
    sp = 0
    counter = 0
    n_comp = 0
    for root in range(n):
        if not active[root] or index[root] >= 0:
            continue
        depth = 0
        call_v[0] = root
        call_i[0] = adj_ptr[root]
        index[root] = counter
        low[root] = counter
        counter += 1
        stack[sp] = root
        sp += 1
        on[root] = True
        while depth >= 0:
            v = call_v[depth]
            i = call_i[depth]
            if i < adj_ptr[v + 1]:
                call_i[depth] = i + 1
                w = adj[i]
                if not active[w]:
                    continue
                if index[w] < 0:
                    index[w] = counter
                    low[w] = counter
                    counter += 1
                    stack[sp] = w
                    sp += 1
                    on[w] = True
                    depth += 1
                    call_v[depth] = w
                    call_i[depth] = adj_ptr[w]
                elif on[w] and index[w] < low[v]:
                    low[v] = index[w]
                continue
            if low[v] == index[v]:
                while True:
                    sp -= 1
                    w = stack[sp]
                    on[w] = False
                    comp[w] = n_comp
                    if w == v:
                        break
                n_comp += 1
            depth -= 1
            if depth >= 0:
                u = call_v[depth]
                if low[v] < low[u]:
                    low[u] = low[v]
    return comp


@numba.njit(cache=True, nogil=True)
def _row_stays(r, c, comp, alive, row_ptr, successor, lower, upper, optimistic):
    """Whether row ``r`` stays in component ``c`` (see
    :func:`maximal_end_components_kernel`)."""
    inside = 0.0
    for e in range(row_ptr[r], row_ptr[r + 1]):
        t = successor[e]
        same = alive[t] and comp[t] == c
        if optimistic:
            if same:
                inside += upper[e]
            elif lower[e] > 0.0:
                return False
        elif upper[e] > 0.0 and not same:
            return False
    if not optimistic:
        return True
    k = row_ptr[r + 1] - row_ptr[r]
    if not near_one(inside, k):
        return inside >= 1.0
    terms = np.empty(k + 1)
    terms[0] = -1.0
    n = 1
    for e in range(row_ptr[r], row_ptr[r + 1]):
        t = successor[e]
        if alive[t] and comp[t] == c:
            terms[n] = upper[e]
            n += 1
    return sum_sign(terms, n, np.empty(k + 1)) >= 0


@numba.njit(cache=True, nogil=True)
def maximal_end_components_kernel(
    n,
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
    rows_ok,
    states_ok,
    optimistic,
):
    """Maximal end components by iterated SCC decomposition (compiled).

    A row stays in the component of its state when (``optimistic=False``) every
    ``upper > 0`` successor lies in that component, or (``optimistic``) no ``lower > 0``
    successor leaves it and its ``upper`` bounds inside sum to at least 1 (exactly). Edges of
    the graph: the ``upper > 0`` entries of the rows kept, into live states. Components
    are refined one at a time (a work list): drop the rows that leave the component and,
    in a cascade through the incoming entries, the states left without rows and the rows
    that then leave; if anything was dropped, split the rest into its SCCs and refine
    those. Each round costs the size of the component it refines. A part of a split from
    which nothing is dropped is a maximal end component without a new decomposition: its
    rows and states, hence its edges, are those it was strongly connected by.

    ``inc_ptr``/``inc_row``/``inc_state``/``inc_lower``/``inc_upper``: the reverse index
    of the entries (the rows, their states and the bounds of the entries into each state,
    :meth:`planner.imdp.model.IMDP.reverse_index`; read in order, the states first). In
    the cascade a dropped state drops a row through an entry at once where that entry
    alone decides (``upper > 0``, or in the optimistic case ``lower > 0``); an entry with
    ``upper == 0`` changes nothing, and only an optimistic row that loses ``upper`` mass
    is checked again. Each state's successors enter its SCC graph once (repeated
    successors of its rows are skipped).

    Returns ``(comp, rows)``: component label per state (-1: in none; labels are not
    consecutive) and the rows kept.
    """
    n_rows = row_ptr.size - 1
    rows = rows_ok.copy()
    alive = states_ok.copy()
    for r in range(n_rows):
        if rows[r] and not alive[row_state[r]]:
            rows[r] = False
    n_live = np.zeros(n, dtype=np.int64)
    for r in range(n_rows):
        if rows[r]:
            n_live[row_state[r]] += 1
    for s in range(n):
        if alive[s] and n_live[s] == 0:
            alive[s] = False
    # rows of every state
    st_ptr = np.zeros(n + 1, dtype=np.int64)
    for r in range(n_rows):
        st_ptr[row_state[r] + 1] += 1
    for s in range(n):
        st_ptr[s + 1] += st_ptr[s]
    comp = np.full(n, -1, dtype=np.int64)
    for s in range(n):
        if alive[s]:
            comp[s] = 0
    next_label = 1
    work = np.empty(n + 1, dtype=np.int64)
    members = np.empty(n, dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    # the components to refine, as (label, list of states): states of a label are found
    # by scanning a per-label list built on the fly
    label_head = np.full(n + 1, -1, dtype=np.int64)
    # labels given to the parts of a split: strongly connected when they were made
    is_scc = np.zeros(n + 1, dtype=np.bool_)
    nxt = np.full(n, -1, dtype=np.int64)
    cnt = 0
    for s in range(n - 1, -1, -1):
        if alive[s]:
            nxt[s] = label_head[0]
            label_head[0] = s
            cnt += 1
    top = 0
    if cnt:
        work[0] = 0
        top = 1
    local_index = np.full(n, -1, dtype=np.int64)
    seen = np.full(n, -1, dtype=np.int64)  # the last member that listed a successor
    tick = 0
    while top > 0:
        top -= 1
        c = work[top]
        # gather the members of c
        k = 0
        s = label_head[c]
        while s >= 0:
            if alive[s] and comp[s] == c:
                members[k] = s
                k += 1
            s = nxt[s]
        if k == 0:
            continue
        # drop rows that leave c, and cascade
        qt = 0
        dropped = False
        for i in range(k):
            s = members[i]
            for r in range(st_ptr[s], st_ptr[s + 1]):
                if rows[r] and not _row_stays(
                    r, c, comp, alive, row_ptr, successor, lower, upper, optimistic
                ):
                    rows[r] = False
                    dropped = True
                    n_live[s] -= 1
            if n_live[s] == 0 and alive[s]:
                alive[s] = False
                queue[qt] = s
                qt += 1
        qh = 0
        while qh < qt:
            t = queue[qh]
            qh += 1
            dropped = True
            for j in range(inc_ptr[t], inc_ptr[t + 1]):
                if inc_upper[j] <= 0.0:
                    continue
                s = inc_state[j]
                if not alive[s] or comp[s] != c:
                    continue
                r = inc_row[j]
                if not rows[r]:
                    continue
                if (
                    not optimistic
                    or inc_lower[j] > 0.0
                    or not _row_stays(r, c, comp, alive, row_ptr, successor, lower, upper, True)
                ):
                    rows[r] = False
                    n_live[s] -= 1
                    if n_live[s] == 0:
                        alive[s] = False
                        queue[qt] = s
                        qt += 1
        if is_scc[c] and not dropped:
            # every row and state kept: the graph is the one c was strongly connected in
            continue
        # the live members, and whether c is one SCC
        m = 0
        for i in range(k):
            if alive[members[i]]:
                members[m] = members[i]
                local_index[members[i]] = m
                m += 1
        if m == 0:
            continue
        # local graph and its SCCs
        # in one pass, into room for every entry of the live rows
        room = 0
        for i in range(m):
            s = members[i]
            for r in range(st_ptr[s], st_ptr[s + 1]):
                if rows[r]:
                    room += row_ptr[r + 1] - row_ptr[r]
        deg = np.zeros(m + 1, dtype=np.int64)
        adj = np.empty(room, dtype=np.int64)
        filled = 0
        for i in range(m):
            s = members[i]
            tick += 1
            for r in range(st_ptr[s], st_ptr[s + 1]):
                if rows[r]:
                    for e in range(row_ptr[r], row_ptr[r + 1]):
                        t = successor[e]
                        if upper[e] > 0.0 and alive[t] and comp[t] == c and seen[t] != tick:
                            seen[t] = tick
                            adj[filled] = local_index[t]
                            filled += 1
            deg[i + 1] = filled
        sub = _tarjan(m, np.ones(m, dtype=np.bool_), deg, adj)
        n_sub = sub.max() + 1
        for i in range(m):
            local_index[members[i]] = -1
        if n_sub == 1 and not dropped:
            continue  # c is a maximal end component
        # new labels for the parts; refine each
        base = next_label
        next_label += n_sub
        if next_label > label_head.size:
            grown = np.full(2 * next_label, -1, dtype=np.int64)
            grown[: label_head.size] = label_head
            label_head = grown
            grown_scc = np.zeros(2 * next_label, dtype=np.bool_)
            grown_scc[: is_scc.size] = is_scc
            is_scc = grown_scc
        is_scc[base:next_label] = True
        for i in range(m):
            s = members[i]
            lab = base + sub[i]
            comp[s] = lab
            nxt[s] = label_head[lab]
            label_head[lab] = s
        for j in range(n_sub):
            if top >= work.size:
                grown_w = np.empty(2 * work.size, dtype=np.int64)
                grown_w[:top] = work[:top]
                work = grown_w
            work[top] = base + j
            top += 1
    for s in range(n):
        if not alive[s]:
            comp[s] = -1
    for r in range(n_rows):
        if rows[r] and (not alive[row_state[r]]):
            rows[r] = False
    return comp, rows


@numba.njit(cache=True, nogil=True)
def component_exit_bound(
    exit_rows,
    exit_ptr,
    members,
    member_ptr,
    comps,
    row_ptr,
    remaining,
    succ,
    lower,
    gap,
    crit,
    v,
    adversary_minimizes,
    raise_values,
) -> None:
    """Per end component ``c`` of ``comps``: ``E_c = max`` of the adversary's expectation
    of ``v`` over its exit rows ``exit_rows[exit_ptr[c]:exit_ptr[c + 1]]`` (0 without
    exits), then ``v[s] = max(v[s], E_c)`` (``raise_values``) or ``min(v[s], E_c)`` for its
    members ``members[member_ptr[c]:member_ptr[c + 1]]``, in place (see
    :mod:`planner.imdp.certify` for when each is sound; raised values are lowered by the
    rounding bound of :func:`planner.imdp.kernels.rows.below` first)."""
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = scratch(row_ptr)
    width = idx.size
    for c in comps:
        best = 0.0
        for k in range(exit_ptr[c], exit_ptr[c + 1]):
            r = exit_rows[k]
            q = threshold_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit)
            if q != q:
                q = sorted_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys)
            if q > best:
                best = q
        low = best - rounding_bound(width)  # rows.below, for the longest row
        for k in range(member_ptr[c], member_ptr[c + 1]):
            s = members[k]
            if raise_values:
                if low > v[s]:
                    v[s] = low
            elif best < v[s]:
                v[s] = best
