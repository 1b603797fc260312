"""Specifications, problems and robust value iteration (IntervalMDP.jl's nouns).

``solve(Problem(model, Specification(prop, satisfaction, strategy)), ValueIteration())``
returns a :class:`Solution` with the values per state, a memoryless strategy (one action
per state), the row values ``Q``, the residual and the iteration count.

Properties:

* :class:`ReachAvoid`: probability of ``(!avoid) U target``. Value iteration starts from 0
  (the least fixed point, right also with end components and zero lower bounds); states
  whose value is 0 or 1 are found by graph analysis first and held fixed. For a
  minimising strategy the value-0 states are those where it can keep every run away from
  the target (:func:`planner.imdp.minimal.unavoidable_reach`): the end components in which
  it could hover for ever lie among them, so the bound from above converges on the rest
  (with them free it would stay at 1 there). Certified, a minimal reachability problem is
  solved as its dual, the maximal reachability of the value-0 states
  (:mod:`planner.imdp.minimal`).
* :class:`DiscountedReward`: ``V(s) = opt_a min/max_p sum_{s'} p(s') (W(s') + gamma V(s'))``:
  the reward ``W`` is collected on *landing* in a state (docs/design.md).

``satisfaction="pessimistic"``: the adversary opposes the strategy (the worst case);
``"optimistic"``: it helps.

**Certified values** (the default): :class:`Solution` carries ``lower <= V* <= upper`` at
every state, and the solver stops when ``max(upper - lower) < tolerance`` (default 1e-8).
For reachability ``V*`` is the least fixed point of the Bellman operator ``T``; ``lower``
comes from sweeps from below (every iterate is a sound lower bound) and ``upper`` is a
vector certified superharmonic, ``T(U) <= U``, which by Knaster-Tarski bounds the least
fixed point from above (see :mod:`planner.imdp.reachability`). A residual
``max |V_k - V_{k-1}|`` below the tolerance does not by itself bound the error (mass
leaking slowly out of a near-end-component keeps the residual small while the values are
still far off); the bracket does. For discounted reward the bracket is the contraction bound
``gamma / (1 - gamma) * residual`` of an exact sweep. ``ValueIteration(certified=False)``
is the fast uncertified mode: it stops on the residual alone.

Reachability sweeps are Gauss-Seidel, state by state in order of graph distance to the
value-1 states (a compiled kernel, :mod:`planner.imdp.kernels`): starting from
``V_0 <= T(V_0)`` the iterates increase and stay below the least fixed point, so zero lower
bounds and end components stay safe (see :mod:`planner.imdp.reachability`).

Where mass leaks slowly out of near-end-components the sweeps from below creep (the
residual can stay near ``1e-8`` per sweep while the values are still far from the fixed
point, so the residual rule alone would stop early or after millions of sweeps). For
maximal reachability (at most 20,000 free states, as its LU solves can fill in) the
sweeps therefore check, after 16, 32, 64, ... sweeps, whether the residuals (once below
1e-3) extrapolate to more than ``max(4 k, 1000)`` further sweeps, and if so run robust
strategy iteration: the strategy is evaluated exactly against the adversary's best
response (:mod:`planner.imdp.evaluate`: sparse solves, adversary policy iteration) and
improved only where a row is strictly better. Its values are a strategy's values, hence at
most the least fixed point and ``<= T(V)``, so the sweeps continue from ``max(V, V_sigma)``
soundly; when no state switches they are the least fixed point and the sweeps only
confirm the residual. The reported ``iterations`` count sweeps only.
"""

from __future__ import annotations

import numpy as np

from planner.errors import SpecificationError
from planner.imdp import graph
from planner.imdp.discounted import discounted_values
from planner.imdp.guess import GUESS_ENTRIES, Guess, GuessFailed, Searched
from planner.imdp.minimal import dual_reach, unavoidable_reach
from planner.imdp.model import IMDP, first_of_runs
from planner.imdp.ordering import OrderingAdversary
from planner.imdp.problem import (
    DiscountedReward,
    Problem,
    ReachAvoid,
    Solution,
    Specification,
    StateSet,
    ValueIteration,
    resolve_states,
)
from planner.imdp.reachability import reach_values
from planner.imdp.strategy import strategy_actions
from planner.modes import Adversary, Objective

