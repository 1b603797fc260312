"""The robust expectation of one row under the state-ordering adversary (Lahijanian et
al. 2015), compiled: with the successors sorted so that the adversary's preferred ones
come first, every successor gets its lower bound and the remaining mass ``1 - sum(l)`` is
handed out in that order, at most ``u_j - l_j`` each.

Layout: per row its entries ``row_ptr[r]:row_ptr[r + 1]`` with successor, lower bound and
gap ``u - l``, and its critical successor ``crit[r]`` (see :func:`threshold_value`), so a
row whose adversary choice still stands costs one pass and no sorting; where it moved,
:func:`sorted_value` sorts the row.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def threshold_value(r: int, row_ptr, remaining, succ, lower, gap, v, sign: float, crit) -> float:
    """The ordering adversary's ``sum_j p_j v[succ_j]`` over the entries
    ``row_ptr[r]:row_ptr[r + 1]`` of row ``r`` (``remaining[r] = 1 - sum(l)``) if the
    row's critical successor from the last call still stands, else ``nan`` (then
    :func:`sorted_value` sorts the row).

    With keys ``k_j = sign * v[succ_j]`` (``sign = 1``: the minimising adversary) the
    adversary gives every successor its lower bound and the remaining mass
    ``rem = 1 - sum(l)`` to the smallest keys first. With ``t`` the key of the critical
    successor (where the handed-out gaps reach ``rem``) that is

        sum_j l_j k_j + rem t - sum_{k_j < t} (u_j - l_j) (t - k_j),

    valid exactly when ``G(< t) <= rem <= G(<= t)`` (``G``: summed gaps): one pass, no
    sorting, no branches on the values.

    The hot loops call this and :func:`sorted_value` themselves (``q =
    threshold_value(...)``, then ``if q != q: q = sorted_value(...)``), and this function
    has one exit: inlined into a loop, a helper that held the sorting call, or returned
    early, ran the loops three times slower (47 ms, or 37 ms, against 17 ms for the 4.6M
    entries of the random benchmark model's free rows; numba then kept the reference
    counts of the array arguments per call).
    """
    a = row_ptr[r]
    b = row_ptr[r + 1]
    rem = remaining[r]
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
    holds = rem > 0.0 and g_less <= rem and rem <= g_less + g_eq
    return sign * (lv + rem * t - short) if holds else np.nan


@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
def feasible_bound(r: int, row_ptr, remaining, succ, lower, gap, v, crit) -> float:
    """An expectation at least row ``r``'s value under the minimising adversary, for a row
    whose critical successor moved (:func:`threshold_value` returned ``nan``), in one pass
    and no sorting: that of a feasible distribution formed around the stale threshold
    ``t``. Where the successors below ``t`` can take more than the remaining mass
    ``rem = 1 - sum(l)``, it is spread over them in proportion to their gaps; else every
    successor up to ``t`` gets its upper bound and the rest is spread over those above
    ``t`` in proportion to their gaps; ``inf`` where neither is feasible, ``nan`` where
    the critical successor stands after all (then :func:`threshold_value` is exact). The
    adversary's minimum is below every feasible distribution's expectation; the sums are
    rounded by a few units in ``1e-16``, which callers cover with a margin."""
    rem = remaining[r]
    t = v[succ[crit[r]]]
    lv = 0.0
    g_less = 0.0
    g_eq = 0.0
    short = 0.0
    g_all = 0.0
    gk_all = 0.0
    for i in range(row_ptr[r], row_ptr[r + 1]):
        k = v[succ[i]]
        g = gap[i]
        lv += lower[i] * k
        d = t - k
        below = d > 0.0
        g_less += g if below else 0.0
        short += g * d if below else 0.0
        g_eq += g if d == 0.0 else 0.0
        g_all += g
        gk_all += g * k
    upto = t * g_less - short + t * g_eq  # sum of g k over the successors up to t
    g_more = g_all - g_less - g_eq
    if rem > 0.0 and g_less <= rem and rem <= g_less + g_eq:
        return np.nan  # the critical successor stands: threshold_value is exact
    if rem > 0.0 and rem <= g_less:
        return lv + rem * t - short * (rem / g_less)
    if rem > 0.0 and g_more > 0.0:
        return lv + upto + (rem - g_less - g_eq) * ((gk_all - upto) / g_more)
    return np.inf


@numba.njit(cache=True, nogil=True, inline="always")
def rounding_bound(k: int) -> float:
    """The rounding bound of :func:`below` for a row of ``k`` entries."""
    return (8 * k + 16) * 2.0**-53


@numba.njit(cache=True, nogil=True, inline="always")
def below(q: float, r: int, row_ptr) -> float:
    """``q``, a row value from :func:`threshold_value` or :func:`sorted_value` of values
    in ``[0, 1]``, lowered by a bound of its rounding, ``(8k + 16)`` units of roundoff for
    ``k`` entries: at most the exact value, so a value iterated from below with it stays a
    sound lower bound however long mass circulates. The bound holds for the sums added in
    any order and association (the sweeps are compiled with reassociation allowed, which
    lets the compiler split them into parallel partial sums): :func:`threshold_value` sums
    at most ``2k + 1`` terms (``l_j k_j``, ``rem t``, ``-g_j (t - k_j)``) of magnitudes
    summing to at most 3, within ``(2k) * 3`` units; the products and differences add 4
    and the precomputed ``rem = 1 - sum(l)`` ``k`` (:func:`sorted_value` sums ``k``
    products of magnitudes summing to at most 1 after ``k`` subtractions from ``rem``).
    The loss adds up only along the chosen rows: about 2e-14 per step of an optimal
    strategy's expected stay."""
    return q - rounding_bound(row_ptr[r + 1] - row_ptr[r])


