"""Compiled (numba) kernels for the sequential parts of robust value iteration.

A Gauss-Seidel sweep is sequential by nature: every state's update reads the values that
the states before it in the sweep have just written. Array operations can only do that
layer by layer (Jacobi inside a layer); these kernels do it state by state.

Layout (built by :class:`ReachSweeper`): the free states in sweep order, their rows
(``state_rows[k]:state_rows[k + 1]`` are the rows of the ``k``-th state) and, per row, its
entries ``row_ptr[r]:row_ptr[r + 1]`` with successor, lower bound and gap ``u - l``.  Each row
remembers its critical successor (see :func:`_row_value`), so a row whose adversary
choice still stands costs one pass and no sorting.

The robust expectation of a row under the state-ordering adversary (Lahijanian et al. 2015):
with the successors sorted so that the adversary's preferred ones come first, every
successor gets its lower bound and the remaining mass ``1 - sum(l)`` is handed out in that
order, at most ``u_j - l_j`` each.
"""

from __future__ import annotations

import numba
import numpy as np

from planner.imdp.model import IMDP, first_of_runs
from planner.imdp.ordering import row_entries


@numba.njit(cache=True, nogil=True)
def _sorted_value(
    a: int, b: int, remaining: float, succ, lower, gap, v, sign: float, crit, r, idx, keys
):
    """The ordering adversary's expectation by sorting the row (an insertion sort into the
    scratch arrays ``idx``/``keys``); records the row's critical entry in ``crit[r]``."""
    n = b - a
    for i in range(n):
        k = sign * v[succ[a + i]]
        j = i - 1
        while j >= 0 and keys[j] > k:
            keys[j + 1] = keys[j]
            idx[j + 1] = idx[j]
            j -= 1
        keys[j + 1] = k
        idx[j + 1] = a + i
    left = remaining
    q = 0.0
    c = idx[n - 1]
    found = False
    for i in range(n):
        e = idx[i]
        add = gap[e] if gap[e] < left else left
        if add < 0.0:
            add = 0.0
        if not found and add < gap[e]:
            c = e
            found = True
        left -= add
        q += (lower[e] + add) * keys[i]
    crit[r] = c
    return sign * q


@numba.njit(cache=True, nogil=True, inline="always")
def _row_value(
    a: int, b: int, remaining: float, succ, lower, gap, v, sign: float, crit, r, idx, keys
):
    """The ordering adversary's ``sum_j p_j v[succ_j]`` over the entries ``a:b``.

    With keys ``k_j = sign * v[succ_j]`` (``sign = 1``: the minimising adversary) the
    adversary gives every successor its lower bound and the remaining mass
    ``rem = 1 - sum(l)`` to the smallest keys first. With ``t`` the key of the critical
    successor (where the handed-out gaps reach ``rem``) that is

        sum_j l_j k_j + rem t - sum_{k_j < t} (u_j - l_j) (t - k_j),

    valid exactly when ``G(< t) <= rem <= G(<= t)`` (``G``: summed gaps). The row's
    threshold from the last call is tried first (one pass, no sorting, no branches on the
    values); if the new values moved it, the row is sorted.
    """
    if remaining > 0.0:
        t = sign * v[succ[crit[r]]]
        lv = 0.0
        g_less = 0.0
        g_eq = 0.0
        short = 0.0
        for i in range(a, b):
            k = sign * v[succ[i]]
            g = gap[i]
            lv += lower[i] * k
            d = t - k
            below = d > 0.0
            g_less += g if below else 0.0
            short += g * d if below else 0.0
            g_eq += g if d == 0.0 else 0.0
        if g_less <= remaining and remaining <= g_less + g_eq:
            return sign * (lv + remaining * t - short)
    return _sorted_value(a, b, remaining, succ, lower, gap, v, sign, crit, r, idx, keys)


@numba.njit(cache=True, nogil=True)
def _scratch(row_ptr):
    """Scratch arrays for :func:`_sorted_value`, as long as the longest row."""
    width = 0
    for r in range(row_ptr.size - 1):
        width = max(width, row_ptr[r + 1] - row_ptr[r])
    return np.empty(width, dtype=np.int64), np.empty(width)


