"""The rounding allowance that the certified upper bound of a reachability solve is
raised by before its exact check (:func:`rounding_widened`)."""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from planner._util.threads import concurrently
from planner.imdp import certify, strategy
from planner.imdp.kernels import ReachSweeper
from planner.imdp.kernels.upper import ROUNDING
from planner.imdp.model import IMDP, first_of_runs, run_ids
from planner.imdp.stay import (
    chain_stay_allowance,
    inner_rows,
    shortest_stay,
    stay_limit,
    surest_exit_start,
    widening_room,
)
from planner.imdp.strategy import SI_MAX_STATES


def rounding_widened(
    m: IMDP,
    free_rows: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    adversary_minimizes: bool,
    maximize: bool,
    tolerance: float,
    sweeper: ReachSweeper,
    stop: Callable[[], bool] | None = None,
) -> np.ndarray | None:
    """``upper`` plus what rounding may have hidden from the floating-point checks: the
    candidate that :func:`planner.imdp.certify.verify_upper` checks in exact arithmetic
    (the proof; this raise lets it pass in 3-4 passes instead of 7-10).

    The checks accept ``T(U) <= U + ROUNDING`` and every evaluation is rounded, so along a
    strategy ``sigma`` whose rows satisfy that (with the adversary ``P`` of ``U``), ``U``
    is only known to be at least ``V_sigma - A^-1 e`` (``e`` the allowance per step,
    :func:`planner.imdp.stay.chain_stay_allowance`; 0 where that chain never leaves the
    free states, the strategy's value there being 0). ``U + A^-1 e`` of an optimal
    strategy would bound ``V*``; the strategy taken stands in for one:

    * minimising strategy: the strategy greedy for ``U`` (a true witness);
    * maximising strategy: among the rows within ``U - L`` of the best at ``U`` (where an
      optimal strategy's rows lie *if* ``U`` bounds ``V*``, which is what is to be shown:
      no proof) one of short stay: the greedy surest exit
      (:func:`planner.imdp.stay.surest_exit_start`), shortened by policy iteration
      (:func:`planner.imdp.stay.shortest_stay`) up to ``SI_MAX_STATES`` free
      states, until the widening fits in the room left to ``tolerance`` (or a tenth of
      an open bracket; :func:`planner.imdp.stay.widening_room`). Beyond
      ``SI_MAX_STATES`` free states, where no sparse LU runs, the rows greedy for ``U``
      are tried first and kept where their widening fits in that room (the random
      100k-state benchmark model: 96-146 ms against 203-255 ms for the search, the same
      raise of 3.5e-14 and the same exact check, draws 0-2). A slow exit below the
      allowance can escape it (7/8 was once certified as ``[0.9999999975, 1)``); not the
      exact check.

    Negligible where stays are short (the 100 x 100 benchmark grid: about 1e-11).

    ``sweeper``: the layout that computed the bracket; from its critical successors come
    every row's value at ``upper`` and the adversary's distributions of the near (or
    chosen) rows only, none sorted again (``row_values``, ``adversary_matrix``; 0.19 s
    to 0.15 s on the benchmark grid's seed 1 against the distributions of all rows).

    ``stop``: asked between the steps of the search (and by its policy iteration); once it
    says so the search ends and ``None`` is returned.
    """
    rs = m.row_state[free_rows]
    seg = first_of_runs(rs)
    st = rs[seg]
    stay = None  # the chosen chain's expected stays, when a policy iteration found them
    # the robust value of every free row at ``upper``; every chain below is a selection
    # of the rows, each with the adversary's distribution at ``upper``
    q = sweeper.row_values(upper)
    allowance = None
    if not maximize or st.size > SI_MAX_STATES:
        # the rows greedy for ``upper`` (for a maximising strategy among those that count
        # as optimal, the attractor's where they tie)
        choice = strategy.strategy_rows(m, free_rows, q, seg, st, upper, maximize, maximize, 0.0)
        chosen = np.searchsorted(free_rows, np.sort(choice[st]))
        chain = sweeper.adversary_matrix(upper, chosen)
        allowance = chain_stay_allowance(chain, rs[chosen], upper, ROUNDING, SI_MAX_STATES)
        if maximize:
            room = widening_room(lower[st], upper[st], tolerance)
            if not float(np.max(allowance[st], initial=0.0)) <= room:
                allowance = None  # stays too long for the room: the search for short ones
    if allowance is None:
        found = _short_stay_chain(m, free_rows, rs, seg, lower, upper, q, tolerance, sweeper, stop)
        if found is None:
            return None
        chosen, chain, stay = found
        if stop is not None and stop():
            return None
        allowance = chain_stay_allowance(
            chain, rs[chosen], upper, ROUNDING, SI_MAX_STATES, stay=stay
        )
    out = upper.copy()
    out[st] = np.minimum(1.0, upper[st] + allowance[st])
    return out


