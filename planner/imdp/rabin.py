"""Worst-case satisfaction of Rabin objectives on interval MDPs: an exact game solution.

**Semantics.** The worst-case probability that a run satisfies a Rabin condition
``OR_i (Inf meets G_i and avoids B_i)`` on a (product) interval MDP is the value

    P_check(s) = max_pi min_zeta P(run satisfies the condition | pi, zeta, s),

the paper's ``P_check``, with a *dynamic* adversary: ``zeta`` picks, each time a row is used,
a distribution inside the row's intervals, knowing the history. This is the sound
reading for an abstraction: the true landing distribution of a hop depends on where in
the cell the robot departs, so it changes from visit to visit. It is a turn-based
stochastic game (the adversary's choices may be taken at the vertices of each row's
polytope; randomisation does not help in turn-based games); the controller has optimal
strategies that are memoryless on the product (the Rabin player), which the solution
returns. A *static* adversary that fixes one distribution per row for ever is weaker and
can give strictly more: the minimum over static vertex resolutions of the resolved MDP's
maximal satisfaction is an upper bound of ``P_check``, and equal to it when the optimal
adversary of the game needs no memory beyond the product *and* its choices are the same
in every automaton state of a model state (e.g. in a model where the controller can see
the resolution it would lose nothing); see the tests for a model where they differ.

**Zero lower bounds.** The adversary may choose the support of every distribution (any
set of successors that contains the ``lower > 0`` ones and has enough upper mass). A run
may therefore stay for ever in states outside every robustly accepting end component and
still satisfy the condition (``G !c`` where no state is labelled ``c``). The solution
below is a game solution, not a reachability of accepting end components:

1. :func:`almost_sure_region`: the states ``W`` from which the controller wins with
   probability 1 against every adversary: Zielonka's recursive algorithm on the Rabin
   condition's Zielonka tree, adapted to the interval game (a.s. player = controller,
   positive player = adversary): the controller's *positive* attractor (rows that put
   mass into a set under every adversary, bounded below) at the nodes whose colour set is
   accepting, the adversary's positive attractor (every row has an ``upper > 0`` edge into
   the set) at the others, sub-games closed for the side that must not leave them, and
   dominions won by the controller kept as absorbing winning states.
2. If no joint end component outside ``W`` (a set both sides can keep the run in) has an
   accepting sub-component, a satisfying run must enter ``W``: ``P_check`` is the
   certified worst-case reachability of ``W`` (:func:`planner.imdp.solve.solve`). This
   covers co-safe formulas (``!Haz U Goal``) and many others, and is what the case
   studies use.
3. Otherwise strategy improvement (Hoffman-Karp, as for stochastic Rabin games,
   Chatterjee and Henzinger 2006): a memoryless strategy is evaluated exactly
   (:func:`evaluate_strategy`: the adversary then solves a Markov decision process with
   the Streett condition; its maximal probability of reaching the Rabin-*rejecting* end
   components it can hold is ``1 - value``), switched where a row is strictly better, and,
   when no row is, improved in the sub-game of value-preserving moves (rows whose robust
   value equals the state's; each row's intervals narrowed to the adversary's optimal
   face) where the controller can win almost surely (step 1 on that sub-game). It stops
   when neither improves; the value of that strategy is ``P_check``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.imdp import graph
from planner.imdp.model import IMDP, first_of_runs
from planner.imdp.ordering import OrderingAdversary
from planner.imdp.problem import ValueIteration
from planner.imdp.rabin_game import almost_sure_region
from planner.imdp.solve import Problem, ReachAvoid, Solution, Specification, solve, solve_with
from planner.modes import Adversary

__all__ = ["almost_sure_region", "evaluate_strategy", "rejecting_components", "robust_satisfaction"]

# --------------------------------------------------------------------------- evaluation


def rejecting_components(
    model: IMDP, rows: np.ndarray, good: np.ndarray, bad: np.ndarray
) -> np.ndarray:
    """States of the end components that the adversary can hold under the strategy whose
    rows are ``rows`` (mask, one row per state) and whose every state is visited for
    ever while no pair is satisfied (the Streett condition of the adversary: refine each
    maximal end component by removing the ``G_i`` of the pairs it satisfies)."""
    m = model
    good = np.asarray(good, dtype=bool).reshape(-1, m.n_states)
    bad = np.asarray(bad, dtype=bool).reshape(-1, m.n_states)
    out = np.zeros(m.n_states, dtype=bool)
    work = [graph.has_row(m, rows)]
    while work:
        states = work.pop()
        for ec in graph.maximal_end_components(
            m, rows=rows, states=states, mode=Adversary.OPTIMISTIC
        ):
            mask = ec.state_mask(m.n_states)
            g = (good & mask).any(axis=1)
            b = (bad & mask).any(axis=1)
            sat = g & ~b
            if not sat.any():
                out |= mask
            else:
                rest = mask & ~good[sat].any(axis=0)
                if rest.any():
                    work.append(rest)
    return out


def evaluate_strategy(
    model: IMDP,
    choice: np.ndarray,
    good: np.ndarray,
    bad: np.ndarray,
    algorithm: ValueIteration | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Certified bracket ``(lower, upper)`` of the worst-case satisfaction probability of the
    memoryless strategy ``choice`` (a row per state, -1: no row: the run stops, losing).

    Against a fixed strategy the adversary solves a Markov decision process with the
    Streett condition (the complement): its maximal probability is that of reaching the
    rejecting end components it can hold (:func:`rejecting_components`), a reachability
    with the adversary cooperating with itself (``"optimistic"``)."""
    m = model
    rows = np.zeros(m.n_rows, dtype=bool)
    rows[choice[choice >= 0]] = True
    stop = choice < 0
    bad_ec = rejecting_components(m, rows, good, bad) | stop
    allowed = graph.actions_from_rows(m, rows)
    sol = solve(
        Problem(m, Specification(ReachAvoid(bad_ec), Adversary.OPTIMISTIC), allowed), algorithm
    )
    return 1.0 - sol.upper, 1.0 - sol.lower