@numba.njit(cache=True, nogil=True, inline="always")
def sort_entries(a: int, n: int, succ, v, sign: float, idx, keys) -> None:
    """Stable sort of the entries ``a:a + n`` by the key ``sign * v[succ]`` into the
    scratch arrays: ``idx[:n]`` the entries, ``keys[:n]`` their keys, ascending
    (``keys[n:2n]`` holds the keys in entry order). Each entry goes to its rank, the
    number of entries with a smaller key or an equal one before it: ``n^2`` compares and
    adds without a branch on the keys, where an insertion sort mispredicts its branches
    (on the random 100k-state benchmark model's rows of 9 entries a row sorted and
    evaluated took 145 ns instead of 205 ns)."""
    for i in range(n):
        keys[n + i] = sign * v[succ[a + i]]
    for i in range(n):
        k = keys[n + i]
        rank = 0
        for j in range(i):
            rank += keys[n + j] <= k
        for j in range(i + 1, n):
            rank += keys[n + j] < k
        idx[rank] = a + i
        keys[rank] = k


@numba.njit(cache=True, nogil=True)
def sorted_value(r: int, row_ptr, remaining, succ, lower, gap, v, sign: float, crit, idx, keys):
    """Row ``r``'s value by sorting it (an insertion sort into the scratch arrays
    ``idx``/``keys``), its critical entry recorded in ``crit[r]`` for
    :func:`threshold_value`. The value returned is ``threshold_value``'s at that entry
    (where its condition holds, as it does but at the edges of rounding), so that a row's
    value in a kernel compiled like this one (without reassociation) does not depend on
    whether the row was sorted or its stored critical entry still stood: skipping rows,
    which leaves theirs stale, changes no value computed after, to the last bit (kernels
    compiled with reassociation evaluate ``threshold_value`` again themselves,
    :func:`planner.imdp.kernels.gauss_seidel.gauss_seidel_sweep`)."""
    a = row_ptr[r]
    n = row_ptr[r + 1] - a
    sort_entries(a, n, succ, v, sign, idx, keys)
    left = remaining[r]
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
    again = threshold_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit)
    return again if again == again else sign * q