@numba.njit(cache=True, nogil=True)
def gauss_seidel_sweep(
    states,
    state_rows,
    row_ptr,
    remaining,
    succ,
    lower,
    gap,
    crit,
    v,
    best_row,
    full,
    maximize,
    adversary_minimizes,
) -> float:
    """One Gauss-Seidel sweep of ``V(s) <- max(V(s), opt_a min/max_p sum p V)`` over
    ``states`` in order, in place; returns ``max_s`` of the change.

    ``opt`` is max (``maximize``) or min over the state's rows; the adversary minimises
    (``adversary_minimizes``) or maximises. Each update reads the values written earlier in
    the same sweep. ``full``: every row is evaluated and ``best_row[k]`` records the optimal
    one; otherwise only the row ``best_row[k]`` is (a modified-policy-iteration sweep: for
    a maximising strategy its update is at most the full one). Iterating from below
    (``V_0 <= T(V_0)``) every update is at most the least fixed point, so the values stay a
    sound lower bound.
    """
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = _scratch(row_ptr)
    residual = 0.0
    for k in range(states.size):
        s = states[k]
        if full:
            lo = state_rows[k]
            hi = state_rows[k + 1]
        else:
            lo = best_row[k]
            hi = lo + 1
        best = -np.inf if maximize else np.inf
        arg = lo
        for r in range(lo, hi):
            q = _row_value(
                row_ptr[r],
                row_ptr[r + 1],
                remaining[r],
                succ,
                lower,
                gap,
                v,
                sign,
                crit,
                r,
                idx,
                keys,
            )
            if (q > best) if maximize else (q < best):
                best = q
                arg = r
        if full:
            best_row[k] = arg
        old = v[s]
        if best > old:
            v[s] = best
            if best - old > residual:
                residual = best - old
    return residual


_ROUNDING = 1e-15
"""Slack of :func:`upper_sweep`'s check for floating-point rounding."""


@numba.njit(cache=True, nogil=True)
def upper_sweep(
    states,
    state_rows,
    row_ptr,
    remaining,
    succ,
    lower,
    gap,
    crit,
    u,
    maximize,
    adversary_minimizes,
    raise_violations,
):
    """One Gauss-Seidel pass of ``U(s) <- T(U)(s)`` from above, in place, that only ever
    lowers ``U``: a state whose Bellman value exceeds ``U(s)`` keeps ``U(s)`` and counts as
    a violation (``raise_violations``: it takes the Bellman value, still counting as a
    violation; the pass is then a candidate's repair, not a bound). Returns
    ``(max decrease, violations)``.

    A value above ``U(s)`` by at most ``_ROUNDING`` (1e-15, floating-point noise of the
    row sums) keeps ``U(s)`` without counting.
    A pass with no violation certifies the final ``U`` as superharmonic, ``T(U) <= U``:
    each state's value was computed from values at least the final ones (they only
    decrease) and ``T`` is monotone. For reachability every superharmonic ``U`` (with the
    targets at 1) is at least the least fixed point, i.e. an upper bound of the values.
    """
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = _scratch(row_ptr)
    decrease = 0.0
    violations = 0
    for k in range(states.size):
        s = states[k]
        best = -np.inf if maximize else np.inf
        for r in range(state_rows[k], state_rows[k + 1]):
            q = _row_value(
                row_ptr[r],
                row_ptr[r + 1],
                remaining[r],
                succ,
                lower,
                gap,
                u,
                sign,
                crit,
                r,
                idx,
                keys,
            )
            if (q > best) if maximize else (q < best):
                best = q
        old = u[s]
        if best <= old:
            u[s] = best
            if old - best > decrease:
                decrease = old - best
        elif best > old + _ROUNDING:
            violations += 1
            if raise_violations:
                u[s] = best
    return decrease, violations


@numba.njit(cache=True, nogil=True)
def gather_rows(sel, row_ptr, remaining, succ, lower, gap, crit):
    """The rows ``sel`` of a layout as a new contiguous layout (crit re-based)."""
    new_ptr = np.zeros(sel.size + 1, dtype=np.int64)
    for i in range(sel.size):
        r = sel[i]
        new_ptr[i + 1] = new_ptr[i] + row_ptr[r + 1] - row_ptr[r]
    n = new_ptr[-1]
    succ2 = np.empty(n, dtype=np.int64)
    lower2 = np.empty(n)
    gap2 = np.empty(n)
    crit2 = np.empty(sel.size, dtype=np.int64)
    rem2 = np.empty(sel.size)
    for i in range(sel.size):
        r = sel[i]
        off = new_ptr[i] - row_ptr[r]
        for e in range(row_ptr[r], row_ptr[r + 1]):
            succ2[e + off] = succ[e]
            lower2[e + off] = lower[e]
            gap2[e + off] = gap[e]
        crit2[i] = crit[r] + off
        rem2[i] = remaining[r]
    return new_ptr, rem2, succ2, lower2, gap2, crit2


