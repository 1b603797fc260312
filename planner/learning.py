"""One re-synthesis of the learning loop, run after every batch of hops (pure planning).

Steps (docs/design.md "Policies" and "Rewards"), timed separately:

1. ``gp_fit``: condition the direction-aware landing-error model on all hops so far
   (departure position, landing error, executed action; :class:`~planner.gp.LandingErrorGP`).
2. ``abstraction``: per-(cell, action) error bounds, transition intervals, the grid IMDP and
   the MT-PIMDP product with the automaton and the reward still to be collected (``W``, with
   the cells this run has already collected at 0 where cells pay once per run;
   :mod:`planner.intervals` states what the intervals guarantee).
3. ``synthesis``: worst-case satisfaction probabilities; the nonviolating sub-model; the
   paper's MEC choice (Section V-C) among the pessimistic maximal end components of the
   *nonviolating* sub-model (``candidates="nonviolating"``, the default): those reachable from
   the current state with worst-case probability 1 if any, else those of the highest
   worst-case probability, then the highest average reward ``(1/|T|) sum_T W``; remaining ties
   go to the component holding the current state, then to the larger one (then the first
   found). The exploration's LTL action steers there within the nonviolating sub-model and,
   inside it, follows a :class:`~planner.tour.ComponentTour` that keeps moving through the
   component (instead of one fixed action per state). With ``candidates="accepting"`` (the
   goal-directed variant) the candidates are the robustly accepting end components instead
   (the nonviolating MECs if there are none): exploration then heads for the goal while the RL
   action collects reward, and a run often reaches the goal before it has learned anything.
   Where the worst-case probability of reaching the chosen component is 0 (early on, when the
   wide prior intervals let the adversary cut every way), :func:`frontier_strategy` heads for
   it along the shortest possible paths (``upper > 0`` edges), so that exploration collects
   data on the way there, while safety still comes from the nonviolating sub-model. (A
   strategy that merely maximises the best-case probability does not do this: under the prior
   that probability is 1 almost everywhere, every action ties, and the robot idles.) Then the
   satisfying sub-model for ``P_sat`` and its goal-reaching strategy; robust Q-values on the
   nonviolating sub-model, with nothing planned after the run's end (:func:`reward_actions`;
   known reward: :func:`robust_q_iteration`; unknown reward: the learner's warm-started sweep
   on its learned rewards); a fallback plan for states without a
   nonviolating action (:func:`fallback_strategy`): every enabled action allowed, the LTL
   action the safest way back.

Between re-syntheses, when a run collects a cell that pays once, :func:`replan_reward`
re-solves the Q-values (and the tour's rewards) with that cell at 0 on the same abstraction
(the MEC choice waits for the next re-synthesis).

The result holds everything a runner needs to act: the two :class:`PhasePlan` objects, the
worst-case satisfaction probabilities, the tour and the RL actor, ready for
:meth:`planner.policy.SwitchingPolicy.resynthesise`. Nothing is printed or logged.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse.csgraph import dijkstra

from planner.automaton import RabinAutomaton
from planner.config import CANDIDATES as CANDIDATES  # re-exported (defined there)
from planner.config import ResynthesisSettings
from planner.errors import PolicyError
from planner.gp.landing import FitReport, LandingErrorGP
from planner.imdp import IMDP, Problem, ReachAvoid, Solution, Specification, graph, solve
from planner.imdp.graph import SubModel
from planner.imdp.grid import GridWorld
from planner.imdp.model import first_of_runs
from planner.imdp.product import MecChoice, ProductIMDP
from planner.intervals import (
    CellErrorBounds,
    TransitionIntervals,
    cell_error_bounds,
    transition_intervals,
)
from planner.policy import PhasePlan, RLActor
from planner.qlearning import GreedyQ, QSolution, RobustQLearner, robust_q_iteration
from planner.tour import ComponentTour


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


@dataclass(frozen=True)
class Resynthesis:
    """Everything one re-synthesis produced; ``timings`` in seconds per step
    (``gp_fit``, ``abstraction``, ``synthesis``), ``synthesis_detail`` splits the last."""

    fit: FitReport
    bounds: CellErrorBounds
    intervals: TransitionIntervals
    model: IMDP
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
    timings: dict[str, float]
    synthesis_detail: dict[str, float]


_NEGLIGIBLE = 1e-8  # the default tolerance of robust value iteration


def fallback_strategy(
    product: ProductIMDP, satisfaction: Solution, nonviolating: SubModel
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

    Returns ``(n_states,)`` actions (-1 where a state has none).
    """
    pm = product.model
    best = satisfaction.strategy.copy()
    # values within the solver's tolerance of 0 are 0: astronomically small positive values
    # (products of small lower bounds) come with arbitrary strategies
    open_ = (satisfaction.values <= _NEGLIGIBLE) | (best < 0)
    if not open_.any():
        return best
    fail = product.failure_states()
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
        optimistic = product.satisfaction(pessimistic=False).strategy
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


