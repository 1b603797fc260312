"""Minimal reachability: the states a minimising controller settles by graph analysis,
and the dual problem that certifies its values.

A minimising controller's value-0 states ``Z`` are the largest set in which it can keep
every run away from the target (:func:`unavoidable_reach`). Every run of an optimal
minimising strategy that never reaches the target ends in ``Z`` (an end component it could
hover in for ever lies in ``Z``), so

    ``V_min(reach target) = 1 - V_max(reach Z)``

with the target held at 0 and the adversary's goal reversed: an adversary that opposes
the minimiser (drives runs to the target) keeps them from ``Z``, one that cooperates
drives them to ``Z``. The dual is a maximal reachability problem and has that side's
certified machinery (interval iteration with end components, strategy iteration;
:func:`planner.imdp.reachability.reach_values`); its bracket ``[L, U]`` gives ``[1 - U,
1 - L]`` (:func:`dual_reach`), and its optimal strategy is the minimising one.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from planner.imdp import graph
from planner.imdp.kernels import attractor
from planner.imdp.model import IMDP, first_of_runs
from planner.imdp.problem import ValueIteration
from planner.imdp.reachability import ReachResult, reach_values


def unavoidable_reach(
    model: IMDP,
    target: np.ndarray,
    avoid: np.ndarray | None = None,
    rows: np.ndarray | None = None,
    cooperative: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """States whose *minimal* probability of ``(!avoid) U target`` is positive: a
    minimising controller cannot keep it at 0, against an opposing adversary or, with
    ``cooperative``, with one that minimises too (targets included).

    Returns ``(mask, row)``: ``row[s]``, for a state outside the mask with rows, one that
    keeps every run outside it (-1 elsewhere).

    The complement is the largest set outside ``target`` in which the controller can keep
    every run: a state stays when one of its rows keeps all mass in the set, under every
    adversary (every ``upper > 0`` successor inside) or, cooperative, under some adversary
    (no ``lower > 0`` edge out, the upper bounds inside summing to at least 1; computed
    as the states joining when *every* row leaks: :func:`planner.imdp.kernels.attractor`
    with ``every_row``; the sums are compared with 1 exactly, so the set of value-0
    states found is the true one and settling it at 0 keeps an upper bound sound).
    ``avoid`` states and states without rows never join (a run there never reaches
    ``target``).
    """
    m = model
    target, cand = graph.reach_rows(m, target, avoid, rows)
    mask, _, led = attractor(target.copy(), cand, *graph.attractor_arrays(m), True, cooperative)
    staying = np.flatnonzero(cand & ~led & ~mask[m.row_state])
    row = np.full(m.n_states, -1, dtype=np.int64)
    # rows are sorted by state: the first staying row of each state
    first = staying[first_of_runs(m.row_state[staying])]
    row[m.row_state[first]] = first
    return mask, row


def dual_reach(
    m: IMDP,
    free_rows: np.ndarray,
    fixed: np.ndarray,
    fixed_val: np.ndarray,
    adversary_minimizes: bool,
    alg: ValueIteration,
) -> tuple[np.ndarray, np.ndarray, ReachResult]:
    """The certified bracket ``(lower, upper)`` of a minimal reachability problem whose
    value-0 and value-1 states are settled (``fixed``, with ``fixed_val``), from its dual,
    and the dual's result (its ``q``, strategy and counts are the maximising side's).

    The bracket is rounded outwards on the free states (``1 - x`` is exact for
    ``x >= 0.5`` and off by at most half an ulp of 1 below it) and exact on the settled
    ones. Where the dual's upper bound was not shown in exact arithmetic
    (:attr:`ReachResult.verified`) the lower bound is 0 on the free states."""
    dual_val = np.where(fixed, 1.0 - fixed_val, 0.0)
    slack = np.finfo(float).eps / 2
    # the dual closes its bracket within the tolerance less the rounding added below
    inner = replace(alg, tolerance=max(alg.tolerance - 2 * slack, alg.tolerance / 2))
    r = reach_values(m, free_rows, dual_val, not adversary_minimizes, True, inner)
    # the dual's upper bound is a proof only where it was shown in exact arithmetic
    shown = np.maximum(0.0, 1.0 - r.upper - slack) if r.verified else 0.0
    lower = np.where(fixed, fixed_val, shown)
    upper = np.where(fixed, fixed_val, np.minimum(1.0, 1.0 - r.lower + slack))
    return lower, upper, r