class ReachSweeper:
    """The compact, sweep-ordered layout of the free rows of a model, and its sweeps.

    Full sweeps evaluate every row and record each state's best row; light sweeps
    evaluate only those rows, from a contiguous copy made after the last full sweep (the
    best rows lie scattered in the full layout, which makes them slow to read).

    Args:
        model: the interval MDP.
        free_rows: the rows the strategy may use at the free states (sorted).
        sweep_key: ``(n_states,)`` sort key of the states; sweeps visit the free states in
            increasing key (ties by index).
        maximize: the strategy maximises (else minimises) over rows.
        adversary_minimizes: the adversary minimises (else maximises) the expectation.
    """

    def __init__(
        self,
        model: IMDP,
        free_rows: np.ndarray,
        sweep_key: np.ndarray,
        maximize: bool,
        adversary_minimizes: bool,
    ) -> None:
        m = model
        rs = m.row_state[free_rows]
        order = np.lexsort((free_rows, sweep_key[rs]))
        self._position = order
        rows = free_rows[order]
        self.rows = rows
        """The model row of every row of the layout."""
        rs = rs[order]
        first = first_of_runs(rs)
        self.states = rs[first].astype(np.int64)
        """The free states in sweep order."""
        self.state_rows = np.append(first, rows.size).astype(np.int64)
        ent = row_entries(m, rows)
        lens = m.row_ptr[rows + 1] - m.row_ptr[rows]
        self.row_ptr = np.concatenate(([0], np.cumsum(lens))).astype(np.int64)
        self.remaining = 1.0 - m.row_lower_sum[rows]
        self.succ = m.successor[ent].astype(np.int64)
        self.lower = m.lower[ent].astype(np.float64)
        self.gap = m.upper[ent] - self.lower
        self.crit = self.row_ptr[:-1].copy()
        self.crit_up = self.crit.copy()
        self.best_row = self.state_rows[:-1].copy()
        self.maximize = bool(maximize)
        self.adversary_minimizes = bool(adversary_minimizes)
        self._one_row = np.arange(self.states.size + 1, dtype=np.int64)
        self._light: tuple[np.ndarray, ...] | None = None
        self._light_rows = self.best_row

    def sweep(self, v: np.ndarray, full: bool = True) -> float:
        """One Gauss-Seidel sweep on ``v`` in place (see :func:`gauss_seidel_sweep`): all
        rows (``full``) or the best rows of the last full sweep."""
        if full or self._light is None:
            residual = gauss_seidel_sweep(
                self.states,
                self.state_rows,
                self.row_ptr,
                self.remaining,
                self.succ,
                self.lower,
                self.gap,
                self.crit,
                v,
                self.best_row,
                True,
                self.maximize,
                self.adversary_minimizes,
            )
            if self._light is None or not np.array_equal(self.best_row, self._light_rows):
                self._light_rows = self.best_row.copy()
                self._light = gather_rows(
                    self.best_row,
                    self.row_ptr,
                    self.remaining,
                    self.succ,
                    self.lower,
                    self.gap,
                    self.crit,
                )
            return float(residual)
        row_ptr, remaining, succ, lower, gap, crit = self._light
        return float(
            gauss_seidel_sweep(
                self.states,
                self._one_row,
                row_ptr,
                remaining,
                succ,
                lower,
                gap,
                crit,
                v,
                self._one_row,
                False,
                self.maximize,
                self.adversary_minimizes,
            )
        )

    def upper_pass(self, u: np.ndarray, raise_violations: bool = False) -> tuple[float, int]:
        """One pass of :func:`upper_sweep` on ``u`` in place (all rows):
        ``(max decrease, violations)``."""
        dec, bad = upper_sweep(
            self.states,
            self.state_rows,
            self.row_ptr,
            self.remaining,
            self.succ,
            self.lower,
            self.gap,
            self.crit_up,
            u,
            self.maximize,
            self.adversary_minimizes,
            raise_violations,
        )
        return float(dec), int(bad)

    def row_values(self, v: np.ndarray) -> np.ndarray:
        """The robust expectation of ``v`` for every free row, in the order of the
        ``free_rows`` given to the constructor."""
        q = all_row_values(
            self.row_ptr,
            self.remaining,
            self.succ,
            self.lower,
            self.gap,
            self.crit,
            v,
            self.adversary_minimizes,
        )
        out = np.empty_like(q)
        out[self._position] = q
        return out