def aimed_successors(product: ProductIMDP, grid: GridWorld) -> np.ndarray:
    """``(n_rows,)`` the product state each row of ``product.model`` aims at: the cell its
    hop is aimed at (``grid.target_cell``) with the automaton's step on entering it (-1 for
    rows of states that are not grid cells)."""
    pm = product.model
    cell = product.base_state[pm.row_state]
    q = product.automaton_state[pm.row_state]
    is_cell = cell < grid.n_cells
    target = np.full(pm.n_rows, -1, dtype=np.int64)
    target[is_cell] = grid.target_cell[cell[is_cell], pm.row_action[is_cell]]
    ok = target >= 0
    aim = np.full(pm.n_rows, -1, dtype=np.int64)
    q_next = product.automaton.transitions[q[ok], product.letters[target[ok]]]
    aim[ok] = target[ok] * product.n_q + q_next
    return aim


def reward_actions(product: ProductIMDP, nonviolating: SubModel) -> np.ndarray:
    """The actions the reward plan maximises over: those of the nonviolating sub-model, none in
    product states whose automaton state is a sink (the run ends there, in success or
    violation), so that ``V = 0`` there and no reward is planned after the end of a run.
    (Without this the plan valued entering the goal by the rewards it could collect in the
    accepting part of the product, and steered runs into the goal to "collect" them.)"""
    table = product.automaton.transitions
    sink = (table == np.arange(product.n_q)[:, None]).all(axis=1)
    return nonviolating.actions & ~sink[product.automaton_state][:, None]


def _remaining(w: np.ndarray, collected: np.ndarray | None, n: int) -> np.ndarray:
    if w.shape != (n,):
        raise PolicyError(f"reward must have shape ({n},), got {w.shape}")
    if collected is None:
        return w
    done = np.asarray(collected, dtype=bool)
    if done.shape != (n,):
        raise PolicyError(f"collected must have shape ({n},), got {done.shape}")
    return np.where(done, 0.0, w)