__all__ = [
    "DiscountedReward",
    "Problem",
    "ReachAvoid",
    "Solution",
    "Specification",
    "StateSet",
    "ValueIteration",
    "resolve_states",
    "solve",
    "solve_with",
]


def _settled(
    m: IMDP,
    prop: ReachAvoid,
    rows: np.ndarray,
    maximize: bool,
    pessimistic: bool,
    precompute: bool,
    target_closed: bool = False,
    searched: Searched | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, Guess | None]:
    """The states of a reach-avoid problem settled before iterating: ``(settled, value,
    choice, guess)``: targets, avoided states and (with ``precompute``) the states of
    value 0 and, worst case maximising or minimising, of value 1 by graph analysis;
    ``choice`` the row by which a settled state attains its value where the action matters
    (-1 elsewhere): a maximising strategy's way to the target from its value-1 states, a
    minimising one's way to stay clear of it at its value-0 states. ``target_closed``:
    the target holds every state that reaches it almost surely, so the probability-1
    search is skipped. Worst case maximising, on large models, the sweeps' layout is
    built on a guess of the free states while the searches run (:mod:`planner.imdp.guess`):
    ``guess`` is that guess while the searches still run (the settled states and values
    are then the guess's, ``choice`` is the guess's to confirm), else ``None``;
    ``searched``: the searches' outcome where a failed guess gave it."""
    n = m.n_states
    target = resolve_states(m, prop.target, "target")
    avoid = (
        np.zeros(n, dtype=bool)
        if prop.avoid is None
        else resolve_states(m, prop.avoid, "avoid") & ~target
    )
    choice = np.full(n, -1, dtype=np.int64)
    prob1 = np.zeros(n, dtype=bool)
    guess = None
    if not precompute:
        zero = np.zeros(n, dtype=bool)
    elif maximize and pessimistic:

        def searches() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            pos, _ = graph.robust_positive_reach(m, target, avoid, rows)
            if target_closed:
                return pos, prob1, choice
            return pos, *graph.robust_almost_sure_reach(m, target, avoid, rows, region=pos)

        if searched is not None:
            pos, prob1, choice = searched
        elif m.n_entries < GUESS_ENTRIES:
            pos, prob1, choice = searches()
        else:
            guess = Guess.start(m, rows, target, avoid, searches)
            if guess.done():
                guess.confirm()  # raises where it failed
            settled, value = guess.settled
            return settled, value, choice, guess
        choice = np.where(prob1, choice, -1)
        zero = ~pos
    elif maximize:
        zero = ~graph.possible_reach(m, target, avoid, rows)
    else:
        # a minimising controller: the states where it can keep the probability at 0, and
        # those from which it cannot make it less than 1: no chance of reaching them (an
        # opposing adversary: none that the controller can force)
        positive, choice = unavoidable_reach(m, target, avoid, rows, cooperative=not pessimistic)
        zero = ~positive
        if pessimistic:
            escape, _ = graph.robust_positive_reach(m, zero, target, rows)
        else:
            escape = graph.possible_reach(m, zero, target, rows)
        prob1 = ~escape & ~target & ~zero
    settled = target | avoid | zero | prob1
    return settled, np.where(target | prob1, 1.0, 0.0), choice, guess


def _row_values(m: IMDP, rows: np.ndarray, adversary_minimizes: bool, values: np.ndarray):
    """The robust value of every allowed row under ``values`` (``nan`` elsewhere), later."""

    def all_q() -> np.ndarray:
        q = np.full(m.n_rows, np.nan)
        all_rows = np.flatnonzero(rows)
        if all_rows.size:
            adv = OrderingAdversary(m, adversary_minimizes, rows=all_rows)
            q[all_rows] = adv.expectation(values)
        return q

    return all_q


def solve(problem: Problem, algorithm: ValueIteration | None = None) -> Solution:
    """Solve ``problem`` by robust value iteration (see the module docstring)."""
    return solve_with(problem, algorithm)