@numba.njit(cache=True, nogil=True)
def robust_attractor(
    start,
    cand,
    row_state,
    row_ptr,
    successor,
    lower,
    upper,
    inc_ptr,
    inc_row,
    inc_lower,
    inc_upper,
    limit,
):
    """The robust attractor of ``start`` with the candidate rows ``cand`` (work list).

    A state joins when one of its candidate rows puts positive mass into the set under
    every adversary: an entry with ``lower > 0`` into the set, or an ``upper > 0`` entry
    into it while the upper bounds of the entries outside sum to less than ``limit``
    (``1 - tolerance``). Each state that joins updates only the rows with an entry into it,
    so the whole attractor costs ``O(entries of the candidate rows + their incoming
    lists)``. Returns ``(mask, choice)``: ``choice[s]`` is the row by which ``s`` joined
    (-1 for ``start`` and outside); a joining row only counts states that joined before.
    """
    n_rows = row_ptr.size - 1
    x = start.copy()
    choice = np.full(x.size, -1, dtype=np.int64)
    must = np.zeros(n_rows, dtype=np.bool_)
    touches = np.zeros(n_rows, dtype=np.bool_)
    outside_up = np.zeros(n_rows)
    queue = np.empty(x.size, dtype=np.int64)
    tail = 0
    for r in range(n_rows):
        if not cand[r]:
            continue
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
        if cand[r] and not x[s] and (must[r] or (touches[r] and outside_up[r] < limit)):
            x[s] = True
            choice[s] = r
            queue[tail] = s
            tail += 1
    head = 0
    while head < tail:
        t = queue[head]
        head += 1
        for k in range(inc_ptr[t], inc_ptr[t + 1]):
            r = inc_row[k]
            if not cand[r]:
                continue
            if inc_lower[k] > 0.0:
                must[r] = True
            if inc_upper[k] > 0.0:
                touches[r] = True
            outside_up[r] -= inc_upper[k]
            s = row_state[r]
            if not x[s] and (must[r] or (touches[r] and outside_up[r] < limit)):
                x[s] = True
                choice[s] = r
                queue[tail] = s
                tail += 1
    return x, choice


@numba.njit(cache=True, nogil=True)
def rows_staying_in(u, rows, row_state, row_ptr, successor, upper, exclude):
    """Rows of ``rows`` at states of ``u`` outside ``exclude`` whose every ``upper > 0``
    successor lies in ``u``."""
    n_rows = row_ptr.size - 1
    out = np.zeros(n_rows, dtype=np.bool_)
    for r in range(n_rows):
        s = row_state[r]
        if not rows[r] or not u[s] or exclude[s]:
            continue
        ok = True
        for e in range(row_ptr[r], row_ptr[r + 1]):
            if upper[e] > 0.0 and not u[successor[e]]:
                ok = False
                break
        out[r] = ok
    return out


@numba.njit(cache=True, nogil=True)
def all_row_values(row_ptr, remaining, succ, lower, gap, crit, v, adversary_minimizes):
    """The adversary's expectation of ``v`` for every row of the layout."""
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = _scratch(row_ptr)
    out = np.empty(row_ptr.size - 1)
    for r in range(row_ptr.size - 1):
        out[r] = _row_value(
            row_ptr[r],
            row_ptr[r + 1],
            remaining[r],
            succ,
            lower,
            gap,
            v,
            sign,
            crit,
            r,
            idx,
            keys,
        )
    return out


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
def backward_distance(sources, row_mask, row_state, inc_ptr, inc_row, inc_upper):
    """Breadth-first number of hops from each state to ``sources`` along ``upper > 0``
    entries of the rows in ``row_mask`` (``inf`` where no path)."""
    dist = np.full(sources.size, np.inf)
    queue = np.empty(sources.size, dtype=np.int64)
    tail = 0
    for s in range(sources.size):
        if sources[s]:
            dist[s] = 0.0
            queue[tail] = s
            tail += 1
    head = 0
    while head < tail:
        t = queue[head]
        head += 1
        for k in range(inc_ptr[t], inc_ptr[t + 1]):
            r = inc_row[k]
            if not row_mask[r] or inc_upper[k] <= 0.0:
                continue
            s = row_state[r]
            if dist[s] == np.inf:
                dist[s] = dist[t] + 1.0
                queue[tail] = s
                tail += 1
    return dist


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
def _row_stays(r, c, comp, alive, row_ptr, successor, lower, upper, optimistic, limit):
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
    return inside >= limit if optimistic else True