@numba.njit(cache=True, nogil=True)
def sort_critical(r: int, row_ptr, remaining, succ, gap, v, sign: float, crit, idx, keys) -> None:
    """Row ``r``'s critical entry into ``crit[r]`` by sorting it, the one
    :func:`sorted_value` records, without summing the row: for kernels that evaluate the
    row by :func:`threshold_value` at that entry next (and by ``sorted_value`` only where
    that fails at the edges of rounding), one pass over the row and the sorted sum fewer
    per sorted row (on the random 100k-state benchmark model the early full sweeps, which
    sort most rows, took 4-14 % less). Taking the entries in order one least key at a
    time, until the remaining mass runs out, instead of the rank sort was slower there
    (the adversary's mass runs out after about a third of the row)."""
    a = row_ptr[r]
    n = row_ptr[r + 1] - a
    sort_entries(a, n, succ, v, sign, idx, keys)
    left = remaining[r]
    c = idx[n - 1]
    for i in range(n):
        e = idx[i]
        add = gap[e] if gap[e] < left else left
        if add < 0.0:
            add = 0.0
        if add < gap[e]:
            c = e
            break
        left -= add
    crit[r] = c


@numba.njit(cache=True, nogil=True)
def scratch(row_ptr):
    """Scratch arrays for :func:`sorted_value`: entries as many as the longest row has,
    keys twice as many (:func:`sort_entries`)."""
    width = longest_row(row_ptr)
    return np.empty(width, dtype=np.int64), np.empty(2 * width)


@numba.njit(cache=True, nogil=True)
def longest_row(row_ptr) -> int:
    """The most entries of a row."""
    width = 0
    for r in range(row_ptr.size - 1):
        width = max(width, row_ptr[r + 1] - row_ptr[r])
    return width


@numba.njit(cache=True, nogil=True)
def all_row_values(
    first, last, out, row_ptr, remaining, succ, lower, gap, crit, v, adversary_minimizes
) -> None:
    """The adversary's expectation of ``v`` for the rows ``first:last`` of the layout, into
    ``out`` (their critical successors updated)."""
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = scratch(row_ptr)
    for r in range(first, last):
        q = threshold_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit)
        if q != q:
            q = sorted_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys)
        out[r] = q


@numba.njit(cache=True, nogil=True)
def row_distributions(sel, row_ptr, remaining, succ, lower, gap, crit, v, adversary_minimizes):
    """The adversary's distributions at ``v`` of the layout rows ``sel``, in that order, as
    CSR arrays ``(ptr, successors, probabilities)``: the successors with keys below the
    critical one's (see :func:`threshold_value`) get their upper bounds, those tied with it
    the rest of ``rem`` in entry order, the others their lower bounds; the same
    distribution as the ordering adversary's
    (:class:`planner.imdp.ordering.OrderingAdversary`) up to the order among ties and the
    rounding of the sums, without sorting the rows that still stand. ``crit`` is updated
    where a row's critical successor moved."""
    sign = 1.0 if adversary_minimizes else -1.0
    idx, keys = scratch(row_ptr)
    ptr = np.zeros(sel.size + 1, dtype=np.int64)
    for i in range(sel.size):
        ptr[i + 1] = ptr[i] + row_ptr[sel[i] + 1] - row_ptr[sel[i]]
    out_succ = np.empty(ptr[-1], dtype=np.int64)
    prob = np.empty(ptr[-1])
    for j in range(sel.size):
        r = sel[j]
        a = row_ptr[r]
        off = ptr[j] - a
        q = threshold_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit)
        if q != q:
            sorted_value(r, row_ptr, remaining, succ, lower, gap, v, sign, crit, idx, keys)
        t = sign * v[succ[crit[r]]]
        left = remaining[r]
        for i in range(a, row_ptr[r + 1]):
            k = sign * v[succ[i]]
            keys[i - a] = k
            if k < t:
                left -= gap[i]
        for i in range(a, row_ptr[r + 1]):
            k = keys[i - a]
            add = 0.0
            if k < t:
                add = gap[i]
            elif k == t and left > 0.0:
                add = gap[i] if gap[i] < left else left
                left -= add
            prob[i + off] = lower[i] + add
            out_succ[i + off] = succ[i]
    return ptr, out_succ, prob


