"""The paper's synthesis (Section V) on one product model, step by step.

Given the MT-PIMDP ``P+`` of the current abstraction (:class:`~planner.imdp.product.ProductIMDP`),
:func:`synthesise` computes, in the order of the paper:

1. the worst-case satisfaction probabilities ``P_check`` (:func:`analysis.satisfaction`);
2. the *failure states* (best-case probability 0) and the *nonviolating* sub-model that
   cannot reach them (Jiang et al. 2023, Alg. 1);
3. the *MEC choice* (Section V-C, :func:`exploration_target`) among the pessimistic maximal
   end components of the nonviolating sub-model (``candidates="nonviolating"``) or the
   robustly accepting ones (``"accepting"``, falling back to the former if there are none):
   those reachable from the current state with worst-case probability 1 if any, else those of
   the highest worst-case probability, then the highest average reward
   ``(1/|T|) sum_T W``; remaining ties go to the component holding the current state, then to
   the larger one (then the first found);
4. *steering* (:func:`exploration_strategy`): the exploration's LTL action maximises the
   worst-case probability of reaching the chosen component within the nonviolating
   sub-model, heading along the shortest possible paths (:func:`frontier_strategy`) where that
   probability is 0, and inside it follows a :class:`~planner.tour.ComponentTour`; the
   fallback plan for states without a nonviolating action (every enabled action allowed,
   the LTL action the safest way back: :func:`fallback_strategy`);
5. the *satisfying* sub-model for ``P_sat`` (Section V-D) and its *goal-reaching strategy*;
6. the robust *Q-values* of the reward on the nonviolating sub-model, with nothing planned
   after the run's end (:func:`reward_actions`, :func:`q_values`).

Where the worst-case probability of reaching the chosen component is 0 (early on, when the
wide prior intervals let the adversary cut every way), heading for it along possible paths
collects data on the way there, while safety still comes from the nonviolating sub-model. (A
strategy that merely maximises the best-case probability does not do this: under the prior
that probability is 1 almost everywhere, every action ties, and the robot idles.)

Steps 2-4 do not depend on step 1: they run on a worker thread while step 1 runs
(:func:`planner._util.threads.concurrently`; on the 100 x 100 benchmark grid the two take
about 1 s and 0.3 s alone). Each step is timed (``Synthesis.synthesis_detail``; the seconds
of steps 2-4 overlap those of step 1). Nothing is printed or logged.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from scipy.sparse.csgraph import dijkstra

from planner._util.threads import concurrently
from planner.imdp import IMDP, Problem, ReachAvoid, Solution, Specification, analysis, graph, solve
from planner.imdp.analysis import MecChoice
from planner.imdp.graph import SubModel
from planner.imdp.model import first_of_runs
from planner.imdp.product import ProductIMDP
from planner.modes import Adversary, Candidates
from planner.policy import PhasePlan, RLActor
from planner.qlearning import GreedyQ, QSolution, RobustQLearner, robust_q_iteration
from planner.tour import ComponentTour

if TYPE_CHECKING:
    from planner.learning import PlannerConfig


@dataclass(frozen=True)
class Synthesis:
    """What :func:`synthesise` produced on ``product``; ``synthesis_detail``: seconds per
    step (``satisfaction``, ``nonviolating``, ``mec_choice`` when there are candidates,
    ``steering``, ``fallback``, ``goal_strategy``, ``q_values``; the first and the next
    three ran at the same time, on two threads)."""

    product: ProductIMDP
    satisfaction: Solution
    nonviolating: SubModel
    satisfying: SubModel
    mec: MecChoice | None
    tour: ComponentTour | None
    exploration: PhasePlan
    goal: PhasePlan
    fallback: PhasePlan
    q_allowed: np.ndarray
    q: QSolution
    rl: RLActor
    synthesis_detail: dict[str, float]


def synthesise(
    product: ProductIMDP,
    settings: PlannerConfig,
    *,
    start: int,
    uncertainty: np.ndarray,
    aim: np.ndarray | None = None,
    learner: RobustQLearner | None = None,
    previous_q: np.ndarray | None = None,
    clock: Callable[[], float] = time.perf_counter,
) -> Synthesis:
    """The steps of the module docstring from product state ``start``.

    Args:
        product: the MT-PIMDP, with the reward still to be collected as ``W``.
        settings: ``p_sat``, ``candidates``, ``tour``, ``discount``, ``q_tolerance``.
        start: the current product state (the MEC choice starts there).
        uncertainty: ``(n_states,)`` how little is known per product state (the tour's
            coverage order).
        aim: ``(n_rows,)`` the product state each row aims at (the tour's steps).
        learner: an unknown reward's learner (its sweep gives the Q-values).
        previous_q: a Q-table of the same product states to warm-start the Q-iteration.
        clock: time source for ``synthesis_detail``.
    """
    laps = _Laps(clock)
    side = _Laps(clock)

    def satisfaction() -> Solution:
        sat = analysis.satisfaction(product)
        laps("satisfaction")
        return sat

    # steps 2-4 do not read step 1: they run on a second thread meanwhile, sharing the
    # model's reverse index, built here once
    product.model.reverse_index()
    safe, sat = concurrently(
        lambda: _safety_steps(product, settings, start, uncertainty, aim, side),
        satisfaction,
        "synthesis",
    )
    nonviolating = safe.nonviolating
    laps.restart()
    fallback = fallback_strategy(product, sat, nonviolating, safe.failure)
    laps("fallback")
    satisfying = analysis.satisfying(product, settings.p_sat, sat)
    goal = analysis.goal_strategy(product, allowed=satisfying.actions)
    laps("goal_strategy")
    q_allowed = reward_actions(product, nonviolating)
    q, rl = q_values(product.model, product.reward, q_allowed, settings, learner, previous_q)
    laps("q_values")
    return Synthesis(
        product=product,
        satisfaction=sat,
        nonviolating=nonviolating,
        satisfying=satisfying,
        mec=safe.mec,
        tour=safe.tour,
        exploration=PhasePlan.masked(nonviolating.actions, safe.steer),
        goal=PhasePlan.masked(satisfying.actions, goal),
        fallback=PhasePlan.masked(product.model.enabled.copy(), fallback),
        q_allowed=q_allowed,
        q=q,
        rl=rl,
        synthesis_detail={"satisfaction": laps.seconds["satisfaction"]}
        | side.seconds
        | laps.seconds,
    )


@dataclass(frozen=True)
class _Safety:
    """Steps 2-4 of the module docstring."""

    failure: np.ndarray
    nonviolating: SubModel
    mec: MecChoice | None
    tour: ComponentTour | None
    steer: np.ndarray


def _safety_steps(
    product: ProductIMDP,
    settings: PlannerConfig,
    start: int,
    uncertainty: np.ndarray,
    aim: np.ndarray | None,
    laps: _Laps,
) -> _Safety:
    """Failure states, nonviolating sub-model, MEC choice (and its tour), steering; timed
    by ``laps`` from their start."""
    laps.restart()
    failure = analysis.failure_states(product)
    nonviolating = analysis.nonviolating(product, failure)
    laps("nonviolating")
    mec = exploration_target(product, nonviolating, settings.candidates, start)
    tour = None
    if mec is not None:
        laps("mec_choice")
        tour = ComponentTour(
            product.model,
            mec.component,
            nonviolating.actions,
            product.base_state,
            product.reward,
            uncertainty,
            settings.tour,
            aim=aim,
        )
    steer = exploration_strategy(product, mec, nonviolating)
    laps("steering")
    return _Safety(failure, nonviolating, mec, tour, steer)


def exploration_target(
    product: ProductIMDP, nonviolating: SubModel, candidates: Candidates, start: int
) -> MecChoice | None:
    """The MEC choice from product state ``start`` (see the module docstring; ``None``:
    no candidate). ``index`` is the component's index among the candidates found."""
    mecs = []
    if candidates == Candidates.ACCEPTING:
        mecs = analysis.accepting_end_components(product)
    if not mecs:
        mecs = analysis.end_components(product, nonviolating.actions)
    if not mecs:
        return None
    # choose_mec takes the first of equally good candidates: order them so that a tie goes
    # to the component holding the current state, then to the larger one
    order = sorted(range(len(mecs)), key=lambda k: (start not in mecs[k].states, -len(mecs[k])))
    ordered = [mecs[k] for k in order]
    mec = analysis.choose_mec(product, ordered, state=start, allowed=nonviolating.actions)
    return replace(mec, index=order[mec.index])


def exploration_strategy(
    product: ProductIMDP, mec: MecChoice | None, nonviolating: SubModel
) -> np.ndarray:
    """The exploration's LTL action: towards ``mec`` within the nonviolating sub-model
    (:func:`analysis.steer_strategy`; where no action reaches it with positive worst-case
    probability, :func:`frontier_strategy`), or, without a component, the worst-case
    satisfaction strategy within the nonviolating sub-model."""
    if mec is None:
        return analysis.goal_strategy(product, allowed=nonviolating.actions)
    pm = product.model
    steer = analysis.steer_strategy(product, mec.component, allowed=nonviolating.actions)
    inside = mec.component.state_mask(pm.n_states)
    open_ = (steer < 0) & ~inside
    if open_.any():
        steer = np.where(open_, frontier_strategy(pm, inside, nonviolating.actions), steer)
    return steer


def frontier_strategy(model: IMDP, target: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """Per state, the allowed action that heads for ``target`` through the *whole* model.

    ``d(s)`` is the least number of hops from ``s`` to ``target`` along edges with
    ``upper > 0`` of any action (unreachable: ``n_states``); an action's score is the mean of
    ``d`` over its successors weighted by their upper bounds; the allowed action of least
    score wins (-1 where nothing is allowed). A heuristic for exploration only: it moves the
    robot to the edge of its safe region nearest the target, where new data widen that
    region; it carries no probability guarantee.
    """
    g = graph.state_graph(model)
    tgt = np.flatnonzero(np.asarray(target, dtype=bool))
    if tgt.size == 0:
        return np.full(model.n_states, -1, dtype=np.int64)
    dist = dijkstra(g.T.tocsr(), unweighted=True, indices=tgt, min_only=True)
    dist = np.where(np.isfinite(dist), dist, float(model.n_states))
    w = model.upper
    num = np.bincount(model.entry_row, weights=w * dist[model.successor], minlength=model.n_rows)
    den = np.bincount(model.entry_row, weights=w, minlength=model.n_rows)
    score = np.where(den > 0, num / np.maximum(den, 1e-300), np.inf)
    ok = np.asarray(allowed, dtype=bool)[model.row_state, model.row_action]
    score = np.where(ok, score, np.inf)
    best = np.minimum.reduceat(score, model.state_ptr[:-1])
    first = np.full(model.n_states, -1, dtype=np.int64)
    is_best = ok & (score == best[model.row_state]) & np.isfinite(score)
    idx = np.flatnonzero(is_best)[::-1]  # reversed: the lowest row index is written last
    first[model.row_state[idx]] = model.row_action[idx]
    return first


_NEGLIGIBLE = 1e-8  # the default tolerance of robust value iteration


def fallback_strategy(
    product: ProductIMDP,
    satisfaction: Solution,
    nonviolating: SubModel,
    failure: np.ndarray | None = None,
) -> np.ndarray:
    """The action for states without a nonviolating action, in this order of preference:

    1. where the worst-case satisfaction probability is positive, the action maximising it;
    2. else, where some action returns to the nonviolating sub-model without passing a
       failure state with positive worst-case probability, the action maximising that
       probability (``(!fail) U nonviolating``, pessimistic);
    3. else the action whose worst-case probability of entering a failure state in this
       very hop, ``min(sum_fail u_j, 1 - sum_other l_j)``, is least, then whose summed
       upper bound into failure states ``sum_fail u_j`` is least (ties: the action that
       maximises the best-case satisfaction probability, if it is among them).

    Without 2 and 3, states whose worst case is 0 everywhere (unexplored, wide intervals)
    would take the best-case optimal action, and under wide intervals every action ties at
    best-case probability 1, hops aimed straight at a hazard included.

    ``failure``: the failure states (default: :func:`~planner.imdp.analysis.failure_states`).
    Returns ``(n_states,)`` actions (-1 where a state has none).
    """
    pm = product.model
    best = satisfaction.strategy.copy()
    # values within the solver's tolerance of 0 are 0: astronomically small positive values
    # (products of small lower bounds) come with arbitrary strategies
    open_ = (satisfaction.values <= _NEGLIGIBLE) | (best < 0)
    if not open_.any():
        return best
    fail = analysis.failure_states(product) if failure is None else failure
    back = solve(Problem(pm, Specification(ReachAvoid(nonviolating.states & ~fail, fail))))
    use_back = open_ & (back.values > _NEGLIGIBLE) & (back.strategy >= 0)
    best = np.where(use_back, back.strategy, best)
    rest = open_ & ~use_back
    if rest.any():
        into = fail[pm.successor]
        fail_up = np.add.reduceat(np.where(into, pm.upper, 0.0), pm.row_ptr[:-1])
        other_lo = np.add.reduceat(np.where(into, 0.0, pm.lower), pm.row_ptr[:-1])
        risk = np.minimum(fail_up, 1.0 - other_lo)
        least = np.minimum.reduceat(risk, pm.state_ptr[:-1])
        safest = risk <= least[pm.row_state] + 1e-12
        # under wide intervals every hop may fail at once: then the least summed upper
        # bound into failure states (the hop not aimed at them) decides
        up_safest = np.where(safest, fail_up, np.inf)
        least_up = np.minimum.reduceat(up_safest, pm.state_ptr[:-1])
        safest &= up_safest <= least_up[pm.row_state] + 1e-12
        optimistic = analysis.satisfaction(product, Adversary.OPTIMISTIC).strategy
        prefer = safest & (pm.row_action == optimistic[pm.row_state])
        first_safe = np.full(pm.n_states, -1, dtype=np.int64)
        safe_rows = np.flatnonzero(safest)
        first = safe_rows[first_of_runs(pm.row_state[safe_rows])]
        first_safe[pm.row_state[first]] = pm.row_action[first]
        pref_rows = np.flatnonzero(prefer)
        has_pref = np.zeros(pm.n_states, dtype=bool)
        has_pref[pm.row_state[pref_rows]] = True
        pick = np.where(has_pref, optimistic, first_safe)
        best = np.where(rest, pick, best)
    return best


def reward_actions(product: ProductIMDP, nonviolating: SubModel) -> np.ndarray:
    """The actions the reward plan maximises over: those of the nonviolating sub-model, none in
    product states whose automaton state is a sink (the run ends there, in success or
    violation), so that ``V = 0`` there and no reward is planned after the end of a run.
    (Without this the plan valued entering the goal by the rewards it could collect in the
    accepting part of the product, and steered runs into the goal to "collect" them.)"""
    return nonviolating.actions & ~product.absorbing[:, None]


def q_values(
    model: IMDP,
    reward: np.ndarray,
    allowed: np.ndarray,
    settings: PlannerConfig,
    learner: RobustQLearner | None = None,
    initial: np.ndarray | None = None,
) -> tuple[QSolution, RLActor]:
    """The reward plan: known reward ``W`` per product state, the robust Q-iteration
    (:func:`robust_q_iteration`, warm-started from ``initial``) and its greedy actor;
    unknown reward, the ``learner``'s sweep on its learned rewards (``reward`` unused) and
    the learner itself."""
    if learner is not None:
        return learner.sweep(model, allowed=allowed, tolerance=settings.q_tolerance), learner
    q = robust_q_iteration(
        model,
        reward,
        discount=settings.discount,
        allowed=allowed,
        initial=initial,
        tolerance=settings.q_tolerance,
    )
    return q, GreedyQ(np.nan_to_num(q.q, nan=-np.inf))


class _Laps:
    """Seconds per named step, measured between successive calls."""

    def __init__(self, clock: Callable[[], float]) -> None:
        self.clock, self.last, self.seconds = clock, clock(), {}

    def __call__(self, name: str) -> None:
        now = self.clock()
        self.seconds[name] = now - self.last
        self.last = now

    def restart(self) -> None:
        """The next step starts now."""
        self.last = self.clock()
