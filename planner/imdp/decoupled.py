"""Orthogonally decoupled interval MDPs (odIMDPs): transitions that are products of
per-axis interval distributions.

A row ``(s, a)`` has per-axis bins with intervals: ``x`` bins ``X_r`` with
``[l^x_b, u^x_b]`` and ``y`` bins ``Y_r`` with ``[l^y_b, u^y_b]``. The adversary picks one
distribution per axis inside its intervals, ``p^x`` and ``p^y`` (each summing to 1), and
the successor is the state ``map[b_x, b_y]`` of the landed bin pair, with probability
``p^x(b_x) p^y(b_y)``. On the grid the bins of an axis are the ``n`` columns plus *below*
and *above*, and a bin pair with either bin outside maps to the absorbing ``out`` state.
This is IntervalMDP.jl's orthogonally decoupled model; it fits the abstraction because the
landing noise and the error bounds are independent per axis, and it is tighter than the
product-interval IMDP (:func:`planner.intervals.transition_intervals`), whose adversary may
pick any joint distribution inside the products of the per-axis bounds.

**The robust Bellman operator is exact.** For values ``v``,

    min_{p^x, p^y} sum_{b_x, b_y} p^x(b_x) p^y(b_y) v(map[b_x, b_y])

is bilinear: for a fixed ``p^x`` it is linear in ``p^y``, minimised by the state-ordering
adversary on the induced values ``w(b_y) = sum_{b_x} p^x(b_x) v(map[b_x, b_y])``; that
minimum is a concave function of ``p^x`` (a minimum of linear functions), so its minimum
over the polytope of ``p^x`` is attained at a vertex. The operator therefore enumerates the
vertices of one axis's polytope (the axis with fewer bins; a vertex has every bin but one
at a bound, so there are at most ``k 2^(k-1)`` for ``k`` bins, a handful on the grid) and
orders the other. (Ordering both axes in a nested way, letting the inner distribution
depend on the outer bin, lets the adversary pick a different ``p^y`` per ``b_x``: a joint
distribution that is not a product, which only gives a lower bound.) The maximising
adversary is the same with maxima (a maximum of convex functions, again at a vertex).

A dynamic adversary that picks the pair anew at each step and may randomise can realise
every point of the convex hull of the product distributions; the values of reachability
games are the same (randomisation does not help in turn-based games), so value iteration
with this operator computes the game value. Reachability is solved by Gauss-Seidel sweeps
from below, certified from above like :func:`planner.imdp.solve.solve` (a candidate
``min(1, L + tolerance / 2)`` checked superharmonic, which bounds the least fixed point).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace

import numba
import numpy as np

from planner.automaton import RabinAutomaton
from planner.errors import ModelError, ProductError, SpecificationError
from planner.imdp.grid import ACTIONS, OUT_ACTION, GridWorld
from planner.imdp.model import BOUND_TOLERANCE, IMDP, first_of_runs
from planner.imdp.solve import (
    Problem,
    ReachAvoid,
    Solution,
    Specification,
    ValueIteration,
    solve,
)
from planner.intervals import TruncatedGaussianNoise, axis_bin_bounds

# --------------------------------------------------------------------------- kernels


@numba.njit(cache=True, nogil=True)
def _vertices(ptr, lo, up, rows, tol):
    """Vertices of ``{l <= p <= u, sum p = 1}`` for the given rows (CSR over the axis
    entries): ``(vptr, values)``, the vertices of row ``rows[k]`` being
    ``values[vptr[k] + i * len : ...]`` with ``len`` the row's length. A vertex has every
    coordinate but (at most) one at a bound; duplicates are dropped."""
    total = 0
    for k in range(rows.size):
        r = rows[k]
        n = ptr[r + 1] - ptr[r]
        total += n * (1 << (n - 1)) * n
    values = np.empty(total)
    vptr = np.zeros(rows.size + 1, dtype=np.int64)
    pos = 0
    for k in range(rows.size):
        r = rows[k]
        a = ptr[r]
        n = ptr[r + 1] - a
        start = pos
        for free in range(n):
            for mask in range(1 << (n - 1)):
                s = 0.0
                bit = 0
                for i in range(n):
                    if i == free:
                        continue
                    v = up[a + i] if (mask >> bit) & 1 else lo[a + i]
                    values[pos + i] = v
                    s += v
                    bit += 1
                pf = 1.0 - s
                if pf < lo[a + free] - tol or pf > up[a + free] + tol:
                    continue
                pf = min(max(pf, lo[a + free]), up[a + free])
                values[pos + free] = pf
                dup = False
                q = start
                while q < pos:
                    same = True
                    for i in range(n):
                        if abs(values[q + i] - values[pos + i]) > 1e-15:
                            same = False
                            break
                    if same:
                        dup = True
                        break
                    q += n
                if not dup:
                    pos += n
        vptr[k + 1] = pos
    return vptr, values[:pos]


@numba.njit(cache=True, nogil=True)
def _row_value(
    r,
    v,
    minimize,
    outer_x,
    optr,
    obin,
    vptr,
    vval,
    iptr,
    ibin,
    ilo,
    igap,
    irem,
    maps,
    row_map,
    w,
    idx,
    keys,
    pin,
):
    """The adversary's expectation of ``v`` for row ``r`` (see the module docstring):
    vertices of the outer axis (:func:`_row_value_at` each), the best of them."""
    n_out = optr[r + 1] - optr[r]
    sign = 1.0 if minimize else -1.0
    best = np.inf
    for vs in range(vptr[r], vptr[r + 1], n_out):
        q = _row_value_at(
            vs,
            r,
            v,
            sign,
            outer_x,
            optr,
            obin,
            vval,
            iptr,
            ibin,
            ilo,
            igap,
            irem,
            maps,
            row_map,
            w,
            idx,
            keys,
            pin,
        )
        if q < best:
            best = q
    return sign * best


@numba.njit(cache=True, nogil=True)
def _sweep(
    states,
    row_lo,
    row_hi,
    v,
    lower_side,
    maximize_rows,
    minimize_adv,
    outer_x,
    optr,
    obin,
    vptr,
    vval,
    iptr,
    ibin,
    ilo,
    igap,
    irem,
    maps,
    row_map,
    width,
):
    """One Gauss-Seidel pass over ``states``. From below (``lower_side``): ``V <- max(V,
    T(V))``, returns ``(max increase, 0)``. From above: ``V <- T(V)`` where that does not
    raise ``V`` (else a violation, see :func:`planner.imdp.kernels.upper_sweep`), returns
    ``(max decrease, violations)``."""
    w = np.empty(width)
    idx = np.empty(width, dtype=np.int64)
    keys = np.empty(width)
    pin = np.empty(width)
    change = 0.0
    bad = 0
    for k in range(states.size):
        s = states[k]
        best = -np.inf if maximize_rows else np.inf
        for r in range(row_lo[k], row_hi[k]):
            q = _row_value(
                r,
                v,
                minimize_adv,
                outer_x,
                optr,
                obin,
                vptr,
                vval,
                iptr,
                ibin,
                ilo,
                igap,
                irem,
                maps,
                row_map,
                w,
                idx,
                keys,
                pin,
            )
            if (q > best) if maximize_rows else (q < best):
                best = q
        old = v[s]
        if lower_side:
            if best > old:
                v[s] = best
                if best - old > change:
                    change = best - old
        elif best <= old:
            v[s] = best
            if old - best > change:
                change = old - best
        elif best > old + 1e-15:
            bad += 1
    return change, bad


@numba.njit(cache=True, nogil=True)
def _all_values(
    v,
    minimize,
    outer_x,
    optr,
    obin,
    vptr,
    vval,
    iptr,
    ibin,
    ilo,
    igap,
    irem,
    maps,
    row_map,
    width,
):
    """:func:`_row_value` of every row."""
    w = np.empty(width)
    idx = np.empty(width, dtype=np.int64)
    keys = np.empty(width)
    pin = np.empty(width)
    out = np.empty(row_map.size)
    for r in range(row_map.size):
        out[r] = _row_value(
            r,
            v,
            minimize,
            outer_x,
            optr,
            obin,
            vptr,
            vval,
            iptr,
            ibin,
            ilo,
            igap,
            irem,
            maps,
            row_map,
            w,
            idx,
            keys,
            pin,
        )
    return out


@numba.njit(cache=True, nogil=True)
def _chosen_distributions(
    rows,
    v,
    minimize,
    outer_x,
    optr,
    obin,
    vptr,
    vval,
    iptr,
    ibin,
    ilo,
    igap,
    irem,
    maps,
    row_map,
    width,
):
    """The adversary's optimal product distribution for each of ``rows`` at values ``v``
    (the vertex and inner order that :func:`_row_value` picks), as COO
    ``(row position, successor, probability)`` with repeated successors."""
    w = np.empty(width)
    idx = np.empty(width, dtype=np.int64)
    keys = np.empty(width)
    total = 0
    for k in range(rows.size):
        r = rows[k]
        total += (optr[r + 1] - optr[r]) * (iptr[r + 1] - iptr[r])
    out_r = np.empty(total, dtype=np.int64)
    out_s = np.empty(total, dtype=np.int64)
    out_p = np.empty(total)
    pos = 0
    pin = np.empty(width)
    for k in range(rows.size):
        r = rows[k]
        a = optr[r]
        n_out = optr[r + 1] - a
        ia = iptr[r]
        n_in = iptr[r + 1] - ia
        base = row_map[r]
        sign = 1.0 if minimize else -1.0
        best = np.inf
        best_vs = vptr[r]
        for vs in range(vptr[r], vptr[r + 1], n_out):
            q = _row_value_at(
                vs,
                r,
                v,
                sign,
                outer_x,
                optr,
                obin,
                vval,
                iptr,
                ibin,
                ilo,
                igap,
                irem,
                maps,
                row_map,
                w,
                idx,
                keys,
                pin,
            )
            if q < best:
                best = q
                best_vs = vs
        _row_value_at(
            best_vs,
            r,
            v,
            sign,
            outer_x,
            optr,
            obin,
            vval,
            iptr,
            ibin,
            ilo,
            igap,
            irem,
            maps,
            row_map,
            w,
            idx,
            keys,
            pin,
        )
        for i in range(n_out):
            for j in range(n_in):
                if outer_x[r]:
                    succ = maps[base, obin[a + i], ibin[ia + j]]
                else:
                    succ = maps[base, ibin[ia + j], obin[a + i]]
                out_r[pos] = k
                out_s[pos] = succ
                out_p[pos] = vval[best_vs + i] * pin[j]
                pos += 1
    return out_r, out_s, out_p


@numba.njit(cache=True, nogil=True)
def _row_value_at(
    vs,
    r,
    v,
    sign,
    outer_x,
    optr,
    obin,
    vval,
    iptr,
    ibin,
    ilo,
    igap,
    irem,
    maps,
    row_map,
    w,
    idx,
    keys,
    pin,
):
    """:func:`_row_value` for one outer vertex (at ``vval[vs:]``), the inner distribution
    written to ``pin`` (signed expectation returned)."""
    a = optr[r]
    n_out = optr[r + 1] - a
    ia = iptr[r]
    n_in = iptr[r + 1] - ia
    base = row_map[r]
    for j in range(n_in):
        acc = 0.0
        for i in range(n_out):
            p = vval[vs + i]
            if p == 0.0:
                continue
            if outer_x[r]:
                succ = maps[base, obin[a + i], ibin[ia + j]]
            else:
                succ = maps[base, ibin[ia + j], obin[a + i]]
            acc += p * v[succ]
        w[j] = sign * acc
    for j in range(n_in):
        k = w[j]
        h = j - 1
        while h >= 0 and keys[h] > k:
            keys[h + 1] = keys[h]
            idx[h + 1] = idx[h]
            h -= 1
        keys[h + 1] = k
        idx[h + 1] = j
    left = irem[r]
    q = 0.0
    for j in range(n_in):
        e = idx[j]
        add = igap[ia + e] if igap[ia + e] < left else left
        if add < 0.0:
            add = 0.0
        left -= add
        pin[e] = ilo[ia + e] + add
        q += pin[e] * keys[j]
    return q


# --------------------------------------------------------------------------- model


class DecoupledIMDP:
    """An orthogonally decoupled interval MDP (see the module docstring).

    Args:
        n_states: number of states.
        row_state, row_action: the (state, action) of every row, sorted by state then
            action (each state needs a row).
        x_ptr, x_bin, x_lower, x_upper: CSR of the ``x`` entries of the rows (bin index,
            bounds); ``y_ptr, y_bin, y_lower, y_upper`` likewise.
        maps: ``(n_maps, n_xbins, n_ybins)`` successor state of every bin pair.
        row_map: ``(n_rows,)`` the map each row uses.
        n_actions, labels, propositions, initial, action_names, tolerance: as for
            :class:`planner.imdp.model.IMDP`.

    Raises:
        ModelError: on unsorted rows, out-of-range indices, bounds outside ``[0, 1]``,
            ``lower > upper``, an axis row that does not bracket 1, or a state without rows.
    """

    def __init__(
        self,
        n_states: int,
        row_state: np.ndarray,
        row_action: np.ndarray,
        x_ptr: np.ndarray,
        x_bin: np.ndarray,
        x_lower: np.ndarray,
        x_upper: np.ndarray,
        y_ptr: np.ndarray,
        y_bin: np.ndarray,
        y_lower: np.ndarray,
        y_upper: np.ndarray,
        maps: np.ndarray,
        row_map: np.ndarray,
        *,
        n_actions: int,
        labels: Sequence[Iterable[str]] | None = None,
        propositions: Sequence[str] | None = None,
        label_matrix: np.ndarray | None = None,
        initial: Iterable[int] = (0,),
        action_names: Sequence[str] | None = None,
        tolerance: float = BOUND_TOLERANCE,
    ) -> None:
        n = int(n_states)
        self.n_states = n
        self.n_actions = int(n_actions)
        self.tolerance = float(tolerance)
        self.row_state = np.asarray(row_state, dtype=np.int64)
        self.row_action = np.asarray(row_action, dtype=np.int64)
        self.maps = np.asarray(maps, dtype=np.int64)
        self.row_map = np.asarray(row_map, dtype=np.int64)
        rs, ra = self.row_state, self.row_action
        key = rs * self.n_actions + ra
        if rs.size == 0 or np.any(np.diff(key) <= 0):
            raise ModelError("decoupled rows must be sorted by state then action, no repeats")
        if rs.min() < 0 or rs.max() >= n or ra.min() < 0 or ra.max() >= self.n_actions:
            raise ModelError("a decoupled row names a state or action out of range")
        if self.maps.ndim != 3 or self.maps.min() < 0 or self.maps.max() >= n:
            raise ModelError(f"maps must be (n_maps, nx, ny) state indices in [0, {n})")
        if self.row_map.shape != rs.shape or np.any(
            (self.row_map < 0) | (self.row_map >= self.maps.shape[0])
        ):
            raise ModelError("row_map must name a map for every row")
        self.axes = []
        for name, ptr, b, lo, up, size in (
            ("x", x_ptr, x_bin, x_lower, x_upper, self.maps.shape[1]),
            ("y", y_ptr, y_bin, y_lower, y_upper, self.maps.shape[2]),
        ):
            ptr = np.asarray(ptr, dtype=np.int64)
            b = np.asarray(b, dtype=np.int64)
            lo = np.asarray(lo, dtype=np.float64)
            up = np.asarray(up, dtype=np.float64)
            if ptr.shape != (rs.size + 1,) or ptr[0] != 0 or np.any(np.diff(ptr) < 1):
                raise ModelError(f"{name}_ptr must give every row at least one {name} bin")
            if b.size != ptr[-1] or b.min() < 0 or b.max() >= size:
                raise ModelError(f"{name} bins must be indices in [0, {size})")
            bad = ~np.isfinite(lo) | ~np.isfinite(up) | (lo < 0) | (up > 1) | (lo > up)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise ModelError(f"{name} entry {i}: bounds [{lo[i]}, {up[i]}] are not valid")
            s_lo = np.add.reduceat(lo, ptr[:-1])
            s_up = np.add.reduceat(up, ptr[:-1])
            bad = (s_lo > 1 + tolerance) | (s_up < 1 - tolerance)
            if bad.any():
                r = int(np.flatnonzero(bad)[0])
                raise ModelError(
                    f"state {rs[r]}, action {ra[r]}: the {name} bounds do not bracket 1 "
                    f"(sums {s_lo[r]:.12g}, {s_up[r]:.12g})"
                )
            self.axes.append((ptr, b, lo, up))
        counts = np.bincount(rs, minlength=n)
        if np.any(counts == 0):
            raise ModelError(f"state {int(np.flatnonzero(counts == 0)[0])} has no row")
        self.state_ptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        self.enabled = np.zeros((n, self.n_actions), dtype=bool)
        self.enabled[rs, ra] = True
        self.row_index = np.full((n, self.n_actions), -1, dtype=np.int64)
        self.row_index[rs, ra] = np.arange(rs.size)
        if label_matrix is not None:
            self.propositions = tuple(propositions or ())
            self.label_matrix = np.asarray(label_matrix, dtype=bool)
        else:
            sets = [frozenset(x) for x in labels] if labels is not None else [frozenset()] * n
            self.propositions = (
                tuple(propositions) if propositions else tuple(sorted(set().union(*sets)))
            )
            self.label_matrix = np.array(
                [[p in ls for p in self.propositions] for ls in sets], dtype=bool
            ).reshape(n, len(self.propositions))
        self.initial = np.unique(np.asarray(list(initial), dtype=np.int64))
        self.action_names = tuple(action_names or (f"a{i}" for i in range(self.n_actions)))
        self._prepare()

    @property
    def n_rows(self) -> int:
        return int(self.row_state.size)

    def states_labelled(self, name: str) -> np.ndarray:
        if name not in self.propositions:
            raise SpecificationError(f"label {name!r} is not among {self.propositions}")
        return self.label_matrix[:, self.propositions.index(name)].copy()

    def _prepare(self) -> None:
        """Per row: the outer axis (fewer bins), its vertices, the inner axis's gaps."""
        (xp, xb, xl, xu), (yp, yb, yl, yu) = self.axes
        nx, ny = np.diff(xp), np.diff(yp)
        outer_x = nx <= ny
        self.outer_x = outer_x
        n_rows = self.n_rows
        # outer / inner axes as per-row CSR (rows keep their own choice)
        o_len = np.where(outer_x, nx, ny)
        i_len = np.where(outer_x, ny, nx)
        self.optr = np.concatenate(([0], np.cumsum(o_len))).astype(np.int64)
        self.iptr = np.concatenate(([0], np.cumsum(i_len))).astype(np.int64)
        ob, ol, ou = (np.empty(self.optr[-1], t) for t in (np.int64, float, float))
        ib, il, iu = (np.empty(self.iptr[-1], t) for t in (np.int64, float, float))
        for sel, (op, obb, ol_, ou_), (ip, ibb, il_, iu_) in (
            (outer_x, (xp, xb, xl, xu), (yp, yb, yl, yu)),
            (~outer_x, (yp, yb, yl, yu), (xp, xb, xl, xu)),
        ):
            for r in np.flatnonzero(sel):
                a, b = self.optr[r], self.optr[r + 1]
                ob[a:b], ol[a:b], ou[a:b] = (arr[op[r] : op[r + 1]] for arr in (obb, ol_, ou_))
                a, b = self.iptr[r], self.iptr[r + 1]
                ib[a:b], il[a:b], iu[a:b] = (arr[ip[r] : ip[r + 1]] for arr in (ibb, il_, iu_))
        self.obin, self.ibin, self.ilo = ob, ib, il
        self.igap = iu - il
        self.irem = 1.0 - np.add.reduceat(il, self.iptr[:-1])
        self.vptr, self.vval = _vertices(
            self.optr, ol, ou, np.arange(n_rows, dtype=np.int64), self.tolerance
        )
        # vertex blocks per row: vptr counts values; the kernel steps by the row length
        self.width = int(max(np.max(i_len), 1))

    def successors(self) -> tuple[np.ndarray, np.ndarray]:
        """``(row, state)`` pairs of every possible successor (``upper > 0`` in both
        axes), deduplicated: the graph of the best case."""
        (xp, xb, _, xu), (yp, yb, _, yu) = self.axes
        rows, states = [], []
        for r in range(self.n_rows):
            bx = xb[xp[r] : xp[r + 1]][xu[xp[r] : xp[r + 1]] > 0]
            by = yb[yp[r] : yp[r + 1]][yu[yp[r] : yp[r + 1]] > 0]
            succ = np.unique(self.maps[self.row_map[r]][np.ix_(bx, by)])
            rows.append(np.full(succ.size, r))
            states.append(succ)
        return np.concatenate(rows), np.concatenate(states)

    def expectation(self, values: np.ndarray, minimize: bool = True) -> np.ndarray:
        """The adversary's (min or max) expectation of ``values`` for every row."""
        return _all_values(
            np.asarray(values, dtype=np.float64), minimize, *self._layout(), self.width
        )

    def _layout(self) -> tuple[np.ndarray, ...]:
        return (
            self.outer_x,
            self.optr,
            self.obin,
            self.vptr,
            self.vval,
            self.iptr,
            self.ibin,
            self.ilo,
            self.igap,
            self.irem,
            self.maps,
            self.row_map,
        )

    def __repr__(self) -> str:
        return f"DecoupledIMDP(states={self.n_states}, rows={self.n_rows})"


