"""Reachability on a decoupled model: Gauss-Seidel sweeps with the exact operator from
below, bounded from above (a candidate checked superharmonic in floating point, then shown
in exact arithmetic through the expanded interval MDP, :func:`shown_bracket`), strategy
iteration, and the expanded interval MDP with the same values."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from planner.imdp.certify import verify_upper
from planner.imdp.decoupled import operator
from planner.imdp.decoupled.model import DecoupledIMDP
from planner.imdp.evaluate import chain_reach
from planner.imdp.kernels.upper import ROUNDING
from planner.imdp.model import IMDP, first_of_runs
from planner.imdp.solve import Solution, ValueIteration
from planner.imdp.stay import (
    chain_stay_allowance,
    shortest_stay,
    stay_limit,
    surest_exit_start,
    widening_room,
)


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


def _greedy_rows(
    m: DecoupledIMDP, v: np.ndarray, pessimistic: bool, slack: float
) -> tuple[np.ndarray, np.ndarray]:
    """The first row per state whose robust value is within ``slack`` of the state's best,
    and the robust values ``q`` of all rows."""
    q = m.expectation(v, minimize=pessimistic)
    best = np.maximum.reduceat(q, m.state_ptr[:-1])
    top = np.flatnonzero(q >= best[m.row_state] - slack)
    return top[first_of_runs(m.row_state[top])], q


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
    layout = m.layout

    def sweep(x: np.ndarray) -> tuple[float, int]:
        return operator.sweep(
            states, row_lo, row_hi, x, True, True, pessimistic, layout, m.width, False
        )

    it, residual, goal, upper, passes = 0, 0.0, alg.tolerance, None, 0
    tries = 0
    while states.size and it < alg.max_iterations:
        it += 1
        residual, _ = sweep(v)
        if alg.callback is not None:
            alg.callback(it, residual)
        if residual >= goal:
            continue
        if not alg.certified:
            break
        u, k = _checked_candidate(m, states, v, alg.tolerance, pessimistic, 8, False)
        passes += k
        if u is not None:
            upper = u
            break
        tries += 1
        if tries >= 6:
            break
        goal = max(goal / 8.0, 1e-15)
    if upper is None:
        upper = v.copy()
        upper[states] = 1.0
    top, q = _greedy_rows(m, v, pessimistic, 1e-12)
    strategy = np.full(n, -1, dtype=np.int64)
    strategy[m.row_state[top]] = m.row_action[top]
    strategy[fixed] = -1
    converged = (
        bool(np.max(upper - v, initial=0.0) < alg.tolerance)
        if alg.certified
        else bool(residual < alg.tolerance)
    )
    sol = Solution(
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
    return shown_bracket(m, sol, pessimistic, alg.tolerance) if alg.certified else sol


EXPAND_MAX_ENTRIES = 2_000_000
"""Entries of :func:`expanded_imdp` (vertex pairs times their supports) up to which it is
built: for the exact check of :func:`shown_bracket` and for the fallback solve of
:meth:`DecoupledProduct.satisfaction <planner.imdp.decoupled.DecoupledProduct.satisfaction>`;
beyond, no bound from above is shown and the direct solve's bracket is returned."""


def expandable(model: DecoupledIMDP) -> bool:
    """Whether :func:`expanded_imdp` is built already or within ``EXPAND_MAX_ENTRIES``."""
    return model._expanded is not None or expanded_size(model) <= EXPAND_MAX_ENTRIES