# --------------------------------------------------------------------------- value


@dataclass(frozen=True)
class _Face:
    """A model whose rows are the value-preserving rows of another, each narrowed to the
    adversary's optimal face (see :func:`_optimal_face`), and the row map back."""

    model: IMDP
    source_row: np.ndarray


def _optimal_face(model: IMDP, v: np.ndarray, rows: np.ndarray, eps: float) -> _Face | None:
    """The sub-game of value-preserving moves for values ``v``: the rows (among ``rows``)
    whose robust value is within ``eps`` of the state's, and in each the adversary's
    distributions that attain the minimum: with ``t`` the value where the minimising order
    stops handing out mass, successors below ``t`` at their upper bound, above at their
    lower bound, at ``t`` (within ``eps``) anywhere in their interval. Rows whose face is
    inconsistent within ``eps`` are dropped (only fewer moves for the controller)."""
    m = model
    idx = np.flatnonzero(rows)
    q = OrderingAdversary(m, True, rows=idx).expectation(v)
    keep = q >= v[m.row_state[idx]] - eps
    idx = idx[keep]
    if idx.size == 0:
        return None
    s_out, a_out, t_out, lo_out, up_out, src = [], [], [], [], [], []
    for r in idx.tolist():
        a, b = m.row_ptr[r], m.row_ptr[r + 1]
        succ = m.successor[a:b]
        lo = m.lower[a:b]
        up = m.upper[a:b]
        val = v[succ]
        order = np.argsort(val, kind="stable")
        rem = 1.0 - lo.sum()
        gap = up - lo
        cum = np.cumsum(gap[order]) - gap[order]
        give = np.clip(rem - cum, 0.0, gap[order])
        # critical value: the first successor not filled to its upper bound
        part = np.flatnonzero(give < gap[order] - 1e-15)
        t = val[order[part[0]]] if part.size else val[order[-1]]
        nlo = np.where(val < t - eps, up, np.where(val > t + eps, lo, lo))
        nup = np.where(val < t - eps, up, np.where(val > t + eps, lo, up))
        if nlo.sum() > 1.0 + m.tolerance or nup.sum() < 1.0 - m.tolerance:
            continue
        live = nup > 0
        s_out.append(np.full(live.sum(), m.row_state[r]))
        a_out.append(np.full(live.sum(), m.row_action[r]))
        t_out.append(succ[live])
        lo_out.append(nlo[live])
        up_out.append(nup[live])
        src.append(r)
    if not src:
        return None
    s = np.concatenate(s_out)
    states_with = np.unique(s)
    # every state needs a row: the others get a losing self-loop (they are not in play)
    missing = np.setdiff1d(np.arange(m.n_states), states_with)
    face = IMDP(
        m.n_states,
        np.concatenate([s, missing]),
        np.concatenate([np.concatenate(a_out), np.zeros(missing.size, dtype=np.int64)]),
        np.concatenate([np.concatenate(t_out), missing]),
        np.concatenate([np.concatenate(lo_out), np.ones(missing.size)]),
        np.concatenate([np.concatenate(up_out), np.ones(missing.size)]),
        n_actions=m.n_actions,
        tolerance=m.tolerance,
    )
    src_rows = np.full(face.n_rows, -1, dtype=np.int64)
    key = face.row_state * m.n_actions + face.row_action
    orig_key = m.row_state[src] * m.n_actions + m.row_action[src]
    pos = np.searchsorted(key, orig_key)
    src_rows[pos] = src
    return _Face(face, src_rows)


