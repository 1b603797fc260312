"""Compile the numba kernels before the first synthesis of a run.

The value-iteration and graph kernels (:mod:`planner.imdp.kernels`) are compiled by numba on
first use and cached on disk (beside the module, or in numba's user cache where that folder
is not writable). On a fresh installation the first synthesis therefore spends seconds in the
compiler; :func:`compile_kernels` spends them up front, on a 4 x 4 world, through the same
:func:`planner.learning.resynthesise` a run calls (known and unknown reward), so a caller can
say what is happening. Afterwards it costs the loading of the cached code, a fraction of a
second.
"""

from __future__ import annotations

import time

import numpy as np


def compile_kernels() -> float:
    """Run one synthesis of the learning loop on a toy world; returns the seconds it took.

    The toy world is 4 x 4 cells of 1 m with the goal in the far corner, one hazard cell and
    the formula ``!Haz U Goal``; the landing-error GPs have no data (their prior alone sets the
    intervals), as at the start of every run.
    """
    from planner.gp.landing import LandingErrorGP
    from planner.imdp import IMDP, OrderingAdversary
    from planner.imdp.certify import verify_upper
    from planner.imdp.grid import ACTIONS, GridWorld
    from planner.imdp.kernels import ReachSweeper
    from planner.imdp.widening import rounding_widened
    from planner.learning import resynthesise
    from planner.ltl.translate import translate
    from planner.qlearning import RobustQLearner

    t0 = time.perf_counter()
    nx = ny = 4
    labels: list[frozenset[str]] = [frozenset()] * (nx * ny)
    labels[(nx - 1) * ny + ny - 1] = frozenset({"Goal"})
    labels[2 * ny + 1] = frozenset({"Haz"})
    grid = GridWorld(nx, ny, 1.0, labels, "Haz")
    automaton = translate("!Haz U Goal")
    none = np.zeros((0, 2))
    reward = np.zeros(grid.n_states)
    reward[1] = 1.0
    resynthesise(LandingErrorGP(), grid, automaton, none, none, reward=reward, initial_cell=0)
    n_product = grid.n_states * automaton.n_states
    learner = RobustQLearner(
        n_product,
        len(ACTIONS),
        grid.n_states,
        state_cell=np.arange(n_product) // automaton.n_states,
    )
    resynthesise(LandingErrorGP(), grid, automaton, none, none, learner=learner, initial_cell=0)
    # a stored adversary re-sorting its rows (the toy synthesis never needs to)
    model = IMDP(
        3, [0, 0, 0, 1, 2], [0] * 5, [0, 1, 2, 1, 2], [0.1] * 3 + [1.0] * 2, [0.9] * 3 + [1.0] * 2
    )
    adversary = OrderingAdversary(model)
    adversary.expectation(np.array([0.0, 0.5, 1.0]))
    adversary.expectation(np.array([1.0, 0.5, 0.0]))
    # the exact check's first pass made ahead on two threads, as on large models
    verify_upper(model, np.array([0]), np.array([0.5, 0.5, 1.0]), True, True, halves_entries=0)
    # the rounding widening's search for short stays (and its search over a chain's own
    # edges), which a certificate stops once the uniform raise beside it is shown: a race
    # the toy synthesis may or may not run into
    free = np.array([0])
    sweeper = ReachSweeper(model, free, np.zeros(3), True, True)
    low, high = np.array([0.4, 0.5, 1.0]), np.array([0.6, 0.5, 1.0])
    rounding_widened(model, free, low, high, True, True, 1e-8, sweeper)
    return time.perf_counter() - t0
