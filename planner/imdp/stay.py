"""Expected stays of chains: the allowance a rounding-tolerant check costs, and strategies
that keep it small.

A check that accepts ``T(U) <= U + e`` (``e`` the floating-point noise of one evaluation)
certifies ``U >= V_sigma - A^-1 e`` only, ``A = I - P`` on the states the chain of a
strategy and its adversary leaves: the noise summed over the expected stay
(:func:`chain_stay_allowance`). The bracket is widened by that allowance, so the upper
bound's check needs a strategy whose stays are short (:func:`surest_exit_start`,
:func:`shortest_stay`), within the room the tolerance leaves
(:func:`widening_room`, :func:`stay_limit`), bounded without a factorisation where they
are well within it (:func:`block_stay_bound`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from planner.imdp.evaluate import SOLVE_MARGIN, chain_lu, reaching, row_rounding
from planner.imdp.kernels import counting_order, surest_exit_choice
from planner.imdp.model import first_of_runs, run_ids


def chain_stay_allowance(
    matrix: sp.csr_matrix,
    states: np.ndarray,
    upper: np.ndarray,
    per_step: float,
    direct_limit: int = 20_000,
    stay: np.ndarray | None = None,
) -> np.ndarray:
    """``A^-1 a`` for the chain ``matrix`` (one distribution per state of ``states``, over
    all states): the allowance ``a = per_step + m`` (``m``: :func:`row_rounding` at
    ``upper``, a bound on the rounding of each evaluation) summed over the expected stay
    among the ``states`` of positive ``upper`` (states at 0 count as left: their rows'
    values and margins are 0), shape ``(n_states,)``. States from which the chain never
    leaves get 0: the strategy's value there is 0. Sparse LU for at most ``direct_limit``
    states, else a checked supersolution of Jacobi sweeps (``inf`` where none is found).

    A check that accepts ``T(U) <= U + e`` per state (floating-point noise of ``e`` per
    evaluation) certifies less than ``T(U) <= U``: along a strategy ``sigma`` with its
    adversary ``P``, ``U >= P U - e`` gives ``U >= V_sigma - A^-1 e`` only (``A = I - P``
    on the states the chain leaves; on a closed class ``V_sigma = 0 <= U``); on a chain
    that stays ``1e7`` steps, ``1e-15`` per step is ``1e-8``.

    ``stay`` (optional, ``(n_states,)``): the expected stay of this chain among all of
    ``states`` (:func:`shortest_stay`), finite at each of them: then ``max(a) * stay``
    bounds ``A^-1 a`` (``A^-1 >= 0``; the states at 0 only shorten the stays) and no
    factorisation is needed.
    """
    matrix = sp.csr_matrix(matrix, copy=True)
    states = np.asarray(states, dtype=np.int64)
    finite_stay = stay is not None and states.size and np.max(stay[states]) < _NEVER
    positive = upper[states] > 0.0
    states = states[positive]
    matrix = matrix[positive]
    a = per_step + row_rounding(matrix.indptr, matrix.indices, upper, per_entry=3.0)
    out = np.zeros(upper.size)
    if finite_stay:
        if states.size:
            out[states] = (1.0 + SOLVE_MARGIN) * float(np.max(a)) * stay[states]
        return out
    inner = matrix[:, states].tocsr()
    transient = reaching(inner, leaving_mass(matrix, states) > 0.0)
    idx = np.flatnonzero(transient)
    if idx.size:
        sub = inner[idx][:, idx]
        if idx.size <= direct_limit:
            lu = chain_lu(sub)
            out[states[idx]] = (1.0 + SOLVE_MARGIN) * np.maximum(lu.solve(a[idx]), 0.0)
        else:
            out[states[idx]] = _stay_supersolution(sub.tocsr(), a[idx])
    return out


def leaving_mass(matrix: sp.csr_matrix, states: np.ndarray) -> np.ndarray:
    """Per row of ``matrix`` (distributions over all states) the mass of its entries
    outside ``states``: what the chain hands to the settled states, however small. Not
    ``1 - `` the mass inside: a distribution computed in floating point may sum to
    ``1 - 1e-16`` without leading anywhere, while a real entry of ``1e-13`` towards a
    target is left within ``1e13`` steps (and may carry the whole value there)."""
    outside = np.ones(matrix.shape[1])
    outside[np.asarray(states, dtype=np.int64)] = 0.0
    return sp.csr_matrix(matrix) @ outside


def inner_rows(
    matrix: sp.csr_matrix, row_states: np.ndarray
) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """The candidate rows restricted to their own states (mass elsewhere leaves), columns
    renumbered in state order, those states, and each row's mass leaving them
    (:func:`leaving_mass`)."""
    rs = np.asarray(row_states, dtype=np.int64)
    states = rs[first_of_runs(rs)]
    matrix = sp.csr_matrix(matrix)
    pos = np.full(matrix.shape[1], -1, dtype=np.int64)
    pos[states] = np.arange(states.size)
    cols = np.flatnonzero(pos >= 0)
    inner = matrix[:, cols].tocsr()
    inner = sp.csr_matrix(
        (inner.data, pos[cols][inner.indices], inner.indptr), shape=(rs.size, states.size)
    )
    return inner, states, leaving_mass(matrix, states)


def surest_exit_start(
    matrix: sp.csr_matrix,
    row_states: np.ndarray,
    fallback: np.ndarray | None = None,
    inner: tuple[sp.csr_matrix, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Per state one of the candidate rows (``matrix``: one distribution per candidate,
    over all states; ``row_states`` their states, sorted, at least one per state) whose
    chain leaves these states from every state that can leave them: the greedy choice of
    :func:`planner.imdp.kernels.surest_exit_choice` (rows with the largest one-step mass
    towards the exit), a good start for :func:`shortest_stay`; ``fallback`` (a
    candidate index per state) where no path leaves, -1 there without one. Returns
    candidate indices. ``inner``: :func:`inner_rows` of these arguments, if at hand."""
    inner, states, leak = inner_rows(matrix, row_states) if inner is None else inner
    local = run_ids(np.asarray(row_states, dtype=np.int64))
    coo = inner.tocoo()
    order, ptr = counting_order(coo.col.astype(np.int64), states.size)
    choice = surest_exit_choice(
        local, leak, states.size, ptr, coo.row[order].astype(np.int64), coo.data[order]
    )
    if fallback is None:
        return choice
    return np.where(choice >= 0, choice, np.asarray(fallback, dtype=np.int64))