def shown_bracket(model: DecoupledIMDP, sol: Solution, pessimistic: bool, tol: float) -> Solution:
    """``sol`` with a bound from above that counts: shown superharmonic in exact arithmetic
    (:func:`planner.imdp.certify.verify_upper`, raised where it raises) on
    :func:`expanded_imdp`, whose values on the model's states are the model's, each
    auxiliary state valued at its distribution's expectation of the bound; converged only
    where that bound closes the bracket. As for interval MDPs
    (:func:`planner.imdp.widening.certified_upper`), the bound checked is ``sol.upper``
    raised by the floating-point allowance of :func:`_rounding_raise` (a raise that lets
    the exact check pass sooner, no proof); where that raise would open a closed bracket
    (long stays), ``sol.upper`` as it is is checked first and kept if shown within the
    tolerance. Where no bound is shown (or the expansion would have more than
    ``EXPAND_MAX_ENTRIES`` entries) ``upper`` is 1 on the free states and the solution is
    not converged: the checks of the sweeps from above are made in floating point, and
    over long stays they pass bounds below the value (a slow exit of ``2^-50`` a step to a
    trap: ``[0, 5e-9]`` for ``1/8``). A shown bound is reported at least ``sol.lower``
    (any number above an upper bound is one): the proof is for the expansion, whose point
    masses are the vertex products rounded to the nearest double, so the model's own
    values, and its bound from below, may differ from the expansion's in the last bits (on
    the grid cases of the tests the bound from below exceeded the shown bound by up to
    6.7e-16 at some states)."""
    free = ~sol.fixed
    if not free.any():
        return sol
    if expandable(model):
        closed = bool(np.max(sol.upper - sol.lower, initial=0.0) < tol)
        raised = _rounding_raise(model, sol, pessimistic, tol) if closed else sol.upper
        tries = [raised]
        if closed and np.max(raised - sol.lower, initial=0.0) >= tol:
            tries.insert(0, sol.upper)
        kept = None
        check = _expansion_check(model, free, pessimistic)
        for u in tries:
            shown, out = check(u)
            if shown:
                upper = np.where(free, np.maximum(out, sol.lower), sol.upper)
                width = float(np.max(upper - sol.lower, initial=0.0))
                if kept is None or width < kept[1]:
                    kept = (upper, width)
                if width < tol:
                    break
        if kept is not None:
            return replace(sol, upper=kept[0], converged=kept[1] < tol)
    return replace(sol, upper=np.where(free, 1.0, sol.upper), converged=False)


def _expansion_check(
    model: DecoupledIMDP, free: np.ndarray, pessimistic: bool
) -> Callable[[np.ndarray], tuple[bool, np.ndarray]]:
    """``check(u) -> (shown, U')``: :func:`planner.imdp.certify.verify_upper` of the bound
    ``u`` on the model's states, checked at the ``free`` ones on :func:`expanded_imdp`
    (each auxiliary state valued at its point distribution's expectation of ``u``); ``U'``
    on the model's states. The expansion's entries of the auxiliary states and the rows
    checked are found once, for every bound checked."""
    big, n = expanded_imdp(model)
    owner = big.row_state[big.entry_row]
    aux = owner >= n  # the auxiliary states' point distributions
    aux_owner, aux_mass, aux_succ = owner[aux] - n, big.lower[aux], big.successor[aux]
    checked = np.concatenate([free, np.ones(big.n_states - n, dtype=bool)])
    rows = np.flatnonzero(checked[big.row_state])

    def check(u: np.ndarray) -> tuple[bool, np.ndarray]:
        x = np.empty(big.n_states)
        x[:n] = u
        x[n:] = np.bincount(aux_owner, aux_mass * x[aux_succ], minlength=big.n_states - n)
        shown, out = verify_upper(big, rows, x, True, pessimistic)
        return shown, out[:n]

    return check


def _rounding_raise(
    model: DecoupledIMDP, sol: Solution, pessimistic: bool, tol: float
) -> np.ndarray:
    """``sol.upper`` raised by what floating point may have hidden from its checks (they
    accept ``T(U) <= U + 1e-15``; every row evaluation is rounded): the allowance summed
    over the expected stay of the strategy of shortest stay among the rows within
    ``U - L`` of the best at ``U``, each with the adversary's distribution at ``U``
    (:func:`planner.imdp.stay.chain_stay_allowance`, as
    :func:`planner.imdp.widening.rounding_widened` for interval MDPs; the search for that
    strategy bounded by the room ``tol`` leaves), at most 1."""
    m = model
    upper, lower = sol.upper, sol.lower
    free = ~sol.fixed
    top, q = _greedy_rows(m, upper, pessimistic, 0.0)
    best = np.full(m.n_states, -np.inf)
    best[m.row_state[top]] = q[top]
    rs = m.row_state
    slack = np.maximum(upper - lower, 0.0)[rs] + ROUNDING
    near = np.flatnonzero(free[rs] & (q >= best[rs] - slack))
    if near.size == 0:
        return upper
    r, t, p = operator.chosen_distributions(near, upper, pessimistic, m.layout, m.width)
    mat = sp.csr_matrix((p, (r, t)), shape=(near.size, m.n_states))
    start = np.searchsorted(near, top[free[m.row_state[top]]])
    start = surest_exit_start(mat, rs[near], start)
    limit = stay_limit(mat, upper, ROUNDING, widening_room(lower[free], upper[free], tol))
    choice, stay = shortest_stay(mat, rs[near], start, limit=limit)
    allowance = chain_stay_allowance(mat[choice], rs[near[choice]], upper, ROUNDING, stay=stay)
    return np.where(free, np.minimum(1.0, upper + allowance), upper)