# --------------------------------------------------------------------------- solve


def _backward_reach(model: DecoupledIMDP, target: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """Breadth-first distance to ``target`` over possible successors, not through
    ``blocked`` states (``inf``: no path)."""
    rows, succ = model.successors()
    n = model.n_states
    order = np.argsort(succ, kind="stable")
    ptr = np.searchsorted(succ[order], np.arange(n + 1))
    pred_state = model.row_state[rows[order]]
    dist = np.full(n, np.inf)
    frontier = np.flatnonzero(target)
    dist[frontier] = 0.0
    d = 0.0
    while frontier.size:
        d += 1.0
        cand = np.concatenate([pred_state[ptr[t] : ptr[t + 1]] for t in frontier])
        cand = np.unique(cand)
        cand = cand[(dist[cand] == np.inf) & ~blocked[cand]]
        dist[cand] = d
        frontier = cand
    return dist


def solve_reach(
    model: DecoupledIMDP,
    target: np.ndarray,
    avoid: np.ndarray | None = None,
    pessimistic: bool = True,
    algorithm: ValueIteration | None = None,
) -> Solution:
    """Maximal probability of ``(!avoid) U target`` (worst case unless not
    ``pessimistic``) with its certified bracket (see the module docstring)."""
    alg = ValueIteration() if algorithm is None else algorithm
    m = model
    n = m.n_states
    target = np.asarray(target, dtype=bool)
    avoid = np.zeros(n, bool) if avoid is None else np.asarray(avoid, bool) & ~target
    dist = _backward_reach(m, target, avoid)
    zero = ~np.isfinite(dist) | avoid
    fixed = target | zero
    v = np.where(target, 1.0, 0.0)
    states = np.flatnonzero(~fixed)
    states = states[np.lexsort((states, dist[states]))]
    row_lo, row_hi = m.state_ptr[states], m.state_ptr[states + 1]
    layout = m._layout()

    def sweep(x: np.ndarray, lower_side: bool) -> tuple[float, int]:
        return _sweep(states, row_lo, row_hi, x, lower_side, True, pessimistic, *layout, m.width)

    it, residual, goal, upper, passes = 0, 0.0, alg.tolerance, None, 0
    tries = 0
    while states.size and it < alg.max_iterations:
        it += 1
        residual, _ = sweep(v, True)
        if alg.callback is not None:
            alg.callback(it, residual)
        if residual >= goal:
            continue
        if not alg.certified:
            break
        u = v.copy()
        u[states] = np.minimum(1.0, v[states] + alg.tolerance / 2)
        last = None
        for _ in range(8):
            passes += 1
            _, bad = sweep(u, False)
            if bad == 0 or (last is not None and bad >= last):
                break
            last = bad
        if bad == 0:
            upper = u
            break
        tries += 1
        if tries >= 6:
            break
        goal = max(goal / 8.0, 1e-15)
    if upper is None:
        upper = v.copy()
        upper[states] = 1.0
    q = m.expectation(v, minimize=pessimistic)
    best = np.maximum.reduceat(q, m.state_ptr[:-1])
    top = np.flatnonzero(q >= best[m.row_state] - 1e-12)
    top = top[first_of_runs(m.row_state[top])]
    strategy = np.full(n, -1, dtype=np.int64)
    strategy[m.row_state[top]] = m.row_action[top]
    strategy[fixed] = -1
    converged = (
        bool(np.max(upper - v, initial=0.0) < alg.tolerance)
        if alg.certified
        else bool(residual < alg.tolerance)
    )
    return Solution(
        values=v,
        strategy=strategy,
        residual=residual,
        iterations=it,
        converged=converged,
        fixed=fixed,
        lower=v.copy(),
        upper=upper,
        upper_sweeps=passes,
        _q=lambda: q,
    )


def _certify(
    m: DecoupledIMDP,
    states: np.ndarray,
    lower: np.ndarray,
    sol: Solution,
    pessimistic: bool,
    alg: ValueIteration,
) -> Solution | None:
    """The bracket ``[lower, min(1, lower + tolerance / 2)]`` if the upper end passes the
    superharmonic check (:func:`_sweep` from above), else ``None``."""
    order = states[np.lexsort((states,))]
    row_lo, row_hi = m.state_ptr[order], m.state_ptr[order + 1]
    u = lower.copy()
    u[order] = np.minimum(1.0, lower[order] + alg.tolerance / 2)
    for _ in range(8):
        _, bad = _sweep(order, row_lo, row_hi, u, False, True, pessimistic, *m._layout(), m.width)
        if bad == 0:
            return Solution(
                values=lower,
                strategy=sol.strategy,
                residual=sol.residual,
                iterations=sol.iterations,
                converged=bool(np.max(u - lower) < alg.tolerance),
                evaluations=1,
                fixed=sol.fixed,
                lower=lower,
                upper=u,
                upper_sweeps=sol.upper_sweeps,
            )
    return None


def expanded_size(model: DecoupledIMDP) -> int:
    """Entries :func:`expanded_imdp` would have (vertex pairs times the pair supports)."""
    m = model
    (xp, _, xl, xu), (yp, _, yl, yu) = m.axes
    rows = np.arange(m.n_rows, dtype=np.int64)
    nx = np.diff(_vertices(xp, xl, xu, rows, m.tolerance)[0]) // np.diff(xp)
    ny = np.diff(_vertices(yp, yl, yu, rows, m.tolerance)[0]) // np.diff(yp)
    return int(np.sum(nx * ny * (1 + np.diff(xp) * np.diff(yp))))


def expanded_imdp(model: DecoupledIMDP) -> tuple[IMDP, int]:
    """An interval MDP with the same reachability values: every row leads, with intervals
    ``[0, 1]``, to one auxiliary state per pair of per-axis vertices, which moves with that
    pair's product distribution (point intervals). The adversary's choice of weights is a
    choice among the vertex pairs (randomisation does not change reachability values), so
    the values on the first ``n_states`` states are the decoupled model's. Returns
    ``(model, n_states)``; the auxiliary states carry no labels."""
    m = model
    (xp, xb, xl, xu), (yp, yb, yl, yu) = m.axes
    rows = np.arange(m.n_rows, dtype=np.int64)
    xv_ptr, xv = _vertices(xp, xl, xu, rows, m.tolerance)
    yv_ptr, yv = _vertices(yp, yl, yu, rows, m.tolerance)
    n = m.n_states
    s_out, a_out, t_out, p_out = [], [], [], []
    aux = n
    for r in range(m.n_rows):
        bx, by = xb[xp[r] : xp[r + 1]], yb[yp[r] : yp[r + 1]]
        vx = xv[xv_ptr[r] : xv_ptr[r + 1]].reshape(-1, bx.size)
        vy = yv[yv_ptr[r] : yv_ptr[r + 1]].reshape(-1, by.size)
        succ = m.maps[m.row_map[r]][np.ix_(bx, by)].ravel()
        uniq, inv = np.unique(succ, return_inverse=True)
        k = vx.shape[0] * vy.shape[0]
        joint = (vx[:, None, :, None] * vy[None, :, None, :]).reshape(k, -1)
        dist = np.zeros((k, uniq.size))
        np.add.at(dist, (slice(None), inv), joint)
        ids = np.arange(aux, aux + k)
        aux += k
        s_out.append(np.full(k, m.row_state[r]))
        a_out.append(np.full(k, m.row_action[r]))
        t_out.append(ids)
        p_out.append(None)
        for j in range(k):
            keep = dist[j] > 0
            s_out.append(np.full(keep.sum(), ids[j]))
            a_out.append(np.zeros(keep.sum(), dtype=np.int64))
            t_out.append(uniq[keep])
            p_out.append(dist[j][keep])
    lo = np.concatenate(
        [np.zeros(t.size) if p is None else p for t, p in zip(t_out, p_out, strict=True)]
    )
    up = np.concatenate(
        [np.ones(t.size) if p is None else p for t, p in zip(t_out, p_out, strict=True)]
    )
    labels = np.zeros((aux, len(m.propositions)), dtype=bool)
    labels[:n] = m.label_matrix
    out = IMDP(
        aux,
        np.concatenate(s_out),
        np.concatenate(a_out),
        np.concatenate(t_out),
        lo,
        up,
        n_actions=m.n_actions,
        labels=[tuple(np.array(m.propositions)[row]) for row in labels],
        propositions=m.propositions,
        initial=m.initial,
        tolerance=max(m.tolerance, 1e-12),
    )
    return out, n


def strategy_iteration(
    model: DecoupledIMDP,
    states: np.ndarray,
    fixed_val: np.ndarray,
    start: np.ndarray,
    pessimistic: bool,
    rounds: int = 50,
) -> np.ndarray | None:
    """Exact values of the reachability game on ``states`` (the others held at
    ``fixed_val``) by strategy iteration (Hoffman-Karp): evaluate the strategy against the
    adversary's best response (adversary policy iteration on the exact operator's choices,
    each a sparse solve), switch rows that are strictly better, repeat. ``None`` when it
    does not settle within ``rounds``. The values are those of the last strategy (a lower
    bound of the value) and, when it settles, the value itself."""
    import scipy.sparse as sp

    from planner.imdp.evaluate import chain_reach

    m = model
    layout = m._layout()
    x = np.asarray(start, dtype=np.float64).copy()
    free = np.zeros(m.n_states, bool)
    free[states] = True

    def greedy(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = m.expectation(values, minimize=pessimistic)
        best = np.maximum.reduceat(q, m.state_ptr[:-1])
        top = np.flatnonzero(q >= best[m.row_state])
        return top[first_of_runs(m.row_state[top])], q

    choice, _ = greedy(x)
    choice = choice[free[m.row_state[choice]]]
    slack = 1e-13
    for _ in range(rounds):
        rows = choice
        for _ in range(rounds):
            r, t, p = _chosen_distributions(rows, x, pessimistic, *layout, m.width)
            mat = sp.csr_matrix((p, (r, t)), shape=(rows.size, m.n_states))
            y = chain_reach(mat, m.row_state[rows], np.where(free, 0.0, fixed_val))
            done = np.max(np.abs(y - x)) <= 1e-15
            x = y
            if done:
                break
        else:
            return None
        best, q = greedy(x)
        best = best[free[m.row_state[best]]]
        better = q[best] > q[rows] + slack
        if not better.any():
            return x
        choice = np.where(better, best, rows)
    return None


# --------------------------------------------------------------------------- product


class DecoupledProduct:
    """The product of a decoupled model with a Rabin automaton (the automaton reads the
    label of the state entered, as :class:`planner.imdp.product.ProductIMDP`); product
    state ``(s, q)`` has index ``s * n_q + q``, and its rows keep the model's per-axis
    intervals with the successor map composed with the automaton.

    :meth:`satisfaction` covers formulas whose automaton accepts by reaching an absorbing
    accepting state (co-safe formulas such as ``!Haz U Goal``): then the worst-case
    satisfaction is the worst-case reachability of those states.

    Raises:
        ProductError: an automaton proposition the model does not declare.
    """

    def __init__(self, model: DecoupledIMDP, automaton: RabinAutomaton) -> None:
        unknown = [p for p in automaton.propositions if p not in model.propositions]
        if unknown:
            raise ProductError(f"automaton propositions {unknown} are not labels of the model")
        nq = automaton.n_states
        self.base, self.automaton, self.n_q = model, automaton, nq
        bits = np.array([model.propositions.index(p) for p in automaton.propositions], int)
        self.letters = (
            (model.label_matrix[:, bits].astype(np.int64) << np.arange(bits.size)).sum(axis=1)
            if bits.size
            else np.zeros(model.n_states, dtype=np.int64)
        )
        delta = automaton.transitions
        rs = model.row_state
        counts = np.diff(model.state_ptr)
        # rows: per model state s, per q, the rows of s
        rows = np.concatenate(
            [
                np.tile(np.arange(model.state_ptr[s], model.state_ptr[s + 1]), nq)
                for s in range(model.n_states)
            ]
        )
        qs = np.concatenate([np.repeat(np.arange(nq), counts[s]) for s in range(model.n_states)])
        maps = model.maps
        pmaps = (
            maps[:, None, :, :] * nq
            + delta[np.arange(nq)[None, :, None, None], self.letters[maps][:, None, :, :]]
        )
        pmaps = pmaps.reshape(-1, maps.shape[1], maps.shape[2])
        axes = []
        for ptr, b, lo, up in model.axes:
            lens = np.diff(ptr)[rows]
            idx = np.concatenate([np.arange(ptr[r], ptr[r + 1]) for r in rows])
            axes += [np.concatenate(([0], np.cumsum(lens))), b[idx], lo[idx], up[idx]]
        init = model.initial * nq + delta[automaton.initial, self.letters[model.initial]]
        self.model = DecoupledIMDP(
            model.n_states * nq,
            rs[rows] * nq + qs,
            model.row_action[rows],
            *axes,
            pmaps,
            model.row_map[rows] * nq + qs,
            n_actions=model.n_actions,
            label_matrix=np.repeat(model.label_matrix, nq, axis=0),
            propositions=model.propositions,
            initial=init,
            action_names=model.action_names,
            tolerance=model.tolerance,
        )
        q_of = np.arange(self.model.n_states) % nq
        self.good = tuple(np.isin(q_of, sorted(p.good)) for p in automaton.pairs)
        self.bad = tuple(np.isin(q_of, sorted(p.bad)) for p in automaton.pairs)

    @property
    def n_states(self) -> int:
        return self.model.n_states

    @property
    def initial(self) -> int:
        return int(self.model.initial[0])

    def accepting_sink(self) -> np.ndarray:
        """Product states whose automaton state is absorbing and accepting (a pair with
        ``B`` empty and ``G`` closed under every letter).

        Raises:
            ProductError: if the automaton does not accept that way (not co-safe).
        """
        aut = self.automaton
        sinks = set()
        for p in aut.pairs:
            g = sorted(p.good)
            if p.bad or not g or not np.isin(aut.transitions[g], g).all():
                raise ProductError(
                    "decoupled models support formulas accepted by reaching an absorbing "
                    "accepting automaton state (co-safe formulas such as !Haz U Goal) only"
                )
            sinks |= set(g)
        return np.isin(np.arange(self.n_states) % self.n_q, sorted(sinks))

    def satisfaction(
        self, pessimistic: bool = True, algorithm: ValueIteration | None = None
    ) -> Solution:
        """Worst-case (or best-case) satisfaction per product state, certified: by sweeps
        with the exact operator; where their bracket does not close (a region the
        controller can circulate in, with equal values), on :func:`expanded_imdp` by
        :func:`planner.imdp.solve.solve` (its strategy iteration makes the values exact)
        when the model has at most ``_EXPAND_MAX_ROWS`` rows (the direct sweeps are then
        capped at ``_DIRECT_SWEEPS``: they can creep where mass leaks slowly)."""
        target = self.accepting_sink()
        alg = ValueIteration() if algorithm is None else algorithm
        small = self.model.n_rows <= _EXPAND_MAX_ROWS
        direct = (
            replace(alg, max_iterations=min(alg.max_iterations, _DIRECT_SWEEPS)) if small else alg
        )
        sol = solve_reach(self.model, target, None, pessimistic, direct)
        if sol.converged or not small:
            return sol
        free = np.flatnonzero(~sol.fixed)
        x = strategy_iteration(self.model, free, sol.lower, sol.lower, pessimistic)
        if x is not None:
            certified = _certify(self.model, free, np.maximum(sol.lower, x), sol, pessimistic, alg)
            if certified is not None:
                return certified
        if expanded_size(self.model) > _EXPAND_MAX_ENTRIES:
            return sol
        big, n = expanded_imdp(self.model)
        spec = Specification(
            ReachAvoid(np.concatenate([target, np.zeros(big.n_states - n, bool)])),
            "pessimistic" if pessimistic else "optimistic",
        )
        full = solve(Problem(big, spec), alg)
        return Solution(
            values=np.maximum(sol.lower, full.lower[:n]),
            strategy=np.where(full.strategy[:n] >= 0, full.strategy[:n], sol.strategy),
            residual=full.residual,
            iterations=sol.iterations + full.iterations,
            converged=full.converged,
            evaluations=full.evaluations,
            fixed=sol.fixed,
            lower=np.maximum(sol.lower, full.lower[:n]),
            upper=np.minimum(sol.upper, full.upper[:n]),
            upper_sweeps=sol.upper_sweeps + full.upper_sweeps,
        )


_EXPAND_MAX_ROWS = 20_000
"""Rows up to which an uncertified decoupled solve falls back to the expanded model."""

_EXPAND_MAX_ENTRIES = 2_000_000
"""Entries of the expanded model (vertex pairs times their supports) up to which it is
built; beyond, the direct solve's (sound, possibly wide) bracket is returned."""

_DIRECT_SWEEPS = 2_000
"""Sweeps of the direct solve before the fallback (it can creep where mass leaks slowly)."""


# --------------------------------------------------------------------------- grid


def grid_decoupled_model(
    grid: GridWorld,
    state: np.ndarray,
    action: np.ndarray,
    error_lower: np.ndarray,
    error_upper: np.ndarray,
    noise: TruncatedGaussianNoise | None = None,
    initial: Iterable[int] = (0,),
    tolerance: float = BOUND_TOLERANCE,
) -> DecoupledIMDP:
    """The decoupled abstraction of ``grid`` from per-row error bounds.

    Args:
        grid: the world.
        state, action: the rows: every enabled (cell, action) pair exactly once.
        error_lower, error_upper: ``(rows, 2)`` bounds of the mean landing error of each
            row, per axis (x, y), metres: the row departs from its cell with that action.
            (Per-cell bounds: index them by ``state``.)
        noise: the per-axis landing noise (default :class:`TruncatedGaussianNoise`).
        initial: initial states.

    Each axis has the bins *below*, the ``n`` columns (rows) and *above*
    (:func:`planner.intervals.axis_bin_bounds`); a pair with a bin outside maps to ``out``,
    which keeps its self-loop. Bins with upper bound 0 are left out.

    Raises:
        ModelError: rows that are not exactly the enabled (cell, action) pairs, or bounds
            of the wrong shape.
    """
    noise = noise or TruncatedGaussianNoise()
    s = np.asarray(state, dtype=np.int64)
    a = np.asarray(action, dtype=np.int64)
    e_lo = np.asarray(error_lower, dtype=np.float64)
    e_hi = np.asarray(error_upper, dtype=np.float64)
    if e_lo.shape != (s.size, 2) or e_hi.shape != (s.size, 2):
        raise ModelError(f"error bounds must have shape ({s.size}, 2)")
    order = np.lexsort((a, s))
    s, a, e_lo, e_hi = s[order], a[order], e_lo[order], e_hi[order]
    want_s, want_a = np.nonzero(grid.enabled[: grid.n_cells])
    if s.size != want_s.size or np.any(s != want_s) or np.any(a != want_a):
        raise ModelError("rows must be every enabled (cell, action) pair exactly once")
    centre = grid.target_centres[s, a]
    axes = []
    for d, n in ((0, grid.nx), (1, grid.ny)):
        lo, hi = axis_bin_bounds(noise, n, grid.cell, centre[:, d], e_lo[:, d], e_hi[:, d])
        lo = np.vstack([lo, np.eye(1, n + 2)])  # out: the "below" bin for sure
        hi = np.vstack([hi, np.eye(1, n + 2)])
        r, b = np.nonzero(hi > 0.0)
        ptr = np.concatenate(([0], np.cumsum(np.bincount(r, minlength=lo.shape[0]))))
        axes += [ptr, b, lo[r, b], hi[r, b]]
    nx, ny = grid.nx, grid.ny
    maps = np.full((1, nx + 2, ny + 2), grid.out, dtype=np.int64)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    maps[0, 1 : nx + 1, 1 : ny + 1] = i * ny + j
    return DecoupledIMDP(
        grid.n_states,
        np.append(s, grid.out),
        np.append(a, OUT_ACTION),
        *axes,
        maps,
        np.zeros(s.size + 1, dtype=np.int64),
        n_actions=len(ACTIONS),
        labels=grid.labels,
        propositions=grid.propositions,
        initial=initial,
        action_names=ACTIONS,
        tolerance=tolerance,
    )