def widening_room(lower: np.ndarray, upper: np.ndarray, tolerance: float) -> float:
    """How much the rounding widening may add to a bracket: what is left to ``tolerance``
    of the widest, or a tenth of that width when it already exceeds the tolerance (an open
    bracket need not be widened minimally). Only bounds the effort spent on a short-stay
    witness; the widening itself is always the witness's full allowance."""
    width = float(np.max(upper - lower)) if upper.size else 0.0
    return max(tolerance - width, 0.1 * width, 0.0)


def stay_limit(matrix: sp.csr_matrix, upper: np.ndarray, per_step: float, room: float) -> float:
    """The expected stay up to which :func:`chain_stay_allowance` of any selection of the
    rows of ``matrix`` (evaluated at ``upper``, ``per_step`` allowance per step) stays
    within ``room``: ``room / ((1 + margin) max a)``, ``a`` the per-step allowance of each
    row; 0 without room."""
    if room <= 0.0 or matrix.shape[0] == 0:
        return 0.0
    top = per_step + float(np.max(row_rounding(matrix.indptr, matrix.indices, upper, 3.0)))
    return room / ((1.0 + SOLVE_MARGIN) * top)


_NEVER = 1e300
"""The expected stay recorded for a state whose chain never leaves."""

_BLOCK_FIRST = 32
"""Steps before the first check of :func:`block_stay_bound` (then at twice as many). Checks
every 16 steps settled the chains of the 100 x 100 benchmark grid's seeds 1 and 2 after
160 and 144 products instead of 256 (0.02-0.03 s less), but on bounds just within the
limit: a wider widening, brackets of seeds 18, 29 and 37 at 8.3-9.2e-9 instead of
4.9-7.6e-9 (seeds 0-40)."""

_STOP_EVERY = 16
"""Steps between two questions of :func:`block_stay_bound` to its ``stop``: the checks come
at 32, 64, ..., 512 steps, and the 256 products before the last took 0.03 s on the 100 x
100 benchmark grid (seed 1), which a search told to stop went on spending."""

_BLOCK_STEPS = 512
"""Steps after which :func:`block_stay_bound` gives up: 512 sparse products cost about one
sparse LU of the chains of the 100 x 100 benchmark grid (0.06-0.09 s); their stays fit
the widening's room after 128-256 steps (seeds 0-2 measured)."""


def block_stay_bound(
    sub: sp.csr_matrix,
    limit: float,
    max_steps: int = _BLOCK_STEPS,
    stop: Callable[[], bool] | None = None,
) -> float:
    """An upper bound of the expected stay from every state of the substochastic chain
    ``sub`` (rows of probabilities summing to at most 1; the missing mass leaves), found
    without a factorisation, or ``inf`` when none at most ``limit`` is found within
    ``max_steps`` steps.

    Let ``x_t = sub^t 1`` (the mass still inside after ``t`` steps, per start). If after
    ``k`` steps at most ``1 - q`` of the mass is inside from every start, ``x_{jk + t} =
    sub^{jk} x_t <= max(x_t) (1 - q)^j`` by the Markov property, so the expected stay
    ``sum_t x_t`` is at most ``S_k / q`` with ``S_k = sum_{t < k} max(x_t)`` (at most
    ``k / q``; exact for a single state). The products are checked at ``k = 32, 64,
    ..., max_steps``; every computed ``x_t`` and the sum are taken up by ``(w + 3) k
    eps`` relative for their rounding (``w`` the longest row: every product of
    non-negative terms is off by at most ``w eps`` relative). ``stop``: asked every
    ``_STOP_EVERY`` steps; ``inf`` once it says so (the caller no longer needs the
    bound)."""
    n = sub.shape[0]
    if n == 0:
        return 0.0
    width = int(np.max(np.diff(sub.indptr))) if sub.nnz else 0
    eps = np.finfo(float).eps
    x = np.ones(n)
    held = 0.0  # S_k
    for k in range(1, max_steps + 1):
        held += float(np.max(x))
        if held > limit:
            break
        x = sub @ x
        if k % _STOP_EVERY == 0 and stop is not None and stop():
            return np.inf
        if k < _BLOCK_FIRST or k & (k - 1):
            continue
        grow = 1.0 + (width + 3) * k * eps
        inside = float(np.max(x)) * grow
        if inside < 1.0:
            bound = held * grow / (1.0 - inside) * (1.0 + 4.0 * eps)
            if bound <= limit:
                return bound
    return np.inf