@numba.njit(cache=True, nogil=True)
def maximal_end_components_kernel(
    n, row_state, row_ptr, successor, lower, upper, rows_ok, states_ok, optimistic, limit
):
    """Maximal end components by iterated SCC decomposition (compiled).

    A row stays in the component of its state when (``optimistic=False``) every
    ``upper > 0`` successor lies in that component, or (``optimistic``) no ``lower > 0``
    successor leaves it and its ``upper`` bounds inside sum to at least ``limit``. Edges of
    the graph: the ``upper > 0`` entries of the rows kept, into live states. Components
    are refined one at a time (a work list): drop the rows that leave the component and,
    in a cascade through the incoming entries, the states left without rows and the rows
    that then leave; if anything was dropped, split the rest into its SCCs and refine
    those. Each round costs the size of the component it refines.

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
    # reverse index of the entries (incoming per state)
    inc_ptr = np.zeros(n + 1, dtype=np.int64)
    for e in range(successor.size):
        inc_ptr[successor[e] + 1] += 1
    for s in range(n):
        inc_ptr[s + 1] += inc_ptr[s]
    fill = inc_ptr[:-1].copy()
    inc_row = np.empty(successor.size, dtype=np.int64)
    erow = np.empty(successor.size, dtype=np.int64)
    for r in range(n_rows):
        for e in range(row_ptr[r], row_ptr[r + 1]):
            erow[e] = r
    for e in range(successor.size):
        t = successor[e]
        inc_row[fill[t]] = erow[e]
        fill[t] += 1
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
                    r, c, comp, alive, row_ptr, successor, lower, upper, optimistic, limit
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
                r = inc_row[j]
                if not rows[r]:
                    continue
                s = row_state[r]
                if not alive[s] or comp[s] != c:
                    continue
                if not _row_stays(
                    r, c, comp, alive, row_ptr, successor, lower, upper, optimistic, limit
                ):
                    rows[r] = False
                    n_live[s] -= 1
                    if n_live[s] == 0:
                        alive[s] = False
                        queue[qt] = s
                        qt += 1
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
        deg = np.zeros(m + 1, dtype=np.int64)
        for i in range(m):
            s = members[i]
            for r in range(st_ptr[s], st_ptr[s + 1]):
                if rows[r]:
                    for e in range(row_ptr[r], row_ptr[r + 1]):
                        t = successor[e]
                        if upper[e] > 0.0 and alive[t] and comp[t] == c:
                            deg[i + 1] += 1
        for i in range(m):
            deg[i + 1] += deg[i]
        pos = deg[:-1].copy()
        adj = np.empty(deg[m], dtype=np.int64)
        for i in range(m):
            s = members[i]
            for r in range(st_ptr[s], st_ptr[s + 1]):
                if rows[r]:
                    for e in range(row_ptr[r], row_ptr[r + 1]):
                        t = successor[e]
                        if upper[e] > 0.0 and alive[t] and comp[t] == c:
                            adj[pos[i]] = local_index[t]
                            pos[i] += 1
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
def prune_kernel(
    removed, rows_ok, row_state, row_ptr, successor, upper, inc_ptr, inc_row, inc_upper
):
    """Remove the rows that may (``upper > 0``) enter a removed state and the states left
    without rows, in a cascade through the incoming entries (Jiang et al. 2023, Alg. 1):
    ``(removed states, rows kept)``."""
    n = removed.size
    n_rows = row_ptr.size - 1
    bad = removed.copy()
    rows = rows_ok.copy()
    live = np.zeros(n, dtype=np.int64)
    for r in range(n_rows):
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
    queue = np.empty(n, dtype=np.int64)
    tail = 0
    for s in range(n):
        if not bad[s] and live[s] == 0:
            bad[s] = True
            queue[tail] = s
            tail += 1
    head = 0
    while head < tail:
        t = queue[head]
        head += 1
        for k in range(inc_ptr[t], inc_ptr[t + 1]):
            r = inc_row[k]
            if rows[r] and inc_upper[k] > 0.0:
                rows[r] = False
                s = row_state[r]
                live[s] -= 1
                if live[s] == 0 and not bad[s]:
                    bad[s] = True
                    queue[tail] = s
                    tail += 1
    return bad, rows


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
    :mod:`planner.imdp.certify` for when each is sound)."""
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = _scratch(row_ptr)
    for c in comps:
        best = 0.0
        for k in range(exit_ptr[c], exit_ptr[c + 1]):
            r = exit_rows[k]
            q = _row_value(
                row_ptr[r],
                row_ptr[r + 1],
                remaining[r],
                succ,
                lower,
                gap,
                v,
                sign,
                crit,
                r,
                idx,
                keys,
            )
            if q > best:
                best = q
        for k in range(member_ptr[c], member_ptr[c + 1]):
            s = members[k]
            if raise_values:
                if best > v[s]:
                    v[s] = best
            elif best < v[s]:
                v[s] = best
