"""Interval iteration with end-component bounds, for maximal reachability against a
minimising adversary (:class:`planner.imdp.certify.EndComponentBounds`).

Each round: ``LOWER_SWEEPS`` Gauss-Seidel sweeps from below (the first of all rows every
``FULL_EVERY``-th round, skipping the rows whose cached value from above is below the best
row's, ``PRUNE``; the others of the best rows), each followed by the lower bound
raised to the best exit on the traversable end components, and meanwhile, on a second
thread, a Gauss-Seidel pass ``U = min(U, T(U))`` from above and ``U`` lowered to the best
exit on every end component. From ``U = 1`` both sides stay sound bounds in every round.
The pass from above evaluates every state until a pass moves few of them, then only the
states with a successor whose upper value fell since their last evaluation
(``TRACK_FRACTION``): a skipped update leaves an upper bound where it was.
Every ``_II_WINDOW`` rounds the states still moving from below, if at most
``RAISE_FRACTION`` of the free states, are solved by strategy iteration with the others
held at ``L`` (sound, as in :mod:`planner.imdp.reachability`).

When the width has not halved over ``_II_WINDOW`` rounds (mass that circulates for a long
time among states of nearly equal value: ``U`` creeps down at the rate of the circulation's
leak; a window ends early where the width near the tolerance stays flat, ``_FLAT``), the
states ``B`` still wider than ``tolerance / 2`` are solved by strategy iteration with the
others held, when they are at most ``LOCAL_FRACTION`` of the free states (when
more are wide, the first such stall takes all free states as ``B`` if they are at most
``GLOBAL_REPAIR_STATES``; ``_II_STALLS`` further stalls end it): from below with ``L``
outside (a sound lower bound), and from above with ``U`` outside, *unlowered*, from the
strategy found below (``START_ABOVE_FROM_BELOW``): ``Y``. The candidate ``U`` with
``min(U, max(Y, L) + tolerance / 4)`` on ``B`` is kept only if checking passes certify it
superharmonic (:func:`planner.imdp.certify.check_upper`, violating states raised to their
Bellman value until a pass finds none; then it bounds ``V*`` by Knaster-Tarski, however
inexact ``Y`` was). At most ``_II_REPAIRS`` such repairs, none without
``strategy_iteration``, and none after a local one that left more than half of its states
wide: it would work on the same states from nearly the same values (on the 100 x 100
benchmark grid, where a first repair failed the next two changed the width by under 1 %
and took 0.45-0.87 s each; the only second repair that closed a bracket there, seeds
0-40, followed a first that left 389 of its 1,144 states wide). On more than
``GLOBAL_REPAIR_STATES`` free states, a stalled window with too many wide states that
shows no progress (``_CATCHING``, ``_THINNING``, ``_NARROWING``) ends it at once. From
``SPLIT_REPAIR_STATES`` wide states on, a repair's strategy iterations run on two threads
for two parts of whole independent components of the wide states
(:func:`planner.imdp.strategy.independent_parts`): the same values and strategies.
"""

from __future__ import annotations

import numpy as np

from planner._util.threads import concurrently, worker
from planner.imdp import certify, strategy
from planner.imdp.kernels import ReachSweeper
from planner.imdp.model import IMDP, first_of_runs
from planner.imdp.problem import ValueIteration

FULL_EVERY = 4
"""Every this many rounds of interval iteration, and sweeps of certified plain sweeps
(:func:`full_due`), all rows are evaluated (and after a sweep below the tolerance)."""

ADAPTIVE_FULL = True
LIGHT_FALL = 0.1
FULL_EVERY_MOST = 8
"""Uncertified plain sweeps from below (:func:`full_due`) evaluate every row once the light
sweeps since the last full one have brought the change below ``LIGHT_FALL`` of that full
sweep's (the strategy's values have nearly settled: only a better row makes more
progress), and at least every ``FULL_EVERY_MOST`` sweeps (while light sweeps still make
progress, a full one costs several of them). On grid seeds 0-11 of
``benchmarks/bench_vi.py`` the uncertified solves took 4.72 s in all instead of 5.36 s
with every ``FULL_EVERY``-th sweep full (least of 4 in turns; seeds 3 and 6 15-18 %
slower, seed 0 the same); the random models' light sweeps settle within 3-4 sweeps, as
before. Certified plain sweeps keep ``FULL_EVERY``: there each full sweep below the goal
tries a candidate bound from above, and the optimistic solve of grid seed 1 took 0.76 s
instead of 0.29 s."""