def solve_with(
    problem: Problem, algorithm: ValueIteration | None = None, target_closed: bool = False
) -> Solution:
    """:func:`solve`, told that a reach-avoid target is closed under almost-sure reach
    (``target_closed``: every state that reaches it with probability 1 against every
    adversary, with the problem's rows, lies in it; true of an almost-sure region, such
    as :func:`planner.imdp.rabin.almost_sure_region`'s): the probability-1 search of the
    graph precomputation is skipped, as it would find the target itself. For the
    package's own callers, which know it; a target that is not closed gets correct
    values but, at the states of value 1 outside it, a strategy from the values alone."""
    alg = ValueIteration() if algorithm is None else algorithm
    try:
        return _solve(problem, alg, target_closed)
    except GuessFailed as failed:
        # the free states guessed for the sweeps' layout were wrong: from the searches'
        return _solve(problem, alg, target_closed, failed.searched)


def _solve(
    problem: Problem, alg: ValueIteration, target_closed: bool, searched: Searched | None = None
) -> Solution:
    """:func:`solve_with`; ``searched``: the graph searches' outcome where known."""
    m = problem.model
    spec = problem.specification
    prop = spec.property
    maximize = spec.strategy == Objective.MAXIMIZE
    pessimistic = spec.satisfaction == Adversary.PESSIMISTIC
    adversary_minimizes = maximize == pessimistic
    rows = problem.row_mask()
    fixed = ~graph.has_row(m, rows)
    fixed_val = np.zeros(m.n_states)
    reach = isinstance(prop, ReachAvoid)
    if reach and alg.initial is not None:
        raise SpecificationError("initial values are for discounted reward (reachability from 0)")
    guess = None  # the sweeps' layout, built while the graph searches run
    if reach:
        settled, fixed_val, settled_choice, guess = _settled(
            m, prop, rows, maximize, pessimistic, alg.precompute, target_closed, searched
        )
        fixed = fixed | settled
    fixed_val = np.where(fixed, fixed_val, 0.0)
    if guess is None:
        free_rows = np.flatnonzero(rows & ~fixed[m.row_state])
    else:
        free_rows = guess.layout.free_rows  # the same rows, formed once
    rs = m.row_state[free_rows]
    seg = first_of_runs(rs)
    sigma, evaluations, upper_sweeps = None, 0, 0
    # a minimising strategy, certified: through its dual (see the module docstring)
    dual = reach and not maximize and alg.precompute and alg.certified
    if reach:
        if dual:
            lower, upper, r = dual_reach(m, free_rows, fixed, fixed_val, adversary_minimizes, alg)
        else:
            layout = None if guess is None else guess.layout
            r = reach_values(m, free_rows, fixed_val, adversary_minimizes, maximize, alg, layout)
            lower, upper = r.lower, r.upper
            if guess is not None:
                settled_choice = guess.confirm()
        v, residual, it, sigma = lower.copy(), r.residual, r.iterations, r.sigma
        evaluations, q_free, upper_sweeps = r.evaluations, r.q, r.upper_sweeps
        converged = (
            bool(np.max(upper - lower, initial=0.0) < alg.tolerance) and r.verified
            if alg.certified
            else bool(residual < alg.tolerance)
        )
        final_v = v
    else:
        reward = np.asarray(prop.reward, dtype=np.float64)
        d = discounted_values(
            m, free_rows, fixed, reward, float(prop.discount), adversary_minimizes, maximize, alg
        )
        v, lower, upper, residual, it = d.values, d.lower, d.upper, d.residual, d.iterations
        q_free, converged = d.q, d.converged
        final_v = reward + float(prop.discount) * v
    greedy_v, greedy_max = (r.lower, True) if dual else (v, maximize)  # the dual's is ours
    strategy = strategy_actions(
        m, free_rows, q_free, seg, rs[seg], greedy_v, greedy_max, prop, alg.tolerance
    )
    if sigma is not None:
        # strategy iteration's strategy: its exact value is the least fixed point
        strategy[rs[seg]] = m.row_action[sigma]
    if reach:
        strategy = np.where(settled_choice >= 0, m.row_action[settled_choice], strategy)
    return Solution(
        values=v,
        strategy=strategy,
        residual=residual,
        iterations=it,
        converged=converged,
        fixed=fixed,
        evaluations=evaluations,
        lower=lower,
        upper=upper,
        upper_sweeps=upper_sweeps,
        _q=_row_values(m, rows, adversary_minimizes, final_v),
    )