def resynthesise(
    gp: LandingErrorGP,
    grid: GridWorld,
    automaton: RabinAutomaton,
    positions: np.ndarray,
    errors: np.ndarray,
    *,
    actions: np.ndarray | None = None,
    reward: np.ndarray | None = None,
    learner: RobustQLearner | None = None,
    initial_cell: int = 0,
    current_state: int | None = None,
    collected: np.ndarray | None = None,
    settings: ResynthesisSettings | None = None,
    previous: Resynthesis | None = None,
    clock: Callable[[], float] = time.perf_counter,
) -> Resynthesis:
    """Refit, rebuild and re-synthesise (see the module docstring).

    Args:
        gp: the landing-error model, refitted in place on ``positions``/``errors``/``actions``.
        grid: the world (labels included).
        automaton: the Rabin automaton of the mandatory task.
        positions, errors: all departure positions and landing errors so far, ``(N, 2)``.
        actions: the executed action of every hop, ``(N,)`` (required when ``N > 0``).
        reward: known ``W`` per grid state (``grid.n_states``); exactly one of ``reward``
            and ``learner`` must be given.
        learner: for an unknown reward, a learner over the product states whose cells are
            the grid states (``state_cell = product.base_state``); its learned rewards
            (prior where unvisited) stand in for ``W`` in the product and the MEC choice.
        initial_cell: the IMDP's initial grid state.
        current_state: product state the MEC choice starts from (default: the initial).
        collected: ``(grid.n_states,)`` mask of the cells whose reward this run has already
            collected (cells that pay once); their ``W`` is 0 in the product, the MEC choice,
            the tour and the Q-values (default: none). For a learner, set its ``collected``
            instead (it applies it to its learned rewards).
        settings: see :class:`ResynthesisSettings`.
        previous: the last re-synthesis of this run; its Q-table warm-starts the known-reward
            Q-iteration (same grid and automaton, so the same product states).
        clock: time source for ``timings``.
    """
    if (reward is None) == (learner is None):
        raise PolicyError("give exactly one of reward (known W) and learner (unknown W)")
    s = settings or ResynthesisSettings()
    if gp.settings.noise != s.noise:
        raise PolicyError(
            f"the GP's landing noise {gp.settings.noise} differs from the intervals' {s.noise}"
        )
    n_hops = int(np.shape(positions)[0]) if np.ndim(positions) else 0
    if actions is None:
        if n_hops:
            raise PolicyError(f"{n_hops} hops given without their executed actions")
        actions = np.zeros(0, dtype=np.int64)
    t0 = clock()
    fit = gp.fit(positions, errors, actions)
    t1 = clock()
    bounds = cell_error_bounds(
        gp,
        grid,
        samples_per_axis=s.samples_per_axis,
        delta=s.delta,
        horizon=s.horizon,
        beta=s.beta,
    )
    intervals = transition_intervals(bounds, grid, s.noise)
    model = grid.imdp_from_intervals(*intervals.coo(), initial=[initial_cell])
    if reward is not None:
        w = _remaining(np.asarray(reward, dtype=np.float64), collected, grid.n_states)
    else:
        assert learner is not None
        w = learner.remaining_reward()
        if w.shape != (grid.n_states,):
            raise PolicyError(
                f"the learner's reward cells must be the {grid.n_states} grid states, got "
                f"{w.shape[0]}"
            )
    product = ProductIMDP(model, automaton, w)
    t2 = clock()
    detail: dict[str, float] = {}
    last = [t2]

    def lap(name: str) -> None:
        now = clock()
        detail[name] = now - last[0]
        last[0] = now

    pm = product.model
    satisfaction = product.satisfaction()
    lap("satisfaction")
    nonviolating = product.nonviolating()
    lap("nonviolating")
    start = product.initial if current_state is None else int(current_state)
    mecs = product.accepting_end_components() if s.candidates == "accepting" else []
    if not mecs:
        mecs = product.end_components(nonviolating.actions)
    mec, tour = None, None
    if mecs:
        # choose_mec takes the first of equally good candidates: order them so that a tie
        # goes to the component holding the current state, then to the larger one
        order = sorted(range(len(mecs)), key=lambda k: (start not in mecs[k].states, -len(mecs[k])))
        ordered = [mecs[k] for k in order]
        mec = product.choose_mec(ordered, state=start, allowed=nonviolating.actions)
        mec = replace(mec, index=order[mec.index])
        lap("mec_choice")
        steer = product.steer_strategy(mec.component, allowed=nonviolating.actions)
        inside = mec.component.state_mask(pm.n_states)
        if ((steer < 0) & ~inside).any():
            frontier = frontier_strategy(pm, inside, nonviolating.actions)
            steer = np.where((steer < 0) & ~inside, frontier, steer)
        # a cell's uncertainty: the summed widths of its error intervals (0 for `out`) and,
        # for a learned reward, first of all whether its reward was ever observed
        gap = np.asarray(bounds.upper) - np.asarray(bounds.lower)
        width = np.append(gap.reshape(grid.n_cells, -1).sum(axis=1), 0.0)
        if learner is not None:
            width = width + (width.max() + 1.0) * (learner.reward_count == 0)
        tour = ComponentTour(
            pm,
            mec.component,
            nonviolating.actions,
            product.base_state,
            product.reward,
            width[product.base_state],
            s.tour,
            aim=aimed_successors(product, grid),
        )
    else:
        steer = product.goal_strategy(allowed=nonviolating.actions)
    lap("steering")
    best = fallback_strategy(product, satisfaction, nonviolating)
    lap("fallback")
    satisfying = product.satisfying(s.p_sat, satisfaction)
    goal = product.goal_strategy(allowed=satisfying.actions)
    lap("goal_strategy")
    q_allowed = reward_actions(product, nonviolating)
    if learner is None:
        q = robust_q_iteration(
            pm,
            product.reward,
            discount=s.discount,
            allowed=q_allowed,
            initial=None if previous is None else previous.q.q,
            tolerance=s.q_tolerance,
        )
        rl: RLActor = GreedyQ(np.nan_to_num(q.q, nan=-np.inf))
    else:
        q = learner.sweep(pm, allowed=q_allowed, tolerance=s.q_tolerance)
        rl = learner
    lap("q_values")
    t3 = clock()
    return Resynthesis(
        fit=fit,
        bounds=bounds,
        intervals=intervals,
        model=model,
        product=product,
        satisfaction=satisfaction,
        nonviolating=nonviolating,
        satisfying=satisfying,
        mec=mec,
        tour=tour,
        exploration=PhasePlan.masked(nonviolating.actions, steer),
        goal=PhasePlan.masked(satisfying.actions, goal),
        fallback=PhasePlan.masked(pm.enabled.copy(), best),
        q_allowed=q_allowed,
        q=q,
        rl=rl,
        timings={"gp_fit": t1 - t0, "abstraction": t2 - t1, "synthesis": t3 - t2},
        synthesis_detail=detail,
    )


