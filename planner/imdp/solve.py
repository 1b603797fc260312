"""Specifications, problems and robust value iteration (IntervalMDP.jl's nouns).

``solve(Problem(model, Specification(prop, satisfaction, strategy)), ValueIteration())``
returns a :class:`Solution` with the values per state, a memoryless strategy (one action
per state), the row values ``Q``, the residual and the iteration count.

Properties:

* :class:`ReachAvoid`: probability of ``(!avoid) U target``. Value iteration starts from 0
  (the least fixed point, right also with end components and zero lower bounds); states
  whose value is 0 or 1 are found by graph analysis first and held fixed.
* :class:`DiscountedReward`: ``V(s) = opt_a min/max_p sum_{s'} p(s') (W(s') + gamma V(s'))``:
  the reward ``W`` is collected on *landing* in a state (docs/design.md).

``satisfaction="pessimistic"``: the adversary opposes the strategy (the worst case);
``"optimistic"``: it helps.

**Certified values** (the default): :class:`Solution` carries ``lower <= V* <= upper`` at
every state, and the solver stops when ``max(upper - lower) < tolerance`` (default 1e-8).
For reachability ``V*`` is the least fixed point of the Bellman operator ``T``; ``lower``
comes from sweeps from below (every iterate is a sound lower bound) and ``upper`` is a
vector certified superharmonic, ``T(U) <= U``, which by Knaster-Tarski bounds the least
fixed point from above (see ``_reach_sweeps``). A residual ``max |V_k - V_{k-1}|`` below
the tolerance does not by itself bound the error (mass leaking slowly out of a
near-end-component keeps the residual small while the values are still far off); the
bracket does. For discounted reward the bracket is the contraction bound
``gamma / (1 - gamma) * residual`` of an exact sweep. ``ValueIteration(certified=False)``
is the fast uncertified mode: it stops on the residual alone.

Reachability sweeps are Gauss-Seidel, state by state in order of graph distance to the
value-1 states (a compiled kernel, :mod:`planner.imdp.kernels`): starting from
``V_0 <= T(V_0)`` the iterates increase and stay below the least fixed point, so zero lower
bounds and end components stay safe (see ``_reach_sweeps``).

Where mass leaks slowly out of near-end-components the sweeps from below creep (the
residual can stay near ``1e-8`` per sweep while the values are still far from the fixed
point, so the residual rule alone would stop early or after millions of sweeps). For
maximal reachability (at most 20,000 free states, as its LU solves can fill in) the
sweeps therefore check, after 16, 32, 64, ... sweeps, whether the
residuals extrapolate to more than ``max(4 k, 1000)`` further sweeps, and if so run robust
strategy iteration: the strategy is evaluated exactly against the adversary's best
response (:mod:`planner.imdp.evaluate`: sparse solves, adversary policy iteration) and
improved only where a row is strictly better. Its values are a strategy's values, hence at
most the least fixed point and ``<= T(V)``, so the sweeps continue from ``max(V, V_sigma)``
soundly; when no state switches they are the least fixed point and the sweeps only
confirm the residual. The reported ``iterations`` count sweeps only.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from planner.errors import SpecificationError
from planner.imdp import certify, graph
from planner.imdp.evaluate import strategy_reach_value
from planner.imdp.kernels import ReachSweeper, backward_distance
from planner.imdp.model import IMDP, first_of_runs
from planner.imdp.ordering import OrderingAdversary

StateSet = np.ndarray | str | Sequence[str] | Sequence[int]


@dataclass(frozen=True)
class ReachAvoid:
    """Reach ``target`` without first entering ``avoid``: ``(!avoid) U target``.

    ``target`` / ``avoid``: a boolean state mask, a label name, a list of label names
    (a state qualifies if it carries any of them) or a list of state indices.
    """

    target: StateSet
    avoid: StateSet | None = None


@dataclass(frozen=True)
class DiscountedReward:
    """Discounted reward ``sum_k gamma^k W(s_{k+1})`` (``W`` collected on landing)."""

    reward: np.ndarray
    discount: float


@dataclass(frozen=True)
class Specification:
    """A property with the adversary's and the strategy's goal.

    Args:
        property: :class:`ReachAvoid` or :class:`DiscountedReward`.
        satisfaction: ``"pessimistic"`` (adversary opposes) or ``"optimistic"``.
        strategy: ``"maximize"`` or ``"minimize"``.
    """

    property: ReachAvoid | DiscountedReward
    satisfaction: str = "pessimistic"
    strategy: str = "maximize"

    def __post_init__(self) -> None:
        if self.satisfaction not in ("pessimistic", "optimistic"):
            raise SpecificationError(
                f"satisfaction must be 'pessimistic' or 'optimistic', got {self.satisfaction!r}"
            )
        if self.strategy not in ("maximize", "minimize"):
            raise SpecificationError(
                f"strategy must be 'maximize' or 'minimize', got {self.strategy!r}"
            )
        if not isinstance(self.property, ReachAvoid | DiscountedReward):
            raise SpecificationError(
                f"property must be ReachAvoid or DiscountedReward, got {type(self.property)}"
            )
        if isinstance(self.property, DiscountedReward) and not 0 <= self.property.discount < 1:
            raise SpecificationError(f"discount must be in [0, 1), got {self.property.discount}")


@dataclass(frozen=True)
class Problem:
    """A model, a specification and (optionally) the actions the strategy may use.

    Args:
        model: the interval MDP.
        specification: what to compute.
        allowed: ``(n_states, n_actions)`` mask of allowed actions (a sub-model); states
            without an allowed action get value 0 and strategy -1.

    Raises:
        SpecificationError: on masks of the wrong shape, unknown labels or state indices.
    """

    model: IMDP
    specification: Specification
    allowed: np.ndarray | None = None

    def __post_init__(self) -> None:
        m = self.model
        if self.allowed is not None:
            a = np.asarray(self.allowed)
            if a.shape != (m.n_states, m.n_actions) or a.dtype != bool:
                raise SpecificationError(
                    f"allowed must be a boolean ({m.n_states}, {m.n_actions}) mask, got "
                    f"{a.dtype} {a.shape}"
                )
        prop = self.specification.property
        if isinstance(prop, ReachAvoid):
            resolve_states(m, prop.target, "target")
            if prop.avoid is not None:
                resolve_states(m, prop.avoid, "avoid")
        else:
            w = np.asarray(prop.reward, dtype=np.float64)
            if w.shape != (m.n_states,) or not np.all(np.isfinite(w)):
                raise SpecificationError(
                    f"reward must be a finite array of shape ({m.n_states},), got {w.shape}"
                )

    def row_mask(self) -> np.ndarray:
        if self.allowed is None:
            return np.ones(self.model.n_rows, dtype=bool)
        return graph.rows_from_actions(self.model, self.allowed)


def resolve_states(model: IMDP, states: StateSet, what: str) -> np.ndarray:
    """A boolean state mask from a mask, a label, label names or state indices."""
    if isinstance(states, str):
        states = [states]
    arr = np.asarray(states)
    if arr.dtype == bool:
        if arr.shape != (model.n_states,):
            raise SpecificationError(
                f"{what} mask must have shape ({model.n_states},), got {arr.shape}"
            )
        return arr.copy()
    if arr.size == 0:
        return np.zeros(model.n_states, dtype=bool)
    if arr.dtype.kind in "US":
        mask = np.zeros(model.n_states, dtype=bool)
        for name in arr.tolist():
            if name not in model.propositions:
                raise SpecificationError(
                    f"{what} label {name!r} is not among the model's propositions "
                    f"{model.propositions}"
                )
            mask |= model.label_matrix[:, model.propositions.index(name)]
        return mask
    if arr.dtype.kind in "iu":
        bad = arr[(arr < 0) | (arr >= model.n_states)]
        if bad.size:
            raise SpecificationError(f"{what} state {bad[0]} is not in [0, {model.n_states})")
        mask = np.zeros(model.n_states, dtype=bool)
        mask[arr] = True
        return mask
    raise SpecificationError(f"cannot read {what} states from {states!r}")


@dataclass(frozen=True)
class ValueIteration:
    """Robust value iteration with the state-ordering adversary.

    Args:
        tolerance: the width of the certified bracket ``upper - lower`` at which to stop
            (default 1e-8); with ``certified=False``, the residual ``max |V_k - V_{k-1}|``
            at which to stop.
        max_iterations: give up after this many sweeps (the solution then reports
            ``converged=False`` and the bracket reached so far).
        callback: called as ``callback(iteration, residual)`` after every sweep.
        precompute: settle the states of (worst- or best-case) reachability probability
            0 and (worst case) 1 by graph analysis before iterating (default). Without it
            the iteration alone approaches the same least fixed point, more slowly.
        strategy_iteration: for maximal reachability, switch to robust strategy
            iteration (exact sparse evaluation of a strategy against the adversary's best
            response, then strict improvements) when the sweeps creep towards the
            tolerance (default). Without it plain sweeps can take millions of sweeps where
            mass leaks slowly out of near-end-components.
        certified: bracket every value from below and above and stop when the bracket is
            narrower than ``tolerance`` (default). ``certified=False`` is the fast
            *uncertified* mode: it stops on the residual alone, which does not bound the
            error (a slow leak can leave an error far above the residual); its ``upper``
            is then the trivial bound.
    """

    tolerance: float = 1e-8
    max_iterations: int = 1_000_000
    callback: Callable[[int, float], None] | None = None
    precompute: bool = True
    strategy_iteration: bool = True
    certified: bool = True

    def __post_init__(self) -> None:
        if not self.tolerance > 0:
            raise SpecificationError(f"tolerance must be positive, got {self.tolerance}")
        if self.max_iterations < 1:
            raise SpecificationError(f"max_iterations must be >= 1, got {self.max_iterations}")


@dataclass
class Solution:
    """Result of :func:`solve`.

    Attributes:
        values: ``(n_states,)`` values. Reachability: the sound lower bound of the bracket
            (``values == lower``); every value is attained: the strategy reaches the
            target with at least this probability against every adversary (or, for a
            minimising strategy, the value is at most ``upper``). Discounted reward: the
            centre of the bracket.
        lower, upper: ``(n_states,)`` the certified bracket, ``lower <= V* <= upper`` for
            the optimal values ``V*`` (up to floating-point rounding, ~1e-15). With the
            uncertified mode ``upper`` is only the trivial bound (1 for reachability; for
            discounted reward the residual bound, which is sound for that property).
        strategy: ``(n_states,)`` chosen action per state (-1: none; targets, avoided
            states, states settled by graph analysis and states without allowed actions).
        residual: the last ``max |V_k - V_{k-1}|`` (a sweep with the exact order).
        iterations: the number of sweeps (from below; the sweeps that check or tighten
            the upper bound are counted in ``upper_sweeps``).
        evaluations: the number of exact strategy evaluations by strategy iteration
            (each: one or more sparse linear solves; 0 when the sweeps did not creep).
        converged: whether the stopping rule was met (certified: ``max(upper - lower) <
            tolerance``; uncertified: ``residual < tolerance``).
        fixed: ``(n_states,)`` mask of the states whose value was set without iteration.
        upper_sweeps: sweeps from above (verification of the upper bound).
        q_values: ``(n_rows,)`` robust value of every row under the final values
            (``nan`` for rows outside the allowed sub-model); computed on first access.
    """

    values: np.ndarray
    strategy: np.ndarray
    residual: float
    iterations: int
    converged: bool = True
    evaluations: int = 0
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upper_sweeps: int = 0
    _q: Callable[[], np.ndarray] | None = field(default=None, repr=False)
    _q_cache: np.ndarray | None = field(default=None, repr=False)

    @property
    def error(self) -> float:
        """``max(upper - lower)``: the certified error bound of ``values``."""
        if self.upper.size == 0:
            return float("inf")
        return float(np.max(self.upper - self.lower))

    @property
    def q_values(self) -> np.ndarray:
        if self._q_cache is None:
            if self._q is None:
                raise SpecificationError("this solution carries no row values")
            self._q_cache = self._q()
        return self._q_cache


def _reduce(model: IMDP, q: np.ndarray, maximize: bool) -> np.ndarray:
    op = np.maximum if maximize else np.minimum
    return op.reduceat(q, model.state_ptr[:-1])


def solve(problem: Problem, algorithm: ValueIteration | None = None) -> Solution:
    """Solve ``problem`` by robust value iteration (see the module docstring)."""
    alg = ValueIteration() if algorithm is None else algorithm
    m = problem.model
    spec = problem.specification
    maximize = spec.strategy == "maximize"
    pessimistic = spec.satisfaction == "pessimistic"
    adversary_minimizes = maximize == pessimistic
    rows = problem.row_mask()
    n = m.n_states
    acting = graph.has_row(m, rows)
    fixed = ~acting
    fixed_val = np.zeros(n)
    reward: np.ndarray | None = None
    discount = 1.0
    prob1_choice = np.full(n, -1, dtype=np.int64)
    prob1 = np.zeros(n, dtype=bool)
    prop = spec.property
    if isinstance(prop, ReachAvoid):
        target = resolve_states(m, prop.target, "target")
        avoid = (
            np.zeros(n, dtype=bool)
            if prop.avoid is None
            else resolve_states(m, prop.avoid, "avoid") & ~target
        )
        if not alg.precompute:
            zero = np.zeros(n, dtype=bool)
        elif maximize and pessimistic:
            pos, _ = graph.robust_positive_reach(m, target, avoid, rows)
            prob1, prob1_choice = graph.robust_almost_sure_reach(m, target, avoid, rows, region=pos)
            zero = ~pos
        elif maximize:
            zero = ~graph.possible_reach(m, target, avoid, rows)
        else:
            zero = np.zeros(n, dtype=bool)
        fixed = fixed | target | avoid | zero | prob1
        fixed_val = np.where(target | prob1, 1.0, 0.0)
    else:
        reward = np.asarray(prop.reward, dtype=np.float64)
        discount = float(prop.discount)
    fixed_val = np.where(fixed, fixed_val, 0.0)

    free = ~fixed
    free_rows = np.flatnonzero(rows & free[m.row_state])
    rs = m.row_state[free_rows]
    seg = np.flatnonzero(np.concatenate(([True], rs[1:] != rs[:-1]))) if rs.size else rs
    seg_states = rs[seg]
    op = np.maximum if maximize else np.minimum

    def backup(v: np.ndarray) -> np.ndarray:
        return v if reward is None else reward + discount * v

    sigma: np.ndarray | None = None
    evaluations = 0
    upper_sweeps = 0
    if reward is None:
        v, upper, residual, it, sigma, evaluations, q_free, upper_sweeps = _reach_sweeps(
            m, free_rows, fixed_val, adversary_minimizes, maximize, alg
        )
        lower = v.copy()
        converged = (
            bool(np.max(upper - lower, initial=0.0) < alg.tolerance)
            if alg.certified
            else bool(residual < alg.tolerance)
        )
    else:
        # discounted reward: Jacobi sweeps that tolerate successors out of order by less
        # than tolerance / 100, then exact sweeps until the residual (certified: the
        # contraction bound on the error) is small
        full = OrderingAdversary(
            m, adversary_minimizes, rows=free_rows, resort_tolerance=alg.tolerance * 1e-2
        )
        v, residual, it = fixed_val.copy(), 0.0, 0
        factor = discount / (1.0 - discount)
        goal = alg.tolerance / (2.0 * factor) if alg.certified and factor > 0 else alg.tolerance
        while free_rows.size and it < alg.max_iterations:
            it += 1
            q_free = full.expectation(backup(v))
            v_new = v.copy()
            v_new[seg_states] = op.reduceat(q_free, seg)
            residual = float(np.max(np.abs(v_new - v)))
            v = v_new
            if alg.callback is not None:
                alg.callback(it, residual)
            if residual < goal:
                if full.resort_tolerance == 0.0:
                    break
                full.resort_tolerance = 0.0
        q_free = full.expectation(backup(v)) if free_rows.size else np.zeros(0)
        # ||V* - v|| <= gamma / (1 - gamma) * residual for an exact sweep (contraction)
        err = np.where(fixed, 0.0, factor * residual)
        lower, upper = v - err, v + err
        converged = bool(residual < goal) and full.resort_tolerance == 0.0
    strategy = _strategy(m, free_rows, q_free, seg, seg_states, v, maximize, prop, alg.tolerance)
    if sigma is not None:
        # strategy iteration's strategy: its exact value is the least fixed point
        strategy[seg_states] = m.row_action[sigma]
    if isinstance(prop, ReachAvoid) and maximize and pessimistic:
        strategy = np.where(prob1 & (prob1_choice >= 0), m.row_action[prob1_choice], strategy)
    final_v = backup(v)

    def all_q() -> np.ndarray:
        q = np.full(m.n_rows, np.nan)
        all_rows = np.flatnonzero(rows)
        if all_rows.size:
            adv = OrderingAdversary(m, adversary_minimizes, rows=all_rows)
            q[all_rows] = adv.expectation(final_v)
        return q

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
        _q=all_q,
    )


def _layers(m: IMDP, free_rows: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """Breadth-first distance (in hops over ``upper > 0`` edges of ``free_rows``) from each
    state to ``sources``; ``inf`` where there is no path."""
    row_mask = np.zeros(m.n_rows, dtype=bool)
    row_mask[free_rows] = True
    ptr, inc_row, _, inc_upper = m.incoming()
    return backward_distance(
        np.asarray(sources, dtype=bool), row_mask, m.row_state, ptr, inc_row, inc_upper
    )


def _reach_sweeps(
    m: IMDP,
    free_rows: np.ndarray,
    fixed_val: np.ndarray,
    adversary_minimizes: bool,
    maximize: bool,
    alg: ValueIteration,
) -> tuple[np.ndarray, np.ndarray, float, int, np.ndarray | None, int, np.ndarray, int]:
    """Reachability value iteration from below, and a certified upper bound.

    **From below**: state-by-state Gauss-Seidel sweeps. The free states are visited in
    order of their graph distance to the value-1 states (targets, and states of worst-case
    value 1), each update reading the values written before it in the same sweep
    (:class:`planner.imdp.kernels.ReachSweeper`, compiled), with the exact adversary for the
    current values and ``max(old, new)``. Starting from ``V_0 <= T(V_0)``, every update
    stays below the least fixed point and the values only increase, which is what makes zero
    lower bounds and end components safe. For a maximising strategy only every
    ``_FULL_EVERY``-th sweep evaluates all rows (and records each state's best row); the
    sweeps between evaluate the recorded best rows only (modified policy iteration: each
    such update is at most the full one, so it stays sound; for a minimising strategy it
    would not be, and every sweep is full).

    **From above** (``certified``): the value is the *least* fixed point of the Bellman
    operator ``T`` (targets at 1), so by Knaster-Tarski every superharmonic ``U``
    (``T(U) <= U``) is an upper bound; no end-component analysis is needed to *check* one.
    When a full sweep from below changes no value by the current goal (``tolerance`` at
    first), the candidate ``U = min(1, L + tolerance / 2)`` is checked by passes of
    :func:`planner.imdp.kernels.upper_sweep` (optimistic value iteration, Hartmanns and
    Kaminski 2020): a pass that finds no state with ``T(U)(s) > U(s)`` certifies ``U``.
    Candidates fail where the values from below still move (a slow leak, or mass that
    circulates long among free states): then, for maximal reachability on at most
    ``_SI_MAX_STATES`` free states, strategy iteration makes the values exact (the least
    fixed point, at which the candidate passes), else the goal is divided by 8 and the
    sweeps continue. After ``_OVI_TRIES`` failures
    the upper bound is iterated from the trivial superharmonic ``U = 1`` instead, each
    pass again a sound upper bound (it may stall above the value inside end components
    that the opposing side can hold; the bracket then stays wide and ``converged`` is
    ``False``).

    Returns ``(lower, upper, residual, sweeps, strategy, evaluations, q, upper_sweeps)``:
    ``strategy`` is the last strategy iteration's optimal strategy (one row per free
    state) or ``None``; ``q`` the robust value of every free row under the final values.
    """
    v = fixed_val.copy()
    if free_rows.size == 0:
        return v, v.copy(), 0.0, 0, None, 0, np.zeros(0), 0
    dist = _layers(m, free_rows, fixed_val == 1.0)
    sweeper = ReachSweeper(m, free_rows, dist, maximize, adversary_minimizes)
    residual = 0.0
    it = 0
    n_free = sweeper.states.size
    use_si = maximize and alg.strategy_iteration
    next_eval = _FIRST_EVALUATION if use_si else alg.max_iterations
    sigma: np.ndarray | None = None
    evaluations = 0
    history: list[tuple[int, float]] = []
    want_full = False
    goal = alg.tolerance
    upper: np.ndarray | None = None
    upper_sweeps = 0
    tries = 0
    exacted = False
    if alg.certified and maximize and adversary_minimizes:
        v, upper, residual, it, upper_sweeps, done, evaluations = _interval_iteration(
            m, sweeper, v, alg
        )
        if done:
            q = sweeper.row_values(v)
            return v, upper, residual, it, None, evaluations, q, upper_sweeps
    while it < alg.max_iterations:
        it += 1
        check = it > next_eval
        # a light sweep (one row per state) is a lower bound only when the strategy maximises
        full = want_full or check or not maximize or it % _FULL_EVERY == 1
        before = v.copy() if check else v
        residual = sweeper.sweep(v, full)
        if alg.callback is not None:
            alg.callback(it, residual)
        if full:
            history.append((it, residual))
        want_full = residual < goal
        if want_full and full:
            if not alg.certified:
                break
            u, passes = certify.optimistic_candidate(sweeper, v, alg.tolerance / 2)
            upper_sweeps += passes
            if u is None and use_si and not exacted and n_free <= _SI_MAX_STATES:
                # make the values from below exact (the least fixed point), then check
                exacted = True
                x, sigma, rounds = _strategy_iteration(
                    m,
                    free_rows,
                    v,
                    fixed_val,
                    adversary_minimizes,
                    alg.tolerance,
                    max_rounds=_CERTIFY_ROUNDS,
                )
                evaluations += rounds
                if x is not None:
                    v = np.maximum(v, x)
                    u, passes = certify.optimistic_candidate(sweeper, v, alg.tolerance / 2)
                    upper_sweeps += passes
            if u is not None:
                # the minimum of superharmonic vectors is superharmonic
                upper = u if upper is None else np.minimum(upper, u)
                if np.max(upper - v) < alg.tolerance:
                    break
            tries += 1
            if tries >= _OVI_TRIES:
                break
            goal = max(goal / 8.0, _MIN_GOAL)
            want_full = False
        if not check:
            continue
        next_eval *= 2
        moving = v - before >= alg.tolerance
        x = None
        if 0 < moving.sum() <= _LOCAL_FRACTION * n_free:
            # the states still moving, with the others held at their current values
            local_rows = free_rows[moving[m.row_state[free_rows]]]
            x, _, rounds = _strategy_iteration(
                m, local_rows, v, np.where(moving, 0.0, v), adversary_minimizes, alg.tolerance
            )
            evaluations += rounds
        elif n_free <= _SI_MAX_STATES and _creeping(history, alg.tolerance):
            x, sigma, rounds = _strategy_iteration(
                m, free_rows, v, fixed_val, adversary_minimizes, alg.tolerance
            )
            evaluations += rounds
        if x is not None:
            v = np.maximum(v, x)
    if upper is None:
        upper = fixed_val.copy()
        upper[sweeper.states] = 1.0
    if alg.certified and np.max(upper - v) >= alg.tolerance:
        # from a superharmonic U (at worst the trivial U = 1) every pass stays one
        for _ in range(_FALLBACK_PASSES):
            upper_sweeps += 1
            sweeper.upper_pass(upper)
            if np.max(upper - v) < alg.tolerance:
                break
    return v, upper, residual, it, sigma, evaluations, sweeper.row_values(v), upper_sweeps


def _interval_iteration(
    m: IMDP, sweeper: ReachSweeper, v: np.ndarray, alg: ValueIteration
) -> tuple[np.ndarray, np.ndarray, float, int, int, bool, int]:
    """Interval iteration with end-component bounds, for maximal reachability against a
    minimising adversary (:class:`planner.imdp.certify.EndComponentBounds`).

    Each round: a Gauss-Seidel sweep from below (all rows every ``_FULL_EVERY``-th round,
    else the best rows), the lower bound raised to the best exit on the traversable end
    components, a Gauss-Seidel pass ``U = min(U, T(U))`` from above (all rows) and ``U``
    lowered to the best exit on every end component. From ``U = 1`` both sides stay sound
    bounds in every round. Every ``_II_WINDOW`` rounds the states still moving from below,
    if at most ``_LOCAL_FRACTION`` of the free states, are solved by strategy iteration
    with the others held at ``L`` (sound, as in :func:`_reach_sweeps`).

    When the width has not halved over ``_II_WINDOW`` rounds (mass that circulates for a
    long time among states of nearly equal value: ``U`` creeps down at the rate of the
    circulation's leak), the states ``B`` still wider than ``tolerance / 2`` are solved by
    strategy iteration with the others held (when they are at most ``_LOCAL_FRACTION`` of
    the free states; ``_II_STALLS`` stalls with more end it): from below with ``L``
    outside (a sound lower bound), and from above with ``U`` outside, *unlowered*: ``Y``.
    The candidate ``U`` with
    ``min(U, max(Y, L) + tolerance / 4)`` on ``B`` is kept only if checking passes certify
    it superharmonic (:func:`planner.imdp.certify.check_upper`, violating states raised to
    their Bellman value until a pass finds none; then it bounds ``V*`` by Knaster-Tarski,
    however inexact ``Y`` was). At most ``_II_REPAIRS`` such repairs, none without
    ``strategy_iteration``.

    Returns ``(lower, upper, residual, sweeps, upper_passes, done, evaluations)``:
    ``done`` when ``max(U - L) < tolerance``, else the caller continues from ``L`` and
    ``U`` with its other means.
    """
    st = sweeper.states
    free = np.zeros(m.n_states, dtype=bool)
    free[st] = True
    bounds = certify.EndComponentBounds(m, sweeper, free)
    u = v.copy()
    u[st] = 1.0
    bounds.deflate(u)
    residual = np.inf
    it = passes = evaluations = repairs = stalls = 0
    checkpoint = np.inf
    tol = alg.tolerance
    before = v.copy()
    while it < alg.max_iterations:
        it += 1
        residual = sweeper.sweep(v, it % _FULL_EVERY == 1)
        if alg.callback is not None:
            alg.callback(it, residual)
        bounds.collapse(v)
        sweeper.upper_pass(u)
        passes += 1
        bounds.deflate(u)
        width = float(np.max(u[st] - v[st]))
        if width < tol:
            # a last full sweep: its change is at most the width (L <= T(L) <= V* <= U)
            it += 1
            residual = sweeper.sweep(v, True)
            return v, u, residual, it, passes, True, evaluations
        if it % _II_WINDOW:
            continue
        if alg.strategy_iteration:
            # the states still moving from below, by strategy iteration with the others
            # held at their lower bounds (sound; as in ``_reach_sweeps``)
            moving = v - before >= tol
            if 0 < moving.sum() <= _LOCAL_FRACTION * st.size:
                rows = np.sort(sweeper.rows[moving[m.row_state[sweeper.rows]]])
                x, _, k = _strategy_iteration(m, rows, v, np.where(moving, 0.0, v), True, tol)
                evaluations += k
                if x is not None:
                    v = np.maximum(v, x)
            before = v.copy()
        if width <= 0.5 * checkpoint:
            checkpoint = width
            continue
        wide = np.zeros(m.n_states, dtype=bool)
        wide[st[u[st] - v[st] >= tol / 2]] = True
        if not alg.strategy_iteration or repairs >= _II_REPAIRS or stalls >= _II_STALLS:
            break
        if wide.sum() > _LOCAL_FRACTION * st.size:
            # too many states for a cheap repair: keep iterating for a while
            stalls += 1
            checkpoint = width
            continue
        repairs += 1
        rows = np.sort(sweeper.rows[wide[m.row_state[sweeper.rows]]])
        x, _, k = _strategy_iteration(m, rows, v, np.where(wide, 0.0, v), True, _CANDIDATE_SLACK)
        evaluations += k
        if x is not None:
            v = np.maximum(v, x)
        # switching slack ~1e-15: a row left better than Y by more than tolerance / 4 times
        # its mass leaving B would fail the check
        y, _, k = _strategy_iteration(
            m, rows, u, np.where(wide, 0.0, u), True, _CANDIDATE_SLACK, sound=False
        )
        evaluations += k
        if y is not None:
            cand = u.copy()
            cand[wide] = np.minimum(u[wide], np.maximum(y[wide], v[wide]) + tol / 4)
            ok, k = certify.check_upper(sweeper, cand, _REPAIR_PASSES, raise_violations=True)
            passes += k
            if ok:
                u = np.minimum(u, cand)
        checkpoint = float(np.max(u[st] - v[st]))
    return v, u, residual, it, passes, False, evaluations


_II_WINDOW = 16
"""Rounds of interval iteration over which the bracket must at least halve."""

_II_REPAIRS = 3
"""Strategy-iteration repairs of a stalled interval iteration."""

_REPAIR_PASSES = 16
"""Checking passes of a repaired upper candidate (violating states raised)."""

_II_STALLS = 4
"""Stalled windows with too many wide states before interval iteration gives up."""

_CANDIDATE_SLACK = 1e-13
"""The ``tol`` given to the strategy iteration of an upper candidate (switching slack
``tol / 100``)."""

_OVI_TRIES = 3
"""Failed candidates before the upper bound is iterated from 1 instead."""

_FALLBACK_PASSES = 50
"""Passes of the upper bound from the last certified vector (or ``U = 1``) when no
candidate closed the bracket (each pass keeps it certified)."""

_CERTIFY_ROUNDS = 12
"""Strategy-improvement rounds spent on making the values exact for the certificate."""

_MIN_GOAL = 1e-15
"""The smallest residual goal the sweeps from below are driven to."""


_LOCAL_FRACTION = 0.25
"""Strategy iteration on the states still moving at a check when they are at most this
fraction of the free states."""

_FULL_EVERY = 4
"""Every this many sweeps (and after a sweep below the tolerance) all rows are evaluated."""

_SI_MAX_STATES = 20_000
"""Strategy iteration only for at most this many free states: its sparse LU solves can
fill in badly on large unstructured graphs (a 3000-state random model: ~0.5 s each)."""

_FIRST_EVALUATION = 16
"""Sweeps before the first check for slow convergence (then after 32, 64, ... sweeps)."""

_CREEP_SWEEPS = 1000
"""Projected sweeps to the tolerance beyond which value iteration counts as creeping."""


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
    if now < tol:
        return False
    if now >= then:
        return True
    rate = (now / then) ** (1.0 / (k - k0))
    return np.log(tol / now) / np.log(rate) > max(4 * k, _CREEP_SWEEPS)


_MAX_IMPROVEMENTS = 100
"""Strategy improvement rounds per strategy iteration."""


def _strategy_iteration(
    m: IMDP,
    free_rows: np.ndarray,
    v: np.ndarray,
    fixed_val: np.ndarray,
    adversary_minimizes: bool,
    tol: float,
    max_rounds: int | None = None,
    sound: bool = True,
) -> tuple[np.ndarray | None, np.ndarray | None, int]:
    """Robust strategy iteration for maximal reachability, started from the strategy
    greedy for ``v``.

    Returns ``(values, strategy, evaluations)``: ``V_sigma`` of the last strategy
    evaluated (``None`` if the first evaluation gave up), that strategy (one row per free
    state) if no state wanted to switch any more, else ``None``, and the number of
    strategies evaluated.

    Each round evaluates ``sigma`` exactly (:func:`strategy_reach_value`: the adversary's
    best response included) and switches a state to its best row only where that row's
    robust value exceeds the current row's by more than ``tol / 100``. Because switches
    are strict, ``V_sigma`` never decreases and no new end component can trap mass that
    had a positive value; when no state switches, ``V_sigma`` is a fixed point of the
    Bellman operator (within the slack) and, being a strategy's value, at most the least
    fixed point: it *is* the least fixed point. With a cooperating adversary each round
    evaluates the chain of ``sigma`` and the adversary greedy for the last values (a
    lower bound, not ``V_sigma``): the values stay sound, the strategy is not returned.
    ``sound=False``: the evaluations are not lowered by their rounding bound (the values
    are then a candidate, not a lower bound; see :func:`strategy_reach_value`).
    """
    rs = m.row_state[free_rows]
    seg = first_of_runs(rs)
    seg_id = np.cumsum(np.concatenate(([0], (rs[1:] != rs[:-1]).astype(np.int64))))
    full = OrderingAdversary(m, adversary_minimizes, rows=free_rows)
    q = full.expectation(v)
    choice = _strategy_rows(m, free_rows, q, seg, rs[seg], v, True, True, tol)
    sigma = choice[rs[seg]]
    slack = tol * 1e-2
    best: np.ndarray | None = None
    limit = _MAX_IMPROVEMENTS if max_rounds is None else max_rounds
    for rounds in range(1, limit + 1):
        start = v if best is None else best
        x = strategy_reach_value(m, sigma, fixed_val, adversary_minimizes, start, sound=sound)
        if x is None:
            return best, None, rounds
        best = x if best is None else np.maximum(best, x)
        q = full.expectation(x)
        q_best = np.maximum.reduceat(q, seg)
        q_sigma = q[np.searchsorted(free_rows, sigma)]
        better = q_best > q_sigma + slack
        if not better.any():
            # a cooperating adversary is only evaluated for one order (a lower bound), so
            # only the opposing adversary's case yields an exactly evaluated strategy
            return best, (sigma if adversary_minimizes else None), rounds
        top = np.flatnonzero(q >= q_best[seg_id])
        top = top[first_of_runs(seg_id[top])]  # one best row per state, in state order
        sigma = np.where(better, free_rows[top], sigma)
    return best, None, limit


def _strategy(
    m: IMDP,
    free_rows: np.ndarray,
    q_free: np.ndarray,
    seg: np.ndarray,
    seg_states: np.ndarray,
    v: np.ndarray,
    maximize: bool,
    prop: ReachAvoid | DiscountedReward,
    tol: float,
) -> np.ndarray:
    """Memoryless strategy: an optimal action per free state (-1 elsewhere)."""
    reach_max = isinstance(prop, ReachAvoid) and maximize
    choice = _strategy_rows(m, free_rows, q_free, seg, seg_states, v, maximize, reach_max, tol)
    return np.where(choice >= 0, m.row_action[np.maximum(choice, 0)], -1)


def _strategy_rows(
    m: IMDP,
    free_rows: np.ndarray,
    q_free: np.ndarray,
    seg: np.ndarray,
    seg_states: np.ndarray,
    v: np.ndarray,
    maximize: bool,
    reach_max: bool,
    tol: float,
) -> np.ndarray:
    """An optimal row per free state (-1 elsewhere).

    For maximal reachability, optimal rows are picked by a robust attractor from the
    states already settled (value fixed, or 0), so the strategy cannot idle inside an end
    component whose optimal rows all tie: each chosen row moves one layer closer with
    positive probability under every adversary.
    """
    n = m.n_states
    choice = np.full(n, -1, dtype=np.int64)
    if free_rows.size == 0:
        return choice
    rs = m.row_state[free_rows]
    best = (np.maximum if maximize else np.minimum).reduceat(q_free, seg)
    best_of = np.zeros(n)
    best_of[seg_states] = best
    slack = max(10 * tol, 1e-12)
    opt_local = np.flatnonzero(np.abs(q_free - best_of[rs]) <= slack)
    first = opt_local[first_of_runs(rs[opt_local])]
    choice[rs[first]] = free_rows[first]
    if reach_max:
        free = np.zeros(n, dtype=bool)
        free[seg_states] = True
        settled = ~free | (v <= 0)
        cand = np.zeros(m.n_rows, dtype=bool)
        cand[free_rows[opt_local]] = True
        _, attr = graph._attractor(m, settled, cand)
        choice = np.where((attr >= 0) & free, attr, choice)
    return choice