def certify_candidate(
    m: DecoupledIMDP,
    states: np.ndarray,
    lower: np.ndarray,
    sol: Solution,
    pessimistic: bool,
    alg: ValueIteration,
    near: np.ndarray | None = None,
) -> Solution | None:
    """The bracket ``[lower, U]`` from the candidate ``min(1, near + tolerance / 2)``
    (``near`` defaults to ``lower``; e.g. the unlowered values of strategy iteration, an
    approximate fixed point, whose candidate has slack where the lowered one has
    violations of the size of the lowering) if checking passes (:func:`operator.sweep`
    from above) certify ``U`` superharmonic, violating states raised to their Bellman value
    until a pass finds none; else ``None``."""
    base = lower if near is None else np.maximum(lower, near)
    u, _ = _checked_candidate(m, np.sort(states), base, alg.tolerance, pessimistic, 16, True)
    if u is None:
        return None
    checked = Solution(
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
    return shown_bracket(m, checked, pessimistic, alg.tolerance)


def _checked_candidate(
    m: DecoupledIMDP,
    states: np.ndarray,
    lower: np.ndarray,
    tol: float,
    pessimistic: bool,
    max_passes: int,
    raise_violations: bool,
) -> tuple[np.ndarray | None, int]:
    """The candidate ``U = min(1, lower + tol / 2)`` on ``states`` (in sweep order), checked
    by at most ``max_passes`` passes of :func:`operator.sweep` from above: ``(U, passes)``
    once a pass finds no violation (``U`` superharmonic), else ``(None, passes)``.
    ``raise_violations``: violating states take their Bellman value and the passes go on
    (a repair); otherwise they stop when the violations no longer decrease."""
    row_lo, row_hi = m.state_ptr[states], m.state_ptr[states + 1]
    u = lower.copy()
    u[states] = np.minimum(1.0, lower[states] + tol / 2)
    last = None
    for k in range(1, max_passes + 1):
        _, bad = operator.sweep(
            states,
            row_lo,
            row_hi,
            u,
            False,
            True,
            pessimistic,
            m.layout,
            m.width,
            raise_violations,
        )
        if bad == 0:
            return u, k
        if not raise_violations and last is not None and bad >= last:
            return None, k
        last = bad
    return None, max_passes


def _vertex_pairs(model: DecoupledIMDP) -> tuple[np.ndarray, np.ndarray]:
    """Per row: the number of per-axis vertex pairs and the size of the pair support."""
    m = model
    (xp, _, xl, xu), (yp, _, yl, yu) = m.axes
    rows = np.arange(m.n_rows, dtype=np.int64)
    nx = np.diff(operator.vertices(xp, xl, xu, rows, m.tolerance)[0]) // np.diff(xp)
    ny = np.diff(operator.vertices(yp, yl, yu, rows, m.tolerance)[0]) // np.diff(yp)
    return nx * ny, np.diff(xp) * np.diff(yp)


def expanded_size(model: DecoupledIMDP) -> int:
    """Entries :func:`expanded_imdp` would have (vertex pairs times the pair supports)."""
    pairs, support = _vertex_pairs(model)
    return int(np.sum(pairs * (1 + support)))


def expanded_imdp(model: DecoupledIMDP) -> tuple[IMDP, int]:
    """An interval MDP with the same reachability values: every row leads, with intervals
    ``[0, 1]``, to one auxiliary state per pair of per-axis vertices, which moves with that
    pair's product distribution (point intervals). The adversary's choice of weights is a
    choice among the vertex pairs (randomisation does not change reachability values), so
    the values on the first ``n_states`` states are the decoupled model's. Returns
    ``(model, n_states)``; the auxiliary states carry no labels. Built once per model
    (kept on it: the exact check of its brackets and the fallback solve both use it)."""
    if model._expanded is not None:
        return model._expanded
    m = model
    (xp, xb, xl, xu), (yp, yb, yl, yu) = m.axes
    rows = np.arange(m.n_rows, dtype=np.int64)
    xv_ptr, xv = operator.vertices(xp, xl, xu, rows, m.tolerance)
    yv_ptr, yv = operator.vertices(yp, yl, yu, rows, m.tolerance)
    n = m.n_states
    nbx, nby = np.diff(xp), np.diff(yp)
    kx, ky = np.diff(xv_ptr) // nbx, np.diff(yv_ptr) // nby
    # one auxiliary state per row and vertex pair (i, j), numbered from n in row order
    k = kx * ky
    aux_row = np.repeat(rows, k)
    pair = np.arange(aux_row.size) - np.repeat(np.cumsum(k) - k, k)
    ai, aj = pair // ky[aux_row], pair % ky[aux_row]
    # its entries: bin pairs (a, b) of the row, the product of the two vertices' masses
    size = (nbx * nby)[aux_row]
    e_aux = np.repeat(np.arange(aux_row.size), size)
    t = np.arange(e_aux.size) - np.repeat(np.cumsum(size) - size, size)
    r = aux_row[e_aux]
    a, b = t // nby[r], t % nby[r]
    prob = xv[xv_ptr[r] + ai[e_aux] * nbx[r] + a] * yv[yv_ptr[r] + aj[e_aux] * nby[r] + b]
    succ = m.maps[m.row_map[r], xb[xp[r] + a], yb[yp[r] + b]]
    # bin pairs that land on the same state merged, in their order; zero masses dropped
    order = np.lexsort((succ, e_aux))
    e_aux, succ, prob = e_aux[order], succ[order], prob[order]
    starts = np.r_[True, (np.diff(e_aux) != 0) | (np.diff(succ) != 0)]
    first = np.flatnonzero(starts)
    mass = np.zeros(first.size)
    np.add.at(mass, np.cumsum(starts) - 1, prob)  # summed in order, as the entries come
    keep = mass > 0
    src, dst, mass = e_aux[first][keep] + n, succ[first][keep], mass[keep]
    aux = n + aux_row.size
    state = np.concatenate([m.row_state[aux_row], src])
    action = np.concatenate([m.row_action[aux_row], np.zeros(src.size, dtype=np.int64)])
    target = np.concatenate([n + np.arange(aux_row.size), dst])
    lo = np.concatenate([np.zeros(aux_row.size), mass])
    up = np.concatenate([np.ones(aux_row.size), mass])
    names = np.array(m.propositions)
    labels = [tuple(names[row]) for row in m.label_matrix] + [()] * (aux - n)
    out = IMDP(
        aux,
        state,
        action,
        target,
        lo,
        up,
        n_actions=m.n_actions,
        labels=labels,
        propositions=m.propositions,
        initial=m.initial,
        tolerance=max(m.tolerance, 1e-12),
    )
    model._expanded = (out, n)
    return out, n


def strategy_iteration(
    model: DecoupledIMDP,
    states: np.ndarray,
    fixed_val: np.ndarray,
    start: np.ndarray,
    pessimistic: bool,
    rounds: int = 50,
    sound: bool = True,
) -> np.ndarray | None:
    """Exact values of the reachability game on ``states`` (the others held at
    ``fixed_val``) by strategy iteration (Hoffman-Karp): evaluate the strategy against the
    adversary's best response (adversary policy iteration on the exact operator's choices,
    each a sparse solve), switch rows that are strictly better, repeat. ``None`` when it
    does not settle within ``rounds``. The values, when it settles, are the value itself
    lowered by the rounding bound of the last evaluation
    (:class:`planner.imdp.evaluate.ChainError`, with the adversary choice's defect as for
    :func:`planner.imdp.evaluate.strategy_reach_value`): a lower bound. ``sound=False``:
    the computed values as they are (a candidate for an upper bound that is then checked,
    an approximate fixed point; not a bound)."""
    out = settled_values(model, states, fixed_val, start, pessimistic, rounds)
    if out is None:
        return None
    return out[1] if sound else out[0]


def settled_values(
    model: DecoupledIMDP,
    states: np.ndarray,
    fixed_val: np.ndarray,
    start: np.ndarray,
    pessimistic: bool,
    rounds: int = 50,
) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`strategy_iteration`'s values both ways: ``(computed, lowered)``."""
    m = model
    layout = m.layout
    x = np.asarray(start, dtype=np.float64).copy()
    free = np.zeros(m.n_states, bool)
    free[states] = True

    def greedy(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _greedy_rows(m, values, pessimistic, 0.0)

    choice, _ = greedy(x)
    choice = choice[free[m.row_state[choice]]]
    slack = 1e-13
    for _ in range(rounds):
        rows = choice
        for _ in range(rounds):
            r, t, p = operator.chosen_distributions(rows, x, pessimistic, layout, m.width)
            mat = sp.csr_matrix((p, (r, t)), shape=(rows.size, m.n_states))
            y, err = chain_reach(mat, m.row_state[rows], np.where(free, 0.0, fixed_val), error=True)
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
            # a lower bound despite rounding: lowered by the solve's bound and, against a
            # minimising adversary (a fixed choice only bounds its value from above), by
            # the defect of the choice at x
            defect = np.maximum(mat @ x - q[rows], 0.0) if pessimistic else None
            return x, np.maximum(x - err.bound(defect), 0.0)
        choice = np.where(better, best, rows)
    return None


# --------------------------------------------------------------------------- product