def shortest_stay(
    matrix: sp.csr_matrix,
    row_states: np.ndarray,
    start: np.ndarray,
    rounds: int = 50,
    limit: float = 0.0,
    block_limit: float | None = None,
    stop: Callable[[], bool] | None = None,
    inner: tuple[sp.csr_matrix, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Per state one of the candidate rows (``matrix``: one distribution per candidate,
    over all states; ``row_states`` their states, sorted, at least one per state), chosen
    to keep the expected stay among these states short: policy iteration for the minimal
    expected number of steps from ``start`` (a candidate index per state, in state order;
    :func:`surest_exit_start` gives a good one), ``rounds`` evaluations at most, until no
    state improves or every stay of a leaving state is at most ``limit`` (short enough:
    :func:`stay_limit`); a state whose chain never leaves counts as staying for ever.
    Each round first tries :func:`block_stay_bound` against ``block_limit`` (default:
    ``limit``; 0: never), which needs no factorisation, then a sparse LU. Returns
    ``(choice, stay)``: candidate indices, one per state (each improvement only shortens
    the stays), and the expected stay of that choice per state (``(n_states,)``, ``1e300``
    where it never leaves, 0 off these states; where the block bound settled it, that
    bound, at most ``block_limit``, at every leaving state), or ``None`` when the last
    round changed the choice without evaluating it. ``stop``: asked before every round and
    factorisation; once it says so, ``(choice, None)`` at once. ``inner``:
    :func:`inner_rows` of ``matrix`` and ``row_states``, if at hand."""
    rs = np.asarray(row_states, dtype=np.int64)
    seg = first_of_runs(rs)
    seg_id = run_ids(rs)
    inner, states, leaving = inner_rows(matrix, rs) if inner is None else inner
    choice = np.asarray(start, dtype=np.int64)

    def evaluated(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        full = np.zeros(matrix.shape[1])
        full[states] = w
        return choice, full

    for _ in range(rounds):
        if stop is not None and stop():
            return choice, None
        sub = inner[choice]
        live = reaching(sub, leaving[choice] > 0.0)
        w = np.full(states.size, _NEVER)
        idx = np.flatnonzero(live)
        if idx.size:
            chain = sub[idx][:, idx]
            most = limit if block_limit is None else block_limit
            bound = block_stay_bound(chain.tocsr(), most, stop=stop)
            if bound <= most:
                w[idx] = bound
                return evaluated(w)
            if stop is not None and stop():
                return choice, None
            w[idx] = chain_lu(chain).solve(np.ones(idx.size))
            if np.max(w[idx]) <= limit:
                return evaluated(w)
        cost = 1.0 + inner @ w
        best = np.minimum.reduceat(cost, seg)
        better = best < cost[choice] * (1.0 - 1e-9)
        if not better.any():
            return evaluated(w)
        top = np.flatnonzero(cost <= best[seg_id])
        top = top[first_of_runs(seg_id[top])]
        choice = np.where(better, top, choice)
    return choice, None


_STAY_SWEEPS = 2_000
"""Jacobi sweeps of the expected stay on models too large for a sparse LU."""


def _stay_supersolution(sub: sp.csr_matrix, a: np.ndarray) -> np.ndarray:
    """An upper bound of ``(I - sub)^-1 a`` without a factorisation: Jacobi sweeps
    ``w <- a + sub w`` from ``a`` until they change by under 1e-3 relative, then ``1.05 w``
    is kept if it is a supersolution, ``a + sub (1.05 w) <= 1.05 w`` (then it bounds the
    least solution); ``inf`` where that fails or the sweeps run out."""
    w = a.copy()
    for _ in range(_STAY_SWEEPS):
        nxt = a + sub @ w
        done = np.max(nxt - w) <= 1e-3 * np.max(nxt)
        w = nxt
        if done:
            cand = 1.05 * w
            if np.all(a + sub @ cand <= cand):
                return cand
            break
    return np.full(a.size, np.inf)