def full_due(it: int, history: list[tuple[int, float]], residual: float, adaptive: bool) -> bool:
    """Whether plain sweep ``it`` evaluates every row, ``history`` holding ``(sweep,
    change)`` of the full sweeps so far and ``residual`` the change of the sweep before
    (``adaptive``: by ``LIGHT_FALL`` and ``FULL_EVERY_MOST``, else every ``FULL_EVERY``-th)."""
    if not (adaptive and ADAPTIVE_FULL):
        return it % FULL_EVERY == 1
    last, change = history[-1] if history else (0, np.inf)
    if it == 1 or it - last >= FULL_EVERY_MOST:
        return True
    return it - last > 1 and residual < LIGHT_FALL * change


LOCAL_FRACTION = 0.25
"""Strategy iteration on the wide states of a stalled interval iteration (and, in plain
value iteration, on the states still moving at a check) when they are at most this
fraction of the free states."""

RAISE_FRACTION = 0.05
"""Strategy iteration on the states still moving from below at a window's end when they
are at most this fraction of the free states: a few creeping states are cheap to make
exact, while a quarter of a 10k-state grid costs more (0.8 s) than the rounds it saves
(none on the benchmark grids, where the bound from above is the slower side)."""

GLOBAL_REPAIR_STATES = 3_000
"""A stalled interval iteration with more wide states than ``LOCAL_FRACTION`` is repaired by
strategy iteration on all free states once, when they are at most this many (each
evaluation is a few sparse LU solves: cheap here, ~0.5 s on a 10k-state grid)."""

LOWER_SWEEPS = 2
"""Sweeps from below per round: a light sweep costs about half a pass from above (which
evaluates every row), so the second one mostly runs in the time the pass takes anyway.
Where the values from below are the slower side, fewer rounds close the bracket: on the
100 x 100 benchmark grid (seeds 0-2) 114 / 82 / 68 passes from above instead of 146 / 130
/ 100, the certified solve 1.01-1.21x faster (A/B in one process; seeds 3-5, which stay
uncertified, 0.94-1.15x; the random 100k-state model, where the bound from above is the
slower side, 0.98-1.03x)."""

TRACK_FRACTION = 1e-4
"""The rounds' passes from above evaluate only the states with a successor whose upper
value fell by more than ``tolerance * TRACK_FRACTION`` since their last evaluation, once
a pass has moved at most ``kernels.sweeps.TRACK_START`` of the free states
(:meth:`planner.imdp.kernels.ReachSweeper.track_changes`; a skipped update leaves ``U``
where it was, an upper bound still). On the 100 x 100 benchmark grid (seed 0) the states
due fall from 6,862 of the 9,908 free states at round 8 to 1,501 at round 32 and 358 at
round 112, and the certified solve of seeds 0-5 is 0.99-1.29x faster (least of 3 runs
each, A/B in one process) with the same sweeps, passes and lower bounds and upper bounds
within 1e-10 of the untracked ones; the random 100k-state model never starts tracking
(about 64,600 of its 64,611 free states move in each pass). The sweeps from below are
not tracked: their values keep rising at 4,000-9,800 states per sweep until late, and
flagging the predecessors of each cost more than the skips saved."""

PRUNE = True
"""The full sweeps from below skip the rows whose value at an upper bound (the row cache of
the passes from above) is below the best row's value from below: such a row can neither
beat nor tie it (action elimination: the same values and best rows, up to the rounding
of the cached values; on the benchmark grids the lower bounds end within 2e-12 of the
unpruned ones). Certified solve of the 100 x 100 benchmark grid 1.02-1.14x faster on seeds
0-2, 1.01x on seed 3, 1.00-1.07x on the random 100k-state model (A/B in one process); its
full sweeps take 5-20 % less."""

START_ABOVE_FROM_BELOW = True
"""A repair's strategy iteration from above starts from the strategy its iteration from
below ended with (when that converged) rather than from the rows greedy for ``U``: with
the states outside held at ``U`` instead of ``L`` the best rows mostly stay the best. On
the 100 x 100 benchmark grid the repairs of seeds 0-2 took 11 / 9 / 12 strategy
evaluations instead of 23 / 17 / 26, and the certified solve was 1.06-1.45x faster (seeds
6 and 8: 1.13x and 1.20x; the seeds that take no repair are unchanged), with the same
outcome and widths (A/B in one process)."""