def replan_reward(
    res: Resynthesis,
    *,
    reward: np.ndarray | None = None,
    learner: RobustQLearner | None = None,
    collected: np.ndarray | None = None,
    settings: ResynthesisSettings | None = None,
) -> tuple[QSolution, RLActor, ComponentTour | None]:
    """Re-solve the reward plan of ``res`` after a collection, on the same abstraction.

    Known reward: the robust Q-iteration on ``reward`` with the ``collected`` cells at 0,
    warm-started from ``res.q``; unknown reward: the learner's sweep (its own ``collected``
    applies). Returns the new Q-solution, the RL actor and ``res.tour`` with the new reward
    (``None`` if ``res`` has no tour). ``res`` itself is not changed.
    """
    if (reward is None) == (learner is None):
        raise PolicyError("give exactly one of reward (known W) and learner (unknown W)")
    s = settings or ResynthesisSettings()
    product = res.product
    pm = product.model
    allowed = res.q_allowed
    if reward is not None:
        w = _remaining(np.asarray(reward, dtype=np.float64), collected, product.base.n_states)
        q = robust_q_iteration(
            pm,
            w[product.base_state],
            discount=s.discount,
            allowed=allowed,
            initial=res.q.q,
            tolerance=s.q_tolerance,
        )
        rl: RLActor = GreedyQ(np.nan_to_num(q.q, nan=-np.inf))
        state_w = w[product.base_state]
    else:
        assert learner is not None
        q = learner.sweep(pm, allowed=allowed, tolerance=s.q_tolerance)
        rl = learner
        state_w = learner.state_reward()
    tour = None if res.tour is None else res.tour.with_reward(state_w)
    return q, rl, tour