@numba.njit(cache=True, nogil=True)
def fill_layout(first, last, sel, model_ptr, successor, lower, upper, ptr, succ, low, gap):
    """The entries of the model rows ``sel[first:last]`` into a layout with row pointers
    ``ptr``, in place: successor, lower bound and gap ``upper - lower`` (the sweeps'
    layout, gathered in one pass without an index of the entries)."""
    for i in range(first, last):
        r = sel[i]
        off = ptr[i] - model_ptr[r]
        for e in range(model_ptr[r], model_ptr[r + 1]):
            succ[e + off] = successor[e]
            low[e + off] = lower[e]
            gap[e + off] = upper[e] - lower[e]


NO_LAYOUT = (
    np.zeros(1, dtype=np.int64),
    np.empty(0),
    np.empty(0, dtype=np.int64),
    np.empty(0),
    np.empty(0),
    np.empty(0, dtype=np.int64),
)
"""A contiguous layout of no rows, ``(ptr, remaining, succ, lower, gap, crit)``: where a
kernel takes a light copy, none."""


def gather_rows(sel, row_ptr, remaining, succ, lower, gap, crit):
    """The rows ``sel`` of a layout as a new contiguous layout (crit re-based)."""
    slots = np.full(sel.size, -1, dtype=np.int64)
    # no old copy; its successors of the layout's integer type, as the compiled
    # regather_rows reads either array through one variable
    none = (NO_LAYOUT[0], NO_LAYOUT[1], succ[:0], NO_LAYOUT[3], NO_LAYOUT[4], NO_LAYOUT[5])
    return regather_rows(sel, slots, none, row_ptr, remaining, succ, lower, gap, crit)


@numba.njit(cache=True, nogil=True)
def regather_rows(sel, slots, light, row_ptr, remaining, succ, lower, gap, crit):
    """:func:`gather_rows` of the rows ``sel`` where ``light`` is a contiguous layout whose
    slot ``k`` holds the row ``slots[k]`` (``-1``: none): a slot that already holds its row
    is copied from there, in one sequential pass, and only the others from the layout's
    scattered rows (after a full sweep that could not copy a best row of another length
    into its slot)."""
    o_ptr, o_rem, o_succ, o_lower, o_gap, o_crit = light
    new_ptr = np.zeros(sel.size + 1, dtype=np.int64)
    for i in range(sel.size):
        r = sel[i]
        new_ptr[i + 1] = new_ptr[i] + row_ptr[r + 1] - row_ptr[r]
    n = new_ptr[-1]
    succ2 = np.empty(n, dtype=succ.dtype)
    lower2 = np.empty(n)
    gap2 = np.empty(n)
    crit2 = np.empty(sel.size, dtype=np.int64)
    rem2 = np.empty(sel.size)
    for i in range(sel.size):
        r = sel[i]
        if slots[i] == r:
            s_succ, s_lower, s_gap, first, last = o_succ, o_lower, o_gap, o_ptr[i], o_ptr[i + 1]
            c, rem2[i] = o_crit[i], o_rem[i]
        else:
            s_succ, s_lower, s_gap, first, last = succ, lower, gap, row_ptr[r], row_ptr[r + 1]
            c, rem2[i] = crit[r], remaining[r]
        off = new_ptr[i] - first
        for e in range(first, last):
            succ2[e + off] = s_succ[e]
            lower2[e + off] = s_lower[e]
            gap2[e + off] = s_gap[e]
        crit2[i] = c + off
    return new_ptr, rem2, succ2, lower2, gap2, crit2