SPLIT_REPAIR_STATES = 500
"""Wide states from which a repair's strategy iterations run on two threads, for two parts
of whole independent components of the wide states. On the 100 x 100 benchmark grid (2-7
components, seed 2: 943, 256, 177, 33 states) seed 2's repair takes 0.30 s instead of
0.35-0.41 s; below a few hundred states a repair costs too little to split."""

_II_WINDOW = 16
"""Rounds of interval iteration over which the bracket must at least halve."""

_FLAT_ROUNDS = 4
_FLAT = 0.99
_FLAT_NEAR = 100.0
"""A window ends early, after any ``_FLAT_ROUNDS`` rounds, when the width, within
``_FLAT_NEAR`` times the tolerance, fell by less than ``1 - _FLAT`` over them (at that
pace halving it takes hundreds of rounds). On the 100 x 100 benchmark grid (seeds 0-80)
the same certificates and closed brackets, all 81 solves 76.3-77.6 s instead of 79.7 s
(seed 0: its width stays at 4.73e-8 from round 88, and the repair comes at round 96
instead of 112); checked every 4 rounds at any width, the flat first rounds (width 1)
ended windows before the bound from below had risen, and 40 brackets stayed open. Such a
window goes to its repair even where the width halved since the last window's end: the
halving came before the flat rounds (seed 0: the width fell to 4.7e-8 at round 82 and
stayed; the repair came at round 88 instead of 92, 179 sweeps instead of 187; seeds 1-40
the same sweeps, passes and bounds)."""

_II_REPAIRS = 3
"""Strategy-iteration repairs of a stalled interval iteration."""

_REPAIR_PASSES = 16
"""Checking passes of a repaired upper candidate (violating states raised)."""

_II_STALLS = 4
"""Stalled windows with too many wide states before interval iteration gives up."""

_CATCHING = 0.01
_THINNING = 0.1
_NARROWING = 0.25
"""On more than ``GLOBAL_REPAIR_STATES`` free states, a stalled window with too many wide
states for a local repair ends interval iteration at once (not after ``_II_STALLS`` such
windows) when it shows no progress: at most ``_CATCHING`` of the wide states rose from
below by their width over the window, their number fell by less than ``_THINNING`` and
the width by less than ``_NARROWING``. The bracket could then close only by a repair, for
which the wide states stay too many. On the 100 x 100 benchmark grid (seeds 0-80, 81
layouts) this ends the stalled solves of 30 layouts one to four windows earlier with the
same 27 certificates and the same closed brackets; the wide states of the seeds whose
bracket closed after stalled windows fell by 59-63 % in each of them (seeds 18 and 22;
seed 72's by under 1 %, but 410 of its wide states rose by their width, and a local
repair closed it a window later). The price: a looser bound from below where the
iteration would have crept on, at the start state by at most 6.0e-4 (seed 13; 8.8e-5 on
seed 16, at most 1.4e-5 elsewhere)."""

_CANDIDATE_SLACK = 1e-13
"""The ``tol`` given to the strategy iteration of an upper candidate (switching slack
``tol / 100``)."""