def _losing_sink_rows(face: _Face) -> np.ndarray:
    return face.source_row >= 0


_MAX_ROUNDS = 200
"""Strategy-improvement rounds before giving up (then the last bracket is returned)."""


def robust_satisfaction(
    model: IMDP,
    good: np.ndarray,
    bad: np.ndarray,
    allowed: np.ndarray | None = None,
    algorithm: ValueIteration | None = None,
) -> Solution:
    """``P_check`` per state with a memoryless optimal strategy (see the module docstring).

    Args:
        model: the (product) interval MDP.
        good, bad: ``(n_pairs, n_states)`` masks of ``G_i`` and ``B_i``.
        allowed: optional ``(n_states, n_actions)`` mask of allowed actions; states
            without one get value 0 and strategy -1.
        algorithm: the value-iteration settings (tolerance of the certified bracket).

    Returns:
        A :class:`Solution` with ``values = lower`` (a strategy's guaranteed probability),
        ``upper``, and the strategy; ``evaluations`` counts strategy evaluations.
    """
    m = model
    alg = ValueIteration() if algorithm is None else algorithm
    good = np.asarray(good, dtype=bool).reshape(-1, m.n_states)
    bad = np.asarray(bad, dtype=bool).reshape(-1, m.n_states)
    rows = None if allowed is None else graph.rows_from_actions(m, allowed)
    win, win_row = almost_sure_region(m, good, bad, rows)
    # a state that reaches ``win`` almost surely wins there: ``win`` is closed
    reach = solve_with(Problem(m, Specification(ReachAvoid(win)), allowed), alg, True)
    # every state with an allowed row plays one (the first, where reachability settled
    # the state without a strategy): a stopped run would lose
    choice = np.full(m.n_states, -1, dtype=np.int64)
    allowed_rows = np.flatnonzero(np.ones(m.n_rows, bool) if rows is None else rows)
    first = allowed_rows[first_of_runs(m.row_state[allowed_rows])]
    choice[m.row_state[first]] = first
    acting = (reach.strategy >= 0) & ~win
    choice[acting] = m.row_index[np.flatnonzero(acting), reach.strategy[acting]]
    choice[win] = win_row[win]
    if not _stays_accepting_outside(m, good, bad, win, rows):
        # every satisfying run enters the almost-sure region: a reachability
        return _solution(
            m, choice, reach.lower, reach.upper, reach, 0, rows, alg.tolerance, reach.converged
        )
    lower, upper = evaluate_strategy(m, choice, good, bad, alg)
    evaluations = 1
    all_rows = np.ones(m.n_rows, dtype=bool) if rows is None else rows
    tol = alg.tolerance
    slack = max(4 * tol, 1e-10)
    for _ in range(_MAX_ROUNDS):
        q = OrderingAdversary(m, True).expectation(lower)
        q = np.where(all_rows, q, -np.inf)
        best = np.maximum.reduceat(q, m.state_ptr[:-1])
        better = best > upper + slack
        if better.any():
            top = np.flatnonzero((q >= best[m.row_state]) & better[m.row_state])
            top = top[first_of_runs(m.row_state[top])]
            candidate = choice.copy()
            candidate[m.row_state[top]] = top
        else:
            candidate = _escape(m, good, bad, lower, upper, all_rows, choice, tol)
            if candidate is None:
                break
        new_lo, new_up = evaluate_strategy(m, candidate, good, bad, alg)
        evaluations += 1
        if not (new_lo >= lower - slack).all() or not (new_lo > lower + slack).any():
            break
        choice, lower, upper = candidate, np.maximum(lower, new_lo), new_up
    return _solution(m, choice, lower, upper, reach, evaluations, rows, alg.tolerance)