def empty_slots(sel, row_ptr, succ_dtype) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    """A contiguous layout with one slot per row of ``sel`` (its length), unfilled, and its
    index of rows, ``-1`` everywhere (no slot holds a row yet): the light copy before the
    first full sweep fills it (:func:`planner.imdp.kernels.gauss_seidel.gauss_seidel_sweep`).
    ``succ_dtype``: the integer type of the layout's successors."""
    ptr = np.zeros(sel.size + 1, dtype=np.int64)
    np.cumsum(row_ptr[sel + 1] - row_ptr[sel], out=ptr[1:])
    n = int(ptr[-1])
    layout = (
        ptr,
        np.empty(sel.size),
        np.empty(n, dtype=succ_dtype),
        np.empty(n),
        np.empty(n),
        np.empty(sel.size, dtype=np.int64),
    )
    return layout, np.full(sel.size, -1, dtype=np.int64)


@numba.njit(cache=True, nogil=True)
def order_rows(todo, row_ptr, successor, lower, upper, remaining, keys, perm, prob, succ):
    """The ordering adversary's distribution of each row ``r`` in ``todo``, in place.

    ``perm[row_ptr[r]:row_ptr[r + 1]]`` lists the row's entries (indices into the model's
    ``successor``, ``lower``, ``upper``) in the adversary's order: it is insertion-sorted,
    from its current order and stably (ties keep their places), by increasing
    ``keys[successor]``. Then, in that order, ``prob = lower + clip(remaining - G, 0,
    upper - lower)`` with ``G`` the gaps ``upper - lower`` of the entries before
    (sequential sums), and ``succ`` the successors. A row whose order still stands costs
    one pass.
    """
    for i in range(todo.size):
        r = todo[i]
        a = row_ptr[r]
        b = row_ptr[r + 1]
        for j in range(a + 1, b):
            e = perm[j]
            k = keys[successor[e]]
            t = j - 1
            while t >= a and keys[successor[perm[t]]] > k:
                perm[t + 1] = perm[t]
                t -= 1
            perm[t + 1] = e
        rem = remaining[r]
        before = 0.0
        for j in range(a, b):
            e = perm[j]
            g = upper[e] - lower[e]
            add = rem - before
            if add > g:
                add = g
            if add < 0.0:
                add = 0.0
            prob[j] = lower[e] + add
            succ[j] = successor[e]
            before += g


@numba.njit(cache=True, nogil=True)
def unordered_rows(row_ptr, succ, keys, tol):
    """The rows whose successors ``succ[row_ptr[r]:row_ptr[r + 1]]`` are out of increasing
    ``keys`` order by more than ``tol`` somewhere (increasing row indices)."""
    out = np.empty(row_ptr.size - 1, dtype=np.int64)
    n = 0
    for r in range(row_ptr.size - 1):
        for j in range(row_ptr[r] + 1, row_ptr[r + 1]):
            if keys[succ[j - 1]] - keys[succ[j]] > tol:
                out[n] = r
                n += 1
                break
    return out[:n]


@numba.njit(cache=True, nogil=True)
def greedy_rows(q, seg, maximize, slack):
    """Per state (its rows ``seg[i]:seg[i + 1]`` of ``q``, the last run to the end) the
    first row of its best value, exactly, and whether any state has another row within
    ``slack`` of its best (``|q - best| <= slack``): one pass, for
    :func:`planner.imdp.strategy.strategy_rows`."""
    greedy = np.empty(seg.size, dtype=np.int64)
    tied = False
    for i in range(seg.size):
        a = seg[i]
        b = seg[i + 1] if i + 1 < seg.size else q.size
        arg = a
        for r in range(a + 1, b):
            if (q[r] > q[arg]) if maximize else (q[r] < q[arg]):
                arg = r
        greedy[i] = arg
        if not tied:
            near = 0
            for r in range(a, b):
                near += abs(q[r] - q[arg]) <= slack
            tied = near > 1
    return greedy, tied
