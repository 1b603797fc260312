"""One re-synthesis of the learning loop, run after every batch of hops (pure planning).

Steps (docs/design.md "Policies" and "Rewards"), timed separately:

1. ``gp_fit``: condition the direction-aware landing-error model on all hops so far
   (departure position, landing error, executed action; :class:`~planner.gp.LandingErrorGP`).
2. ``abstraction``: per-(cell, action) error bounds, transition intervals, the grid IMDP and
   the MT-PIMDP product with the automaton and the reward still to be collected (``W``, with
   the cells this run has already collected at 0 where cells pay once per run;
   :mod:`planner.intervals` states what the intervals guarantee).
3. ``synthesis``: the paper's Section V on that product (:func:`planner.synthesis.synthesise`:
   satisfaction, failure states, nonviolating sub-model, MEC choice, steering and the
   in-component tour, fallback, satisfying sub-model, goal strategy, Q-values). With
   ``candidates="accepting"`` (the goal-directed variant) exploration heads for the goal
   while the RL action collects reward, and a run often reaches the goal before it has
   learned anything.

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
from dataclasses import dataclass, fields

import numpy as np

from planner.automaton import RabinAutomaton
from planner.config import CANDIDATES as CANDIDATES  # re-exported (defined there)
from planner.config import PlannerConfig
from planner.errors import PolicyError
from planner.gp.landing import FitReport, LandingErrorGP
from planner.imdp import IMDP
from planner.imdp.grid import GridWorld
from planner.imdp.product import ProductIMDP
from planner.intervals import (
    CellErrorBounds,
    TransitionIntervals,
    cell_error_bounds,
    transition_intervals,
)
from planner.policy import RLActor
from planner.qlearning import QSolution, RobustQLearner
from planner.synthesis import Synthesis, q_values, synthesise
from planner.tour import ComponentTour


@dataclass(frozen=True)
class Resynthesis(Synthesis):
    """Everything one re-synthesis produced: the :class:`~planner.synthesis.Synthesis` on
    the product and what it was built from; ``timings`` in seconds per step (``gp_fit``,
    ``abstraction``, ``synthesis``), ``synthesis_detail`` splits the last."""

    fit: FitReport
    bounds: CellErrorBounds
    intervals: TransitionIntervals
    model: IMDP
    timings: dict[str, float]


def aimed_successors(product: ProductIMDP, grid: GridWorld) -> np.ndarray:
    """``(n_rows,)`` the product state each row of ``product.model`` aims at: the cell its
    hop is aimed at (``grid.target_cell``) with the automaton's step on entering it (-1 for
    rows of states that are not grid cells)."""
    pm = product.model
    cell = product.base_state[pm.row_state]
    is_cell = cell < grid.n_cells
    target = np.full(pm.n_rows, -1, dtype=np.int64)
    target[is_cell] = grid.target_cell[cell[is_cell], pm.row_action[is_cell]]
    ok = target >= 0
    aim = np.full(pm.n_rows, -1, dtype=np.int64)
    aim[ok] = product.steps(pm.row_state[ok], target[ok])
    return aim


def uncertainty(
    bounds: CellErrorBounds, grid: GridWorld, learner: RobustQLearner | None = None
) -> np.ndarray:
    """``(grid.n_states,)`` a cell's uncertainty for the tour: the summed widths of its error
    intervals (0 for ``out``) and, for a learned reward, first of all whether its reward was
    ever observed."""
    gap = np.asarray(bounds.upper) - np.asarray(bounds.lower)
    width = np.append(gap.reshape(grid.n_cells, -1).sum(axis=1), 0.0)
    if learner is not None:
        width = width + (width.max() + 1.0) * (learner.reward_count == 0)
    return width


def _remaining(w: np.ndarray, collected: np.ndarray | None, n: int) -> np.ndarray:
    if w.shape != (n,):
        raise PolicyError(f"reward must have shape ({n},), got {w.shape}")
    if collected is None:
        return w
    done = np.asarray(collected, dtype=bool)
    if done.shape != (n,):
        raise PolicyError(f"collected must have shape ({n},), got {done.shape}")
    return np.where(done, 0.0, w)


def _check_inputs(
    gp: LandingErrorGP,
    positions: np.ndarray,
    actions: np.ndarray | None,
    reward: np.ndarray | None,
    learner: RobustQLearner | None,
    s: PlannerConfig,
) -> np.ndarray:
    """The executed actions (empty without hops), after checking the inputs agree."""
    if (reward is None) == (learner is None):
        raise PolicyError("give exactly one of reward (known W) and learner (unknown W)")
    if gp.settings.noise != s.noise:
        raise PolicyError(
            f"the GP's landing noise {gp.settings.noise} differs from the intervals' {s.noise}"
        )
    n_hops = int(np.shape(positions)[0]) if np.ndim(positions) else 0
    if actions is None:
        if n_hops:
            raise PolicyError(f"{n_hops} hops given without their executed actions")
        return np.zeros(0, dtype=np.int64)
    return actions


def _reward_to_collect(
    grid: GridWorld,
    reward: np.ndarray | None,
    learner: RobustQLearner | None,
    collected: np.ndarray | None,
) -> np.ndarray:
    """``W`` per grid state still to be collected (known, or the learner's belief)."""
    if reward is not None:
        return _remaining(np.asarray(reward, dtype=np.float64), collected, grid.n_states)
    assert learner is not None
    w = learner.remaining_reward()
    if w.shape != (grid.n_states,):
        raise PolicyError(
            f"the learner's reward cells must be the {grid.n_states} grid states, got {w.shape[0]}"
        )
    return w


def _abstraction(
    gp: LandingErrorGP, grid: GridWorld, s: PlannerConfig, initial_cell: int
) -> tuple[CellErrorBounds, TransitionIntervals, IMDP]:
    """Per-(cell, action) error bounds of ``gp``, their transition intervals, the grid IMDP."""
    bounds = cell_error_bounds(
        gp,
        grid,
        samples_per_axis=s.samples_per_axis,
        delta=s.delta,
        horizon=s.horizon,
        beta=s.beta,
    )
    intervals = transition_intervals(bounds, grid, s.noise)
    return bounds, intervals, grid.imdp_from_intervals(*intervals.coo(), initial=[initial_cell])


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
    settings: PlannerConfig | None = None,
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
        settings: see :class:`PlannerConfig`.
        previous: the last re-synthesis of this run; its Q-table warm-starts the known-reward
            Q-iteration (same grid and automaton, so the same product states).
        clock: time source for ``timings``.
    """
    s = settings or PlannerConfig()
    actions = _check_inputs(gp, positions, actions, reward, learner, s)
    t0 = clock()
    fit = gp.fit(positions, errors, actions)
    t1 = clock()
    bounds, intervals, model = _abstraction(gp, grid, s, initial_cell)
    product = ProductIMDP(model, automaton, _reward_to_collect(grid, reward, learner, collected))
    t2 = clock()
    syn = synthesise(
        product,
        s,
        start=product.initial if current_state is None else int(current_state),
        uncertainty=uncertainty(bounds, grid, learner)[product.base_state],
        aim=aimed_successors(product, grid),
        learner=learner,
        previous_q=None if previous is None else previous.q.q,
        clock=clock,
    )
    t3 = clock()
    return Resynthesis(
        **{f.name: getattr(syn, f.name) for f in fields(Synthesis)},
        fit=fit,
        bounds=bounds,
        intervals=intervals,
        model=model,
        timings={"gp_fit": t1 - t0, "abstraction": t2 - t1, "synthesis": t3 - t2},
    )


def replan_reward(
    res: Resynthesis,
    *,
    reward: np.ndarray | None = None,
    learner: RobustQLearner | None = None,
    collected: np.ndarray | None = None,
    settings: PlannerConfig | None = None,
) -> tuple[QSolution, RLActor, ComponentTour | None]:
    """Re-solve the reward plan of ``res`` after a collection, on the same abstraction.

    Known reward: the robust Q-iteration on ``reward`` with the ``collected`` cells at 0,
    warm-started from ``res.q``; unknown reward: the learner's sweep (its own ``collected``
    applies). Returns the new Q-solution, the RL actor and ``res.tour`` with the new reward
    (``None`` if ``res`` has no tour). ``res`` itself is not changed.
    """
    if (reward is None) == (learner is None):
        raise PolicyError("give exactly one of reward (known W) and learner (unknown W)")
    s = settings or PlannerConfig()
    product = res.product
    if reward is not None:
        w = _remaining(np.asarray(reward, dtype=np.float64), collected, product.base.n_states)
        state_w = w[product.base_state]
    else:
        assert learner is not None
        state_w = learner.state_reward()
    q, rl = q_values(product.model, state_w, res.q_allowed, s, learner, res.q.q)
    tour = None if res.tour is None else res.tour.with_reward(state_w)
    return q, rl, tour