def _short_stay_chain(
    m: IMDP,
    free_rows: np.ndarray,
    rs: np.ndarray,
    seg: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    q: np.ndarray,
    tolerance: float,
    sweeper: ReachSweeper,
    stop: Callable[[], bool] | None,
) -> tuple[np.ndarray, sp.csr_matrix, np.ndarray | None] | None:
    """The maximising side of :func:`rounding_widened`: ``(chosen, chain, stay)``, the
    positions in ``free_rows`` of the rows of short stay, their distributions and the
    expected stays if a policy iteration found them; ``None`` once ``stop`` says so
    (``rs``: the rows' states, ``seg``: where each state's run of them starts)."""
    st = rs[seg]
    slack = np.maximum(upper - lower, 0.0)[rs] + ROUNDING
    near = np.flatnonzero(q >= np.maximum.reduceat(q, seg)[run_ids(rs)] - slack)
    matrix = sweeper.adversary_matrix(upper, near)  # one row per near row
    cand = free_rows[near]
    crs = rs[near]
    cseg = first_of_runs(crs)
    if stop is not None and stop():
        return None
    inner = inner_rows(matrix, crs)  # for both searches below
    pick = surest_exit_start(matrix, crs, inner=inner)
    if (pick < 0).any():
        # where no chain of the near rows leaves, rows that move towards the settled
        # states (a robust attractor; states at 0 count as settled)
        first = strategy.strategy_rows(m, cand, q[near], cseg, crs[cseg], upper, True, True, 1.0)
        pick = np.where(pick >= 0, pick, np.searchsorted(cand, first[crs[cseg]]))
    stay = None
    if st.size <= SI_MAX_STATES:  # policy iteration by sparse LU
        room = widening_room(lower[st], upper[st], tolerance)
        limit = stay_limit(matrix, upper, ROUNDING, room)
        # an open bracket's room is a tenth of its width: there the stays are solved
        # for, not bounded, so that the widening stays as small as they are
        closing = float(np.max(upper[st] - lower[st])) < tolerance
        pick, stay = shortest_stay(
            matrix,
            crs,
            pick,
            limit=limit,
            block_limit=limit if closing else 0.0,
            stop=stop,
            inner=inner,
        )
    return near[pick], matrix[pick], stay


UNIFORM_SHARE = 1.0 / 16.0
"""The share of the room left to the tolerance that :func:`uniformly_widened` adds. On the
100 x 100 benchmark grid (seeds 0-80) shares of 1/16, 1/4 and 1/2 were all shown on the
same layouts (seeds 0-40 measured for the larger shares) with checks of 0.03-0.07 s; 1/16
keeps the brackets about as narrow as the widening's (seed 8: 4.0e-9 against 8.5e-9,
seed 1: 6.2e-9 against 6.0e-9)."""