def _escape(
    m: IMDP,
    good: np.ndarray,
    bad: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    rows: np.ndarray,
    choice: np.ndarray,
    tol: float,
) -> np.ndarray | None:
    """A strategy that switches, where the controller wins almost surely in the sub-game
    of value-preserving moves although its value is below 1, to that sub-game's winning
    rows; ``None`` if there is no such state."""
    v = 0.5 * (lower + upper)
    eps = max(4 * tol, 1e-9)
    face = _optimal_face(m, v, rows, eps)
    if face is None:
        return None
    fm = face.model
    win, row = almost_sure_region(fm, good, bad, _losing_sink_rows(face))
    gain = win & (upper < 1.0 - eps)
    if not gain.any():
        return None
    candidate = choice.copy()
    candidate[gain] = face.source_row[row[gain]]
    return candidate


def _stays_accepting_outside(
    m: IMDP, good: np.ndarray, bad: np.ndarray, win: np.ndarray, rows: np.ndarray | None
) -> bool:
    """Whether some set of states outside ``win`` that both sides can keep the run in has
    a sub-component that satisfies a pair (then runs may satisfy the condition without
    entering ``win``)."""
    outside = ~win
    pairs = [i for i in range(good.shape[0]) if (good[i] & outside).any()]
    if not pairs:
        return False
    for i in pairs:
        states = outside & ~bad[i]
        ecs = graph.maximal_end_components(m, rows=rows, states=states, mode=Adversary.OPTIMISTIC)
        if any(good[i][ec.states].any() for ec in ecs):
            return True
    return False


def _solution(
    m: IMDP,
    choice: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    reach: Solution,
    evaluations: int,
    rows: np.ndarray | None,
    tolerance: float,
    shown: bool = True,
) -> Solution:
    """``shown``: the bracket's bound from above was proven (a reachability solve's
    ``converged``); only then can it count as converged."""
    strategy = np.where(choice >= 0, m.row_action[np.maximum(choice, 0)], -1)
    lower = np.clip(lower, 0.0, 1.0)
    upper = np.clip(np.maximum(upper, lower), 0.0, 1.0)
    final = lower.copy()

    def q_values() -> np.ndarray:
        q = OrderingAdversary(m, True).expectation(final)
        return q if rows is None else np.where(rows, q, np.nan)

    return Solution(
        values=lower,
        strategy=strategy,
        residual=reach.residual,
        iterations=reach.iterations,
        converged=shown and bool(np.max(upper - lower, initial=0.0) < tolerance),
        evaluations=reach.evaluations + evaluations,
        fixed=reach.fixed,
        lower=lower,
        upper=upper,
        upper_sweeps=reach.upper_sweeps,
        _q=q_values,
    )
