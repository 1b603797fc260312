"""Upper bounds for reachability values, and their certificate.

The maximal (or minimal) reachability value ``V*`` of an interval MDP is the *least* fixed
point of its Bellman operator ``T`` with the targets held at 1. By Knaster-Tarski every
superharmonic vector, ``T(U) <= U`` (targets at 1), is at least the least fixed point, so
checking ``T(U) <= U`` once certifies ``U`` as an upper bound; no end-component analysis is
needed for the check. :func:`planner.imdp.kernels.upper_sweep` does the check and lowers
``U`` at the same time (a Gauss-Seidel pass that never raises a value; a pass without a
violation leaves a superharmonic vector).

The candidate (:func:`optimistic_candidate`, optimistic value iteration, Hartmanns and
Kaminski 2020) is ``min(1, L + delta)`` from the values ``L`` from below, lowered by a few
checking passes: cheap, and it passes where the values from below have settled to well
within ``delta`` *relative to their own pending change*. It fails where mass circulates
for a long time among free states (a slow leak, or strategies that can hover near a
value): there ``T(L + delta) - (L + delta)`` keeps the pending change of ``L``. The solver
then makes ``L`` exact by strategy iteration (when the model is small enough for its
sparse solves) and checks again: at the least fixed point ``V*`` itself,
``T(V* + delta) <= V* + delta`` always holds.
"""

from __future__ import annotations

import numpy as np

from planner.imdp.kernels import ReachSweeper

OVI_PASSES = 8
"""Checking passes per optimistic candidate."""


def check_upper(sweeper: ReachSweeper, u: np.ndarray, passes: int) -> tuple[bool, int]:
    """Up to ``passes`` checking passes on ``u`` in place; ``(certified, passes used)``.
    Stops early once the number of violations no longer decreases over two passes."""
    last = None
    stalled = 0
    for k in range(1, passes + 1):
        _, bad = sweeper.upper_pass(u)
        if bad == 0:
            return True, k
        stalled = stalled + 1 if last is not None and bad >= last else 0
        if stalled >= 2:
            return False, k
        last = bad
    return False, passes


def optimistic_candidate(
    sweeper: ReachSweeper, lower: np.ndarray, delta: float
) -> tuple[np.ndarray | None, int]:
    """``min(1, lower + delta)`` on the free states, checked; ``(U or None, passes)``."""
    u = lower.copy()
    st = sweeper.states
    u[st] = np.minimum(1.0, lower[st] + delta)
    ok, passes = check_upper(sweeper, u, OVI_PASSES)
    return (u if ok else None), passes