class _IntervalIteration:
    """The state of one interval iteration: ``v`` (lower), ``u`` (upper) and the counts."""

    def __init__(self, m: IMDP, sweeper: ReachSweeper, v: np.ndarray, alg: ValueIteration):
        self.m, self.sweeper, self.alg = m, sweeper, alg
        st = sweeper.states
        free = np.zeros(m.n_states, dtype=bool)
        free[st] = True
        self.bounds = certify.EndComponentBounds(m, sweeper, free)
        self.v = v
        self.u = v.copy()
        self.u[st] = 1.0
        self.bounds.deflate(self.u)
        # ``u`` only ever decreases below (passes, deflation, repairs keep a minimum)
        self.cache = sweeper.upper_cache()
        sweeper.track_changes(alg.tolerance * TRACK_FRACTION)
        self.residual = np.inf
        self.it = self.sweeps = self.passes = self.evaluations = self.repairs = self.stalls = 0
        self.global_repair = False
        self.repaired = np.inf  # states wide at the last local repair
        self.sigma: np.ndarray | None = None

    def width(self) -> float:
        st = self.sweeper.states
        return float(np.max(self.u[st] - self.v[st]))

    def _from_above(self) -> None:
        self.sweeper.upper_pass(self.u, cache=self.cache, track=True)
        if self.bounds.n_components:
            before = self.u.copy()
            self.bounds.deflate(self.u)
            self.sweeper.moved_above(before, self.u)

    def round(self) -> float:
        """One round: sweeps and collapses from below, pass and deflate from above; the
        width after it.

        The two sides share no mutable data (``v`` and ``crit`` below, ``u`` and
        ``crit_up`` above) and their kernels release the GIL, so the pass from above runs
        on a second thread meanwhile; the result is the same as one after the other. (The
        full sweep's bounds are a copy of the pass's row cache taken before the pass.)"""
        self.it += 1
        full = self.it % FULL_EVERY == 1
        bound = self.cache.copy() if PRUNE and full else None
        above = worker("upper").submit(self._from_above)
        try:
            for k in range(LOWER_SWEEPS):
                self.residual = self.sweeper.sweep(self.v, k == 0 and full, bound)
                self.bounds.collapse(self.v)
                self.sweeps += 1
                if self.alg.callback is not None:
                    self.alg.callback(self.sweeps, self.residual)
        finally:
            above.result()
        self.passes += 1
        return self.width()

    def _held_rows(self, states: np.ndarray) -> np.ndarray:
        """The free rows at the (masked) ``states``, sorted."""
        rows = self.sweeper.rows
        return np.sort(rows[states[self.m.row_state[rows]]])

    def raise_moving(self, before: np.ndarray) -> None:
        """Strategy iteration on the states still moving from below, the others held at
        their lower bounds (sound; as in :mod:`planner.imdp.reachability`)."""
        v, tol = self.v, self.alg.tolerance
        moving = v - before >= tol
        if 0 < moving.sum() <= RAISE_FRACTION * self.sweeper.states.size:
            rows = self._held_rows(moving)
            x, _, k = strategy.strategy_iteration(
                self.m, rows, v, np.where(moving, 0.0, v), True, tol
            )
            self.evaluations += k
            if x is not None:
                self.v = np.maximum(v, x)

    def repair(self, wide: np.ndarray) -> None:
        """Strategy iteration on the ``wide`` states from below (sound) and from above (a
        candidate), the candidate kept if checking passes certify it. From
        ``SPLIT_REPAIR_STATES`` wide states on, the two strategy iterations run on two
        threads for two parts of whole independent components
        (:func:`planner.imdp.strategy.independent_parts`)."""
        self.repairs += 1
        rows = self._held_rows(wide)
        parts = [rows]
        if np.count_nonzero(wide) >= SPLIT_REPAIR_STATES:
            parts = strategy.independent_parts(self.m, rows, wide)
        u, v0 = self.u, self.v
        if len(parts) == 1:
            found = [self._repair_part(rows, wide, v0, u)]
        else:
            other, first = concurrently(
                lambda: self._repair_part(parts[1], wide, v0, u),
                lambda: self._repair_part(parts[0], wide, v0, u),
                "repair",
            )
            found = [first, other]
        for x, _, k, _ in found:
            self.evaluations += k
            if x is not None:
                self.v = np.maximum(self.v, x)
        sigmas = [sigma for _, sigma, _, _ in found]
        if all(s is not None for s in sigmas) and rows.size == self.sweeper.rows.size:
            # every free state: an exactly evaluated strategy that no state wants to leave
            self.sigma = np.sort(np.concatenate(sigmas))
        # switching slack ~1e-15: a row left better than Y by more than tolerance / 4 times
        # its mass leaving B would fail the check
        v, cand = self.v, None
        for part, (_, _, _, y) in zip(parts, found, strict=True):
            if y is not None:
                cand = u.copy() if cand is None else cand
                rs = self.m.row_state[part]  # sorted: the part's rows are
                st = rs[first_of_runs(rs)]
                cand[st] = np.minimum(u[st], np.maximum(y[st], v[st]) + self.alg.tolerance / 4)
        if cand is not None:
            ok, k = certify.check_upper(self.sweeper, cand, _REPAIR_PASSES, raise_violations=True)
            self.passes += k
            if ok:
                self.u = np.minimum(u, cand)
                self.sweeper.moved_above(u, self.u)

    def _repair_part(
        self, rows: np.ndarray, wide: np.ndarray, v: np.ndarray, u: np.ndarray
    ) -> tuple[np.ndarray | None, np.ndarray | None, int, np.ndarray | None]:
        """A repair's two strategy iterations on ``rows`` (every other state held at ``v``,
        then ``u``; 0 at the other wide states, which these rows never reach): ``(x,
        sigma, evaluations, y)``. Reads only its arguments and the model."""
        x, sigma, k = strategy.strategy_iteration(
            self.m, rows, v, np.where(wide, 0.0, v), True, _CANDIDATE_SLACK
        )
        # from the strategy just found below: held at U instead of L, the best rows mostly
        # stay the best (seeds 0-2 of the benchmark grid: 15, 9, 16 evaluations from the
        # rows greedy for U)
        y, _, k_above = strategy.strategy_iteration(
            self.m,
            rows,
            u,
            np.where(wide, 0.0, u),
            True,
            _CANDIDATE_SLACK,
            sound=False,
            start=sigma if START_ABOVE_FROM_BELOW else None,
        )
        return x, sigma, k + k_above, y

    def _window(self, v0: np.ndarray) -> tuple[np.ndarray, int]:
        """At a window's end, from the bound from below ``v0`` at its start: the wide
        states (a mask over the model's states), and how many of them rose from below by
        at least their width (still closing from below)."""
        st, tol = self.sweeper.states, self.alg.tolerance
        gap = self.u[st] - self.v[st]
        is_wide = gap >= tol / 2
        wide = np.zeros(self.m.n_states, dtype=bool)
        wide[st[is_wide]] = True
        catching = int(np.count_nonzero(is_wide & (self.v[st] - v0[st] >= gap)))
        return wide, catching

    def run(self) -> bool:
        """Rounds until the bracket closes (``True``) or stalls for good (``False``)."""
        alg, st = self.alg, self.sweeper.states
        tol = alg.tolerance
        checkpoint = flat_from = np.inf
        v0, last_wide, last_width = self.v.copy(), st.size, 1.0
        while self.sweeps < alg.max_iterations:
            width = self.round()
            if width < tol:
                # a last full sweep: its change is at most the width (L <= T(L) <= V* <= U)
                self.sweeps += 1
                self.residual = self.sweeper.sweep(self.v, True)
                if alg.callback is not None:
                    alg.callback(self.sweeps, self.residual)
                return True
            flat = False
            if self.it % _FLAT_ROUNDS == 0:
                flat = _FLAT * flat_from < width < _FLAT_NEAR * tol
                flat_from = width
            if self.it % _II_WINDOW and not flat:
                continue
            if alg.strategy_iteration:
                self.raise_moving(v0)
            wide, catching = self._window(v0)
            n_wide = int(wide.sum())
            # no sign of progress over the window: at most a few wide states caught up from
            # below, and neither their number nor the width fell much
            stuck = (
                catching <= _CATCHING * n_wide
                and n_wide > (1.0 - _THINNING) * last_wide
                and width > (1.0 - _NARROWING) * last_width
            )
            v0, last_wide, last_width = self.v.copy(), n_wide, width
            if width <= 0.5 * checkpoint and not flat:
                checkpoint = width
                continue
            many = n_wide > LOCAL_FRACTION * st.size
            # not after a local repair that left most of its states wide: again it would not
            can_repair = (
                alg.strategy_iteration
                and self.repairs < _II_REPAIRS
                and n_wide <= self.repaired / 2
            )
            if not can_repair or self.stalls >= _II_STALLS:
                break
            if many:
                if st.size <= GLOBAL_REPAIR_STATES and not self.global_repair:
                    # once: strategy iteration on all free states (the values exact
                    # below, the candidate from them checked above)
                    self.global_repair = True
                    wide[st] = True
                    self.repair(wide)
                    checkpoint = self.width()
                    continue
                if st.size > GLOBAL_REPAIR_STATES and stuck:
                    # too many states for any repair, and no sign of progress
                    break
                self.stalls += 1
                checkpoint = width
                continue
            self.repaired = n_wide
            self.repair(wide)
            checkpoint = self.width()
        return False


def interval_iteration(
    m: IMDP, sweeper: ReachSweeper, v: np.ndarray, alg: ValueIteration
) -> tuple[np.ndarray, np.ndarray, float, int, int, bool, int, np.ndarray | None]:
    """Interval iteration from the lower bound ``v`` (updated in place) and ``U = 1`` (see
    the module docstring).

    Returns ``(lower, upper, residual, sweeps, upper_passes, done, evaluations, sigma)``
    (``sweeps`` from below):
    ``done`` when ``max(U - L) < tolerance``, else the caller continues from ``L`` and
    ``U`` with its other means; ``sigma`` the optimal strategy (one row per free state) of
    a strategy iteration on all free states, or ``None``.
    """
    ii = _IntervalIteration(m, sweeper, v, alg)
    done = ii.run()
    return ii.v, ii.u, ii.residual, ii.sweeps, ii.passes, done, ii.evaluations, ii.sigma
