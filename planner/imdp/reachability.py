"""Reachability value iteration from below, and a certified upper bound.

**From below**: state-by-state Gauss-Seidel sweeps. The free states are visited in order of
their graph distance to the value-1 states (targets, and states of worst-case value 1),
each update reading the values written before it in the same sweep (a large full sweep
runs as two such halves at once, the later reading the earlier's values from before the
sweep; :class:`planner.imdp.kernels.ReachSweeper`, compiled), with the exact adversary for the
current values and ``max(old, new)``. Starting from ``V_0 <= T(V_0)``, every update stays
below the least fixed point and the values only increase, which is what makes zero lower
bounds and end components safe. For a maximising strategy only some sweeps evaluate all
rows (and record each state's best row: :func:`planner.imdp.interval.full_due`); the sweeps
between evaluate the recorded best rows only (modified policy iteration: each such update
is at most the full one, so it stays sound; for a minimising strategy it would not be, and
every sweep is full).

**From above** (``certified``): the value is the *least* fixed point of the Bellman
operator ``T`` (targets at 1), so by Knaster-Tarski every superharmonic ``U``
(``T(U) <= U``) is an upper bound; no end-component analysis is needed to *check* one.
Maximal reachability against a minimising adversary runs interval iteration
(:mod:`planner.imdp.interval`); where that gives up (its bound from above stalled over
most free states, or after its repairs) on more than ``GLOBAL_REPAIR_STATES`` free states,
at most ``_STALLED_SWEEPS`` sweeps from below (with strategy iteration on the few states
still moving) and the candidate below finish the solve, the bracket left open where it
fails (:meth:`_ReachSweeps.finish_stalled`; the exact check of the bound from above that
interval iteration left runs on a second thread meanwhile). Otherwise, when a full sweep
from below changes no value by the current goal (``tolerance`` at first), the candidate
``U = min(1, L + tolerance / 2)`` is checked by passes of
:func:`planner.imdp.kernels.upper_sweep` (optimistic value iteration, Hartmanns and
Kaminski 2020): a pass that finds no state with ``T(U)(s) > U(s)`` (in floating point,
up to ``ROUNDING``) accepts ``U``.
Candidates fail where the values from below still move (a slow leak, or mass that
circulates long among free states): then, for maximal reachability on at most
``SI_MAX_STATES`` free states, strategy iteration makes the values exact (the least fixed
point, at which the candidate passes), else the goal is divided by 8 and the sweeps
continue. After ``_OVI_TRIES`` failures the upper bound is iterated from the trivial
superharmonic ``U = 1`` instead, each pass again a sound upper bound (it may stall above the
value inside end components that the opposing side can hold; the bracket then stays wide
and ``converged`` is ``False``).

**The certificate**: the accepted bound, raised by
:func:`planner.imdp.widening.rounding_widened`, counts only once
:func:`planner.imdp.certify.verify_upper` shows it superharmonic in exact arithmetic
(``ReachResult.verified``; where it is not, ``upper`` is 1 on the free states): the
floating-point checks above only steer, and over long stays they may keep a bound below
the value (docs/design.md). Where the raise would open a closed bracket (long stays: it
sums an allowance along them), the bound as it is is checked first and kept if shown; a
uniform raise is checked beside the widening's search for short stays, which stops once
it is shown, and for an open bracket before that search, which then runs only where the
raise is not shown (:func:`planner.imdp.widening.certified_upper`).

**Creeping** (maximal reachability): after 16, 32, 64, ... sweeps the states still moving,
if few, are solved by strategy iteration with the others held; else, if the residuals
(below 1e-3) extrapolate to more than ``max(4 k, 1000)`` further sweeps, it runs on all
free states (:mod:`planner.imdp.strategy`). Its values are a strategy's values, hence at
most the least fixed point and ``<= T(V)``, so the sweeps continue from ``max(V,
V_sigma)`` soundly.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from planner._util.threads import concurrently
from planner.imdp import certify, strategy
from planner.imdp.interval import GLOBAL_REPAIR_STATES, LOCAL_FRACTION, full_due, interval_iteration
from planner.imdp.kernels import ReachSweeper
from planner.imdp.kernels.sweeps import sweep_layout
from planner.imdp.model import IMDP, first_of_runs
from planner.imdp.problem import ValueIteration
from planner.imdp.strategy import SI_MAX_STATES
from planner.imdp.widening import certified_upper

_OVI_TRIES = 3
"""Failed candidates before the upper bound is iterated from 1 instead."""

_FALLBACK_PASSES = 50
"""Passes of the upper bound from the last certified vector (or ``U = 1``) when no
candidate closed the bracket (each pass keeps it certified)."""

_CERTIFY_ROUNDS = 12
"""Strategy-improvement rounds spent on making the values exact for the certificate."""

_CERTIFY_SLACK = 1e-3
"""The strategy iteration that makes the values exact for the certificate switches rows
better by ``tolerance * _CERTIFY_SLACK / 100`` (1e-13 at the default tolerance; the
creep checks' by ``tolerance / 100``): a strategy short of the best by ``d`` per step is
short of the least fixed point by up to ``d`` times its expected stay, and the candidate
``L + tolerance / 2`` needs ``L`` far closer than that on stays of 1e4 steps. On the
100 x 100 benchmark grid (seeds 3-5) the coarser switching did not converge within
``_CERTIFY_ROUNDS`` and left the sweeps creeping for 900-1300 sweeps after it."""

_CERTIFY_FLOOR = 1e-12
"""The least tolerance passed to that strategy iteration: switches by at least 1e-14,
above the rounding of a row's value (a few ``eps``), so that noise does not switch."""

_MIN_GOAL = 1e-15
"""The smallest residual goal the sweeps from below are driven to."""

_STALLED_SWEEPS = 4
"""Full sweeps from below after interval iteration gave up on more than
``GLOBAL_REPAIR_STATES`` free states (each followed by strategy iteration on the few states
still moving). More work did not close those brackets: on the 100 x 100 benchmark grid
(seeds 3-5, 7, 9-14, 16, 19, 21, 24-28, 36, 38, 39 of 0-40: states of value near 1 that
the controller can keep among free states for 1e11 steps and more) the sweeps, the
strategy iteration on all 9,905 free states that made the values exact and the passes
from above that followed took 2-20 s and closed none. On fewer free states that strategy
iteration is cheap and the full sweeps still run (they close many small models whose
interval iteration gave up)."""

_ROW_ROUNDING = 1e-12
"""What a row's computed value may exceed its exact value by, taken generously (its
rounding is a few ``eps``)."""

_FIRST_EVALUATION = 16
"""Sweeps before the first check for slow convergence (then after 32, 64, ... sweeps)."""

_CREEP_SWEEPS = 1000
"""Projected sweeps to the tolerance beyond which value iteration counts as creeping."""

_CREEP_RESIDUAL = 1e-3
"""Residuals from which the sweeps never count as creeping: values still moving this much
are a front spreading from the targets, whose residuals do not decay geometrically (on the
100 x 100 benchmark grid they stay at 0.1-0.3 for the first 60 sweeps, and the
extrapolation at sweep 33 of seeds 0, 3, 5, 7-11 called them creeping once the sweeps ran
in two halves; the strategy iteration on all 9,908 free states it started took 5.6-9.4
s, against 0.4-1.5 s for the sweeps to the tolerance). A creep with a larger residual leaks
at least ``_CREEP_RESIDUAL`` per sweep of its distance to the fixed point."""


def _creeping(history: list[tuple[int, float]], tol: float) -> bool:
    """Whether, after ``k`` sweeps, the sweeps would take more than
    ``max(4 k, _CREEP_SWEEPS)`` more sweeps to reach ``tol`` at the rate seen since sweep
    ``k / 2`` (geometric extrapolation of the residuals, given as ``(sweep, residual)``).
    Only decides *when* to run strategy iteration; the values are sound either
    way."""
    if len(history) < 2:
        return False
    k, now = history[-1]
    earlier = [h for h in history[:-1] if h[0] <= k // 2] or history[:1]
    k0, then = earlier[-1]
    if now < tol or now >= _CREEP_RESIDUAL:
        return False
    if now >= then:
        return True
    rate = (now / then) ** (1.0 / (k - k0))
    return np.log(tol / now) / np.log(rate) > max(4 * k, _CREEP_SWEEPS)


@dataclass
class ReachResult:
    """The outcome of :func:`reach_values`.

    Attributes:
        lower, upper: the bracket.
        residual: the last sweep's change; iterations: sweeps from below.
        sigma: the last strategy iteration's optimal strategy (one row per free state) or
            ``None``.
        evaluations: strategy evaluations; q: the robust value of every free row under
            ``lower``; upper_sweeps: passes from above.
        verified: ``upper`` was shown superharmonic in exact arithmetic
            (:func:`planner.imdp.certify.verify_upper`), hence an upper bound; only then
            does a closed bracket count as certified.
    """

    lower: np.ndarray
    upper: np.ndarray
    residual: float
    iterations: int
    sigma: np.ndarray | None
    evaluations: int
    q: np.ndarray
    upper_sweeps: int
    verified: bool = False


class _ReachSweeps:
    """The state of one reachability iteration (see the module docstring)."""

    def __init__(
        self,
        m: IMDP,
        free_rows: np.ndarray,
        fixed_val: np.ndarray,
        adversary_minimizes: bool,
        maximize: bool,
        alg: ValueIteration,
        sweeper: ReachSweeper | None = None,
    ) -> None:
        self.m, self.free_rows, self.fixed_val, self.alg = m, free_rows, fixed_val, alg
        self.adversary_minimizes, self.maximize = adversary_minimizes, maximize
        if sweeper is None:
            sweeper = sweep_layout(m, free_rows, fixed_val, maximize, adversary_minimizes)
        self.sweeper = sweeper
        self.v = fixed_val.copy()
        self.upper: np.ndarray | None = None
        self.residual = 0.0
        self.it = self.evaluations = self.upper_sweeps = self.tries = 0
        self.n_free = self.sweeper.states.size
        self.use_si = maximize and alg.strategy_iteration
        self.next_eval = _FIRST_EVALUATION if self.use_si else alg.max_iterations
        self.sigma: np.ndarray | None = None
        self.history: list[tuple[int, float]] = []
        self.goal = alg.tolerance
        self.exacted = False
        self._q: tuple[np.ndarray, np.ndarray] | None = None  # (v, row values at v)
        self.certificate: tuple[np.ndarray, bool, np.ndarray] | None = None
        """``(bound, shown, certified bound)`` where :meth:`finish_stalled` certified a
        bound from above already."""

    def result(self) -> ReachResult:
        return ReachResult(
            self.v,
            self.upper,
            self.residual,
            self.it,
            self.sigma,
            self.evaluations,
            self.row_values(),
            self.upper_sweeps,
        )

    def row_values(self) -> np.ndarray:
        """The robust value of every free row under ``v`` (exact within the optimal slack
        of the best, :meth:`ReachSweeper.row_values`), kept while ``v`` stays."""
        if self._q is None or not np.array_equal(self._q[0], self.v):
            q = self.sweeper.row_values(self.v, strategy.optimal_slack(self.alg.tolerance))
            self._q = (self.v.copy(), q)
        return self._q[1]

    def candidate_below_value(self) -> bool:
        """Whether the candidate ``min(1, L + tolerance / 2)`` lies below the value at some
        state, so that no checking pass can show it superharmonic: ``L <= V*`` and ``T``
        is monotone, so ``T(L) <= T(V*) = V*``, and where ``T(L)`` exceeds the candidate
        (by more than the rounding of a row's value) so does ``V*``."""
        rs = self.m.row_state[self.free_rows]
        seg = first_of_runs(rs)
        best = np.maximum.reduceat(self.row_values(), seg)
        st = rs[seg]
        cand = np.minimum(1.0, self.v[st] + self.alg.tolerance / 2)
        return bool(np.any(best > cand + _ROW_ROUNDING))

    def interval_iteration(self) -> bool:
        """Interval iteration first (certified maximal reachability against a minimising
        adversary); whether it closed the bracket."""
        v, self.upper, self.residual, self.it, self.upper_sweeps, done, self.evaluations, sigma = (
            interval_iteration(self.m, self.sweeper, self.v, self.alg)
        )
        self.v = v
        if done:
            self.sigma = sigma
        return done

    def _strategy_iteration(
        self, rows, held, max_rounds=None, keep_sigma=False, tol: float | None = None
    ) -> None:
        x, sigma, rounds = strategy.strategy_iteration(
            self.m,
            rows,
            self.v,
            held,
            self.adversary_minimizes,
            self.alg.tolerance if tol is None else tol,
            max_rounds=max_rounds,
        )
        self.evaluations += rounds
        if keep_sigma:
            self.sigma = sigma
        if x is not None:
            self.v = np.maximum(self.v, x)

    def candidate(self) -> np.ndarray | None:
        """The candidate ``L + tolerance / 2`` if its checking passes (counted) pass."""
        u, passes = certify.optimistic_candidate(self.sweeper, self.v, self.alg.tolerance / 2)
        self.upper_sweeps += passes
        return u

    def keep_upper(self, u: np.ndarray | None) -> None:
        """``upper`` lowered to a checked candidate ``u`` (the minimum of superharmonic
        vectors is superharmonic); nothing for ``None``."""
        if u is not None:
            self.upper = u if self.upper is None else np.minimum(self.upper, u)

    def try_certify(self) -> bool:
        """After a full sweep below the goal: check the candidate ``L + tolerance / 2``
        (once making the values exact by strategy iteration first if it fails); whether
        to stop (certified, or out of tries)."""
        u = self.candidate()
        if u is None and self.use_si and not self.exacted and self.n_free <= SI_MAX_STATES:
            # make the values from below exact (the least fixed point), then check
            self.exacted = True
            before = self.v
            self._strategy_iteration(
                self.free_rows,
                self.fixed_val,
                max_rounds=_CERTIFY_ROUNDS,
                keep_sigma=True,
                tol=max(self.alg.tolerance * _CERTIFY_SLACK, _CERTIFY_FLOOR),
            )
            if self.v is not before:
                u = self.candidate()
        self.keep_upper(u)
        if u is not None and np.max(self.upper - self.v) < self.alg.tolerance:
            return True
        self.tries += 1
        if self.tries >= _OVI_TRIES:
            return True
        self.goal = max(self.goal / 8.0, _MIN_GOAL)
        return False

    def _raise_moving(self, before: np.ndarray) -> bool:
        """Strategy iteration on the states that moved by at least the tolerance since
        ``before``, the others held at their current values, when they are at most
        ``LOCAL_FRACTION`` of the free states; whether it ran."""
        moving = self.v - before >= self.alg.tolerance
        if not 0 < moving.sum() <= LOCAL_FRACTION * self.n_free:
            return False
        local_rows = self.free_rows[moving[self.m.row_state[self.free_rows]]]
        self._strategy_iteration(local_rows, np.where(moving, 0.0, self.v))
        return True

    def check_progress(self, before: np.ndarray) -> None:
        """At a check: strategy iteration on the states still moving (few of them) or, if
        the sweeps creep, on all free states."""
        self.next_eval *= 2
        if self._raise_moving(before):
            return
        if self.n_free <= SI_MAX_STATES and _creeping(self.history, self.alg.tolerance):
            self._strategy_iteration(self.free_rows, self.fixed_val, keep_sigma=True)

    def finish_stalled(self) -> None:
        """After interval iteration gave up (its bound from above stalled). On at most
        ``GLOBAL_REPAIR_STATES`` free states, where strategy iteration on all of them is
        cheap (or without strategy iteration), the sweeps with their certificate attempts
        and the passes from above (:meth:`sweeps`, :meth:`fallback`). On more, a bounded
        finish: sweeps from below (:meth:`_settle`), then the candidate ``L + tolerance /
        2`` once; where it fails the bound from above stays the interval iteration's (a
        sound bound after every pass) and the bracket stays open. Meanwhile that bound is
        widened and checked in exact arithmetic on a second thread (:func:`_certificate`,
        from the bound from below as interval iteration left it, which only steers the
        widening); the solve keeps that certificate unless the candidate lowered the
        bound (on the benchmark grid's stalled seeds 3-5 the check, 0.2-0.35 s, ran after
        these sweeps before)."""
        if not self.use_si or self.n_free <= GLOBAL_REPAIR_STATES:
            self.sweeps()
            self.fallback()
            return
        # the certificate of the bound from above as it stands, on a second thread while
        # the sweeps settle the bound from below (they share nothing it reads; the
        # candidate below rarely lowers the bound, which then needs a certificate of its
        # own)
        lower, upper, sweeper = self.v.copy(), self.upper.copy(), self.sweeper.frozen()

        def certificate() -> tuple[np.ndarray, bool, np.ndarray]:
            return (upper, *_certificate(self, lower, upper, False, sweeper))

        def below() -> None:
            self._settle()
            if not self.candidate_below_value():
                self.keep_upper(self.candidate())

        self.certificate, _ = concurrently(certificate, below, "upper")

    def _settle(self) -> None:
        """At most ``_STALLED_SWEEPS`` full sweeps from below, each followed by strategy
        iteration on the states still moving when they are few."""
        for _ in range(_STALLED_SWEEPS):
            if self.it >= self.alg.max_iterations:
                break
            before = self.v.copy()
            self.it += 1
            self.residual = self.sweeper.sweep(self.v, True)
            if self.alg.callback is not None:
                self.alg.callback(self.it, self.residual)
            if not self._raise_moving(before):
                break

    def sweeps(self) -> None:
        """Sweeps from below with the certificate attempts and the creep checks."""
        alg = self.alg
        want_full = False
        while self.it < alg.max_iterations:
            self.it += 1
            check = self.it > self.next_eval
            due = full_due(self.it, self.history, self.residual, not alg.certified)
            # a light sweep (one row per state) is a lower bound only when maximising
            full = want_full or check or not self.maximize or due
            before = self.v.copy() if check else self.v
            self.residual = self.sweeper.sweep(self.v, full, split=True)
            if alg.callback is not None:
                alg.callback(self.it, self.residual)
            if full:
                self.history.append((self.it, self.residual))
            want_full = self.residual < self.goal
            if want_full and full:
                if not alg.certified or self.try_certify():
                    break
                want_full = False
            if check:
                self.check_progress(before)

    def fallback(self) -> None:
        """The upper bound from the last certified vector (or ``U = 1``) by passes, each
        one a sound bound, while the bracket is open."""
        if self.upper is None:
            self.upper = self.fixed_val.copy()
            self.upper[self.sweeper.states] = 1.0
        if not self.alg.certified:
            return
        for _ in range(_FALLBACK_PASSES):
            if np.max(self.upper - self.v) < self.alg.tolerance:
                break
            self.upper_sweeps += 1
            self.sweeper.upper_pass(self.upper)


def reach_values(
    m: IMDP,
    free_rows: np.ndarray,
    fixed_val: np.ndarray,
    adversary_minimizes: bool,
    maximize: bool,
    alg: ValueIteration,
    sweeper: ReachSweeper | None = None,
) -> ReachResult:
    """Reachability values of the free states by sweeps from below and a certified upper
    bound (see the module docstring); ``fixed_val`` holds the settled states' values;
    ``sweeper``: their :func:`sweep_layout`, if already built (for the first solve).

    When the bracket closed but the rounding widening then opened it again (at tolerances
    near ``1e-12``, where the widening of long stays is a sizeable part of the tolerance),
    the solve runs once more to ``_RETRY_FRACTION`` of the tolerance (a shown bound kept
    first, then the narrower)."""
    if free_rows.size == 0:
        v = fixed_val.copy()
        return ReachResult(v, v.copy(), 0.0, 0, None, 0, np.zeros(0), 0, verified=True)

    def solved(a: ValueIteration, layout: ReachSweeper | None = None) -> tuple[ReachResult, bool]:
        run = _ReachSweeps(m, free_rows, fixed_val, adversary_minimizes, maximize, a, layout)
        return _reach_once(run)

    result, closed = solved(alg, sweeper)
    if closed and _width(result) >= alg.tolerance:
        again, _ = solved(replace(alg, tolerance=alg.tolerance * _RETRY_FRACTION))
        kept = min((result, again), key=lambda r: (not r.verified, _width(r)))
        # the counts are of both solves, whichever is kept
        kept.iterations = result.iterations + again.iterations
        kept.evaluations = result.evaluations + again.evaluations
        kept.upper_sweeps = result.upper_sweeps + again.upper_sweeps
        result = kept
    if alg.certified and not result.verified:
        result.upper = result.upper.copy()
        result.upper[m.row_state[free_rows]] = 1.0
    return result


_RETRY_FRACTION = 0.25
"""The tolerance of the second solve when the widening opened a closed bracket."""


def _width(result: ReachResult) -> float:
    return float(np.max(result.upper - result.lower, initial=0.0))


def _reach_once(run: _ReachSweeps) -> tuple[ReachResult, bool]:
    """One solve: the result (certified: widened for rounding), and whether the bracket
    was below the tolerance before the widening."""
    alg = run.alg
    if not (alg.certified and run.maximize and run.adversary_minimizes):
        run.sweeps()
        run.fallback()
    elif not run.interval_iteration():
        run.finish_stalled()
    result = run.result()
    if not alg.certified:
        return result, False
    closed = _width(result) < alg.tolerance
    early = run.certificate
    if early is not None and np.array_equal(early[0], result.upper):
        result.verified, result.upper = early[1], early[2]
    else:
        result.verified, result.upper = _certificate(
            run, result.lower, result.upper, closed, run.sweeper
        )
    return result, closed


def _certificate(
    run: _ReachSweeps, lower: np.ndarray, upper: np.ndarray, closed: bool, sweeper: ReachSweeper
) -> tuple[bool, np.ndarray]:
    """:func:`planner.imdp.widening.certified_upper` for the solve ``run``."""
    sides = (run.maximize, run.adversary_minimizes)
    return certified_upper(
        run.m, run.free_rows, run.alg.tolerance, *sides, lower, upper, closed, sweeper
    )