def uniformly_widened(
    lower: np.ndarray, upper: np.ndarray, states: np.ndarray, tolerance: float
) -> np.ndarray:
    """``min(1, upper + c)`` on ``states``, ``c = UNIFORM_SHARE * (tolerance - w)``, ``w``
    the widest bracket below the tolerance (of every state where the bracket is closed):
    a candidate for the exact check that costs nothing to build (no stays computed), tried
    before :func:`rounding_widened`. Every state gains ``c`` of slack against the mass its
    rows send to the settled states and to the states the cap holds at 1, which the exact
    check's raises then carry along the chains; the check, not this raise, is the proof,
    and where it fails the widening by stays is checked instead. A state whose bracket was
    below the tolerance stays below it unless the check raises it further
    (:func:`_shown_uniformly` then refuses the bound)."""
    st = np.asarray(states, dtype=np.int64)
    gap = upper[st] - lower[st]
    room = tolerance - float(np.max(gap[gap < tolerance], initial=0.0))
    out = upper.copy()
    out[st] = np.minimum(1.0, upper[st] + UNIFORM_SHARE * max(room, 0.0))
    return out


def _shown_uniformly(
    m: IMDP,
    free_rows: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    states: np.ndarray,
    tolerance: float,
    sides: tuple[bool, bool],
) -> tuple[bool, np.ndarray] | None:
    """``(True, bound)`` where :func:`uniformly_widened` is shown superharmonic in exact
    arithmetic and every bracket below the tolerance stays below it; else ``None``."""
    raised = uniformly_widened(lower, upper, states, tolerance)
    verified, shown = certify.verify_upper(m, free_rows, raised, *sides)
    st = np.asarray(states, dtype=np.int64)
    closed = upper[st] - lower[st] < tolerance
    if verified and np.all(shown[st][closed] - lower[st][closed] < tolerance):
        return True, shown
    return None


def certified_upper(
    m: IMDP,
    free_rows: np.ndarray,
    tolerance: float,
    maximize: bool,
    adversary_minimizes: bool,
    lower: np.ndarray,
    upper: np.ndarray,
    closed: bool,
    sweeper: ReachSweeper,
) -> tuple[bool, np.ndarray]:
    """``(shown, bound)``: ``upper`` widened for rounding and checked in exact arithmetic
    (:func:`planner.imdp.certify.verify_upper`; the bound it raised where shown, else the
    widened one). Where the widening would open a ``closed`` bracket (long stays), the
    bound as it is is checked first and kept if shown within the tolerance: the widening
    is a raise that speeds the exact check, no proof. Where the widening searches for
    short stays (maximising, at most ``SI_MAX_STATES`` free states), the bound raised
    uniformly (:func:`uniformly_widened`) is checked first and kept if shown with every
    closed bracket still closed: for a closed bracket here while the search runs on a
    second thread (stopped once the raise is shown), for an open one before the search
    (an open bracket's certificate already runs beside the sweeps from below; on the 100 x
    100 benchmark grid's stalled seeds 3-5, 7, 9, 10, 12 and 21 the raise was shown in
    18-30 ms, against 130-200 ms for the search and its check). The random 100k-state
    benchmark model has no such search: checking the raise there cost 0.1-0.3 s."""
    sides = (maximize, adversary_minimizes)
    widening = (m, free_rows, lower, upper, adversary_minimizes, maximize)
    uniform = (m, free_rows, lower, upper, sweeper.states, tolerance, sides)

    def rounding(stop: Callable[[], bool] | None = None) -> np.ndarray | None:
        return rounding_widened(*widening, tolerance, sweeper, stop=stop)

    if not maximize or sweeper.states.size > SI_MAX_STATES:
        widened = rounding()
    elif not closed:
        quick = _shown_uniformly(*uniform)
        if quick is not None:
            return quick
        widened = rounding()
    else:
        # the uniform raise checked here while the widening searches on a second thread;
        # the search stops once the check has shown the raise
        shown_here = threading.Event()

        def check() -> tuple[bool, np.ndarray] | None:
            quick = _shown_uniformly(*uniform)
            if quick is not None:
                shown_here.set()
            return quick

        widened, quick = concurrently(lambda: rounding(shown_here.is_set), check, "widen")
        if quick is not None:
            return quick
    if closed and np.max(widened - lower, initial=0.0) >= tolerance:
        verified, shown = certify.verify_upper(m, free_rows, upper, *sides)
        if verified and np.max(shown - lower, initial=0.0) < tolerance:
            return True, shown
    verified, shown = certify.verify_upper(m, free_rows, widened, *sides)
    return verified, (shown if verified else widened)
