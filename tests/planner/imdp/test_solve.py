import importlib
import threading
from concurrent.futures import Future
from fractions import Fraction

import numpy as np
import pytest

from planner.errors import SpecificationError
from planner.imdp import (
    IMDP,
    DiscountedReward,
    Problem,
    ReachAvoid,
    Specification,
    ValueIteration,
    graph,
    solve,
)
from tests.planner.imdp.reference import (
    random_imdp,
    ref_discounted,
    ref_reach,
    ref_reach_by_strategies,
    ref_strategy_value,
    slow_leak_imdp,
    sticky_imdp,
)

solve_module = importlib.import_module("planner.imdp.reachability")
interval = importlib.import_module("planner.imdp.interval")
widening = importlib.import_module("planner.imdp.widening")


def reach(m, target, avoid=None, sat="pessimistic", strategy="maximize", **kw):
    spec = Specification(ReachAvoid(target, avoid), sat, strategy)
    return solve(Problem(m, spec, **kw), ValueIteration(tolerance=1e-12))


def test_self_loop_trap_gives_zero_worst_case():
    # state 0: one action, [0, 1] to itself and [0, 1] to the goal (state 1)
    m = IMDP(2, [0, 0, 1], [0, 0, 0], [0, 1, 1], [0, 0, 1], [1, 1, 1], labels=[(), ("g",)])
    assert reach(m, "g").values.tolist() == [0.0, 1.0]
    # the cooperating adversary reaches the goal surely; the sweeps' values are lowered by
    # their rounding bound (a sound lower bound below 1 by a few ulps), the bracket holds 1
    best = reach(m, "g", sat="optimistic")
    assert best.values[1] == 1.0 and 1.0 - 1e-13 <= best.values[0] <= 1.0 == best.upper[0]
    # value iteration alone (no graph precomputation) stays at the least fixed point
    plain = ValueIteration(1e-12, precompute=False)
    assert solve(Problem(m, Specification(ReachAvoid("g"))), plain).values.tolist() == [0, 1]


def test_geometric_closed_form():
    # state 0 -> goal [.2,.5], sink [.1,.4], itself [.3,.6]
    m = IMDP(
        3,
        [0, 0, 0, 1, 2],
        [0] * 5,
        [0, 1, 2, 1, 2],
        [0.3, 0.2, 0.1, 1, 1],
        [0.6, 0.5, 0.4, 1, 1],
        labels=[(), ("g",), ()],
    )
    # worst: p = (goal .2, sink .4, self .4): V = .2 / (1 - .4) = 1/3
    # best: p = (goal .5, self .4, sink .1): V = .5 / (1 - .4) = 5/6
    assert reach(m, "g").values[0] == pytest.approx(float(Fraction(1, 3)), abs=1e-10)
    assert reach(m, "g", sat="optimistic").values[0] == pytest.approx(5 / 6, abs=1e-10)
    # minimising strategy with the adversary against it (only one action: same numbers)
    assert reach(m, "g", strategy="minimize").values[0] == pytest.approx(5 / 6, abs=1e-10)


def test_choice_between_safe_and_risky_action_and_avoid():
    # s0: a0 -> goal 1 w.p. [.5,.9], s2 (bad) rest; a1 -> s1 [1,1]; s1 -> goal [.7,.8], s0 rest
    m = IMDP(
        4,
        [0, 0, 0, 1, 1, 2, 3],
        [0, 0, 1, 0, 0, 0, 0],
        [3, 2, 1, 3, 0, 2, 3],
        [0.5, 0.1, 1, 0.7, 0.2, 1, 1],
        [0.9, 0.5, 1, 0.8, 0.3, 1, 1],
        labels=[(), (), ("bad",), ("g",)],
    )
    sol = reach(m, "g", avoid="bad")
    # a1 then s1: reaches s1, from s1 goal w.p. >= .7 else back to s0 -> value 1 (a.s.)
    assert sol.values.tolist() == [1.0, 1.0, 0.0, 1.0]
    assert sol.strategy[0] == 1
    # avoiding s1 (label-free) by restricting actions: only a0 at s0
    allowed = m.enabled.copy()
    allowed[0, 1] = False
    sol = reach(m, "g", avoid="bad", allowed=allowed)
    assert sol.values[0] == pytest.approx(0.5, abs=1e-12)
    assert sol.strategy[0] == 0


def test_discounted_reward_closed_form():
    # s0 -> s1 [.2,.6], s2 [.4,.8]; s1, s2 absorbing; W(s1) = 10 per landing, gamma = .9
    m = IMDP(3, [0, 0, 1, 2], [0] * 4, [1, 2, 1, 2], [0.2, 0.4, 1, 1], [0.6, 0.8, 1, 1])
    w = np.array([0.0, 10.0, 0.0])
    worst = solve(Problem(m, Specification(DiscountedReward(w, 0.9))), ValueIteration(1e-11))
    best = solve(
        Problem(m, Specification(DiscountedReward(w, 0.9), "optimistic")), ValueIteration(1e-11)
    )
    # V(s1) = 10 + .9 V(s1) = 100; V(s0) = p1 * (10 + 90) with p1 = .2 or .6
    assert worst.values == pytest.approx([20.0, 100.0, 0.0], abs=1e-8)
    assert best.values == pytest.approx([60.0, 100.0, 0.0], abs=1e-8)


@pytest.mark.parametrize("zero_lower", [True, False])
@pytest.mark.parametrize("sat", ["pessimistic", "optimistic"])
def test_reach_matches_reference(zero_lower, sat):
    rng = np.random.default_rng(11 if zero_lower else 12)
    for _ in range(3):
        m = random_imdp(rng, n_states=20, zero_lower=zero_lower)
        tgt, avd = m.states_labelled("goal"), m.states_labelled("bad")
        got = reach(m, "goal", "bad", sat=sat)
        ref = ref_reach(m, tgt, avd & ~tgt, pessimistic=sat == "pessimistic")
        assert got.values == pytest.approx(ref, abs=1e-8)
        assert got.converged and got.residual < 1e-12


def test_without_graph_precomputation_same_values():
    rng = np.random.default_rng(13)
    m = random_imdp(rng, n_states=25)
    spec = Specification(ReachAvoid("goal", "bad"))
    with_pre = solve(Problem(m, spec), ValueIteration(1e-12))
    plain = solve(Problem(m, spec), ValueIteration(1e-12, precompute=False))
    assert plain.values == pytest.approx(with_pre.values, abs=1e-9)
    assert plain.iterations >= with_pre.iterations


def test_min_reach_matches_reference():
    rng = np.random.default_rng(21)
    m = random_imdp(rng, n_states=15)
    tgt, avd = m.states_labelled("goal"), m.states_labelled("bad")
    for sat in ("pessimistic", "optimistic"):
        got = reach(m, "goal", "bad", sat=sat, strategy="minimize")
        ref = ref_reach(m, tgt, avd & ~tgt, pessimistic=sat == "pessimistic", maximize=False)
        assert got.values == pytest.approx(ref, abs=1e-8)


def test_invariants_pessimistic_below_optimistic():
    rng = np.random.default_rng(7)
    m = random_imdp(rng, n_states=40)
    lo = reach(m, "goal", "bad")
    hi = reach(m, "goal", "bad", sat="optimistic")
    tgt = m.states_labelled("goal")
    assert np.all(lo.values <= hi.values + 1e-12)
    assert np.all(lo.values[tgt] == 1.0)
    assert np.all((lo.values >= 0) & (hi.values <= 1))


def test_strategy_achieves_the_values():
    rng = np.random.default_rng(8)
    m = random_imdp(rng, n_states=30)
    sol = reach(m, "goal", "bad")
    allowed = np.zeros_like(m.enabled)
    acting = sol.strategy >= 0
    allowed[np.flatnonzero(acting), sol.strategy[acting]] = True
    allowed[~acting] = m.enabled[~acting]
    # fixing the strategy (targets/avoid keep any action: their values are fixed anyway)
    fixed = reach(m, "goal", "bad", allowed=allowed)
    assert fixed.values == pytest.approx(sol.values, abs=1e-8)


@pytest.mark.parametrize("sat", ["pessimistic", "optimistic"])
def test_discounted_matches_reference(sat):
    rng = np.random.default_rng(31)
    m = random_imdp(rng, n_states=15)
    w = rng.normal(size=m.n_states)
    got = solve(Problem(m, Specification(DiscountedReward(w, 0.8), sat)), ValueIteration(1e-12))
    ref = ref_discounted(m, w, 0.8, pessimistic=sat == "pessimistic")
    assert got.values == pytest.approx(ref, abs=1e-8)


def test_specification_errors():
    m = IMDP(1, [0], [0], [0], [1.0], [1.0], labels=[("g",)])
    with pytest.raises(SpecificationError, match="satisfaction"):
        Specification(ReachAvoid("g"), "worst")
    with pytest.raises(SpecificationError, match="strategy"):
        Specification(ReachAvoid("g"), strategy="argmax")
    with pytest.raises(SpecificationError, match="discount"):
        Specification(DiscountedReward(np.zeros(1), 1.0))
    with pytest.raises(SpecificationError, match="'nope'"):
        Problem(m, Specification(ReachAvoid("nope")))
    with pytest.raises(SpecificationError, match="state 3"):
        Problem(m, Specification(ReachAvoid([3])))
    with pytest.raises(SpecificationError, match="reward"):
        Problem(m, Specification(DiscountedReward(np.zeros(2), 0.9)))
    with pytest.raises(SpecificationError, match="allowed"):
        Problem(m, Specification(ReachAvoid("g")), allowed=np.ones((2, 1), bool))
    with pytest.raises(SpecificationError, match="tolerance"):
        ValueIteration(tolerance=0)


def test_slow_leak_closed_form():
    # state 2 keeps 1 - 3e-7 .. 1 - 1e-7 on itself, exits to the goal (1) with
    # [1e-7, 2e-7] and to the sink (0) with [0, 2e-7]: the worst case keeps the goal at
    # 1e-7 and sends 2e-7 to the sink, V = 1e-7 / 3e-7 = 1/3; value iteration from 0
    # alone would creep up by about 1e-7 per sweep.
    m = IMDP(
        3,
        [0, 1, 2, 2, 2],
        [0] * 5,
        [0, 1, 1, 0, 2],
        [1, 1, 1e-7, 0, 1 - 3e-7],
        [1, 1, 2e-7, 2e-7, 1 - 1e-7],
        labels=[(), ("g",), ()],
    )
    # ~3e6 steps of stay: certified at the default 1e-8 too since the strategy's value is
    # bounded from below in exact arithmetic (planner.imdp.shown_below: a self-loop adds
    # no rounding per step); before, its rounding bound (stay x 7 eps) left it open. The
    # bounds as written in floating point make the exact value 1/3 + 5.2e-11.
    default = solve(Problem(m, Specification(ReachAvoid("g"))))
    exact = _slow_leak_exact(1e-7)
    assert abs(exact - Fraction(1, 3)) < Fraction(1, 10**9)
    assert default.converged and default.error < 1e-8
    assert Fraction(default.lower[2]) <= exact <= Fraction(default.upper[2])
    sol = solve(Problem(m, Specification(ReachAvoid("g"))), ValueIteration(1e-7))
    assert sol.values[2] == pytest.approx(1 / 3, abs=1e-7)
    assert Fraction(sol.lower[2]) <= exact <= Fraction(sol.upper[2])
    assert sol.converged and sol.iterations < 1000 and sol.evaluations >= 1
    # plain sweeps from 0 are nowhere near after as many sweeps
    plain = ValueIteration(max_iterations=1000, strategy_iteration=False)
    slow = solve(Problem(m, Specification(ReachAvoid("g"))), plain)
    assert slow.values[2] < 0.01 and not slow.converged and slow.evaluations == 0
    best = solve(Problem(m, Specification(ReachAvoid("g"), "optimistic")))
    assert best.values[2] == pytest.approx(1.0, abs=1e-8)


def _loop_exact(lo, up, target=Fraction(1)) -> Fraction:
    """The worst case of a state with entries ``(sink, itself, target)`` (bounds ``lo``,
    ``up`` as written in floating point; the target worth ``target``) in rational
    arithmetic: the adversary fills the sink, then the loop, then the target (the
    state-ordering vertex)."""
    lo_s, lo_self, lo_g = (Fraction(x) for x in lo)
    up_s, up_self, _ = (Fraction(x) for x in up)
    rem = 1 - (lo_g + lo_s + lo_self)
    p_s = lo_s + min(up_s - lo_s, rem)
    rem -= p_s - lo_s
    p_self = lo_self + min(up_self - lo_self, rem)
    rem -= p_self - lo_self
    return (lo_g + rem) * target / (1 - p_self)


def _slow_leak_exact(leak: float) -> Fraction:
    """The exact worst case of ``_leaky_loop(leak)`` (1/3 up to the rounding of its
    bounds)."""
    return _loop_exact((0.0, 1 - 3 * leak, leak), (2 * leak, 1 - leak, 2 * leak))


def test_a_self_loop_leaking_1e_8_per_step_is_certified_at_the_default():
    m = _leaky_loop(1e-8)  # a stay of 3e7 steps
    sol = solve(Problem(m, Specification(ReachAvoid("g"))))
    exact = _slow_leak_exact(1e-8)
    assert sol.converged and sol.error < 1e-8
    assert Fraction(sol.lower[2]) <= exact <= Fraction(sol.upper[2])


@pytest.mark.parametrize("leak", [1e-9, 1e-10])
def test_a_markov_chain_loop_leaking_1e_9_is_certified_at_the_default(leak):
    # point intervals written in decimal: 1 - leak on itself, leak / 2 to the goal and to
    # the sink. The chain's stay on the state is implied by what leaves it, so the leak
    # keeps its relative precision (1 - fl(1 - 1e-9) is off by 5e-8 relative)
    lo = [1 - leak, leak / 2, leak / 2, 1, 1]
    m = IMDP(3, [0, 0, 0, 1, 2], [0] * 5, [0, 1, 2, 1, 2], lo, lo, labels=[(), ("g",), ("b",)])
    sol = solve(Problem(m, Specification(ReachAvoid("g", "b"))))
    entries = slice(m.row_ptr[0], m.row_ptr[1])  # state 0's row: itself, goal, sink
    bounds = [m.lower[entries], m.upper[entries]]
    # the adversary fills the sink, then the loop (the bounds as stored: bracketed exactly)
    exact = _loop_exact(*([b[2], b[0], b[1]] for b in bounds))
    assert abs(exact - Fraction(1, 2)) < Fraction(1, 10**6)
    assert sol.converged and sol.error < 1e-8
    assert Fraction(sol.lower[0]) <= exact <= Fraction(sol.upper[0])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_slow_leak_matches_strategy_enumeration(seed):
    rng = np.random.default_rng(seed)
    m = slow_leak_imdp(rng, n_states=7)
    tgt = m.states_labelled("goal")
    sol = solve(Problem(m, Specification(ReachAvoid("goal"))))
    assert sol.converged and sol.iterations < 1000
    assert sol.values == pytest.approx(ref_reach_by_strategies(m, tgt), abs=1e-7)
    # the returned strategy achieves the values (its own worst case, by LP)
    assert (sol.strategy[2:] >= 0).all()
    strategy = {q: int(sol.strategy[q]) for q in range(2, m.n_states)}
    assert ref_strategy_value(m, tgt, strategy) == pytest.approx(sol.values, abs=1e-7)


@pytest.mark.parametrize("zero_lower", [True, False])
def test_strategy_iteration_from_the_first_sweep_matches_reference(zero_lower, monkeypatch):
    # strategy iteration after sweeps 1, 2, 4, ... (whatever the rate): same least fixed point
    monkeypatch.setattr(solve_module, "_FIRST_EVALUATION", 1)
    monkeypatch.setattr(solve_module, "_creeping", lambda history, tol: True)
    rng = np.random.default_rng(31 if zero_lower else 32)
    for _ in range(3):
        m = random_imdp(rng, n_states=20, zero_lower=zero_lower)
        tgt, avd = m.states_labelled("goal"), m.states_labelled("bad")
        for sat in ("pessimistic", "optimistic"):
            got = reach(m, "goal", "bad", sat=sat)
            ref = ref_reach(m, tgt, avd & ~tgt, pessimistic=sat == "pessimistic")
            assert got.values == pytest.approx(ref, abs=1e-8)
        plain = solve(
            Problem(m, Specification(ReachAvoid("goal", "bad"))),
            ValueIteration(1e-12, precompute=False),
        )
        assert plain.values == pytest.approx(ref_reach(m, tgt, avd & ~tgt, True), abs=1e-8)


def test_creeping_detection():
    creeping = solve_module._creeping

    def fresh(residuals):  # residuals of the sweeps 8, 16, 24, ...
        return [(8 * (k + 1), r) for k, r in enumerate(residuals)]

    assert not creeping(fresh([0.5]), 1e-8)
    assert creeping(fresh([1e-6, 1e-6]), 1e-8)  # no progress
    # values still moving by a lot: a front spreading from the targets, not a creep
    assert not creeping(fresh([0.3, 0.25]), 1e-8)
    assert not creeping(fresh([2e-3, 2e-3]), 1e-8)
    assert creeping(fresh([9e-4, 9e-4]), 1e-8)
    assert creeping(fresh([1e-6, 1e-6 * 0.9999**8]), 1e-8)
    assert not creeping(fresh([0.5**8, 0.5**16]), 1e-8)
    assert not creeping(fresh([1.0, 1e-9]), 1e-8)  # already below the tolerance
    # the rate is taken since sweep k / 2: 16 -> 32 here
    assert not creeping(fresh([1.0, 1e-3, 1e-3, 1e-3 * 0.5**16]), 1e-8)


def test_local_strategy_iteration_on_a_slow_corner(monkeypatch):
    # 40 fast states reach the goal (1) with [0.6, 0.8] and the sink (0) with [0.2, 0.4]:
    # worst case 0.6, settled within a few sweeps. Three slow states keep 1 - 3e-7 ..
    # 1 - 1e-7 on themselves and leak to fast state 2 with [1e-7, 2e-7] and to the sink
    # with [0, 2e-7]: worst case V = 0.6 * 1e-7 / 3e-7 = 0.2, which sweeps from 0 reach only
    # after millions of sweeps. With the global switch disabled, only strategy iteration on
    # the states still moving (the slow corner, the fast states held) can get there.
    monkeypatch.setattr(solve_module, "_creeping", lambda history, tol: False)
    n_fast, n_slow = 40, 3
    s, a, t, lo, up = [0, 1], [0, 0], [0, 1], [1.0, 1.0], [1.0, 1.0]
    for q in range(2, 2 + n_fast):
        s += [q, q]
        a += [0, 0]
        t += [1, 0]
        lo += [0.6, 0.2]
        up += [0.8, 0.4]
    for q in range(2 + n_fast, 2 + n_fast + n_slow):
        s += [q, q, q]
        a += [0, 0, 0]
        t += [2, 0, q]
        lo += [1e-7, 0.0, 1 - 3e-7]
        up += [2e-7, 2e-7, 1 - 1e-7]
    n = 2 + n_fast + n_slow
    m = IMDP(n, s, a, t, lo, up, labels=[(), ("g",)] + [()] * (n - 2))
    # a stay of ~3e6 steps, certified at the default 1e-8 as well since the strategy's value
    # is bounded from below in exact arithmetic (planner.imdp.shown_below); the exact
    # values of the bounds as written in floating point
    fast = _loop_exact((0.2, 0.0, 0.6), (0.4, 0.0, 0.8))
    slow = _loop_exact((0.0, 1 - 3e-7, 1e-7), (2e-7, 1 - 1e-7, 2e-7), fast)

    def contains(sol):
        lo, up = sol.lower, sol.upper
        ok = [Fraction(lo[q]) <= fast <= Fraction(up[q]) for q in range(2, 2 + n_fast)]
        ok += [Fraction(lo[q]) <= slow <= Fraction(up[q]) for q in range(2 + n_fast, n)]
        return all(ok)

    default = solve(Problem(m, Specification(ReachAvoid("g"))))
    assert default.converged and default.error < 1e-8 and contains(default)
    sol = solve(Problem(m, Specification(ReachAvoid("g"))), ValueIteration(1e-7))
    assert sol.values[2 : 2 + n_fast] == pytest.approx(0.6, abs=1e-12)
    assert sol.values[2 + n_fast :] == pytest.approx(0.2, abs=1e-7)
    assert contains(sol)
    assert sol.converged and sol.iterations < 200 and sol.evaluations >= 1
    plain = ValueIteration(max_iterations=1000, strategy_iteration=False)
    slow = solve(Problem(m, Specification(ReachAvoid("g"))), plain)
    assert np.all(slow.values[2 + n_fast :] < 0.01) and slow.evaluations == 0


def _leaky_loop(leak: float) -> IMDP:
    """State 2 keeps ``1 - 3 leak .. 1 - leak`` on itself and leaks to the goal (1) with
    ``[leak, 2 leak]`` and to the sink (0) with ``[0, 2 leak]``: worst case 1/3."""
    return IMDP(
        3,
        [0, 1, 2, 2, 2],
        [0] * 5,
        [0, 1, 1, 0, 2],
        [1, 1, leak, 0, 1 - 3 * leak],
        [1, 1, 2 * leak, 2 * leak, 1 - leak],
        labels=[(), ("g",), ()],
    )


def test_residual_rule_stops_far_from_the_value_but_the_bracket_does_not():
    # the stopping case in miniature: the residual drops below 1e-8 while the
    # values are still 5e-4 short (V_k = (1 - (1 - 3e-5)^k) / 3 from below)
    m = _leaky_loop(1e-5)
    problem = Problem(m, Specification(ReachAvoid("g")))
    fast = solve(problem, ValueIteration(certified=False, strategy_iteration=False))
    assert fast.residual < 1e-8 and fast.converged
    assert 1 / 3 - fast.values[2] > 1e-6  # the uncertified answer is off by far more
    sol = solve(problem)  # default: certified
    assert sol.converged and sol.error < 1e-8
    exact = _slow_leak_exact(1e-5)  # 1/3 + 2.8e-13 with the bounds as written
    assert Fraction(sol.lower[2]) <= exact <= Fraction(sol.upper[2])
    assert sol.values.tolist() == sol.lower.tolist()
    # certified without strategy iteration: the bracket stays honest (wide) when capped
    capped = solve(problem, ValueIteration(max_iterations=2000, strategy_iteration=False))
    assert not capped.converged
    assert Fraction(capped.lower[2]) <= exact <= Fraction(capped.upper[2])


@pytest.mark.parametrize("zero_lower", [True, False])
@pytest.mark.parametrize("sat", ["pessimistic", "optimistic"])
@pytest.mark.parametrize("strategy", ["maximize", "minimize"])
def test_certified_bracket_contains_reference(zero_lower, sat, strategy):
    rng = np.random.default_rng(101 if zero_lower else 102)
    for _ in range(3):
        m = random_imdp(rng, n_states=20, zero_lower=zero_lower)
        tgt, avd = m.states_labelled("goal"), m.states_labelled("bad")
        spec = Specification(ReachAvoid("goal", "bad"), sat, strategy)
        sol = solve(Problem(m, spec))  # default tolerance 1e-8, certified
        ref = ref_reach(
            m, tgt, avd & ~tgt, pessimistic=sat == "pessimistic", maximize=strategy == "maximize"
        )
        assert sol.converged and np.all(sol.upper - sol.lower < 1e-8)
        # the reference iterates from below to a residual of 1e-14: it may sit a little
        # under the exact value
        assert np.all(sol.lower <= ref + 1e-10) and np.all(ref <= sol.upper + 1e-12)
        assert sol.values == pytest.approx(ref, abs=1e-8)


def test_certified_upper_bound_in_an_adversary_trap():
    # state 0: [0, 1] to itself and to the goal: the adversary keeps the run at 0 forever;
    # the greatest fixed point (1) is not the value (0); the bracket must close at 0
    m = IMDP(2, [0, 0, 1], [0, 0, 0], [0, 1, 1], [0, 0, 1], [1, 1, 1], labels=[(), ("g",)])
    sol = solve(Problem(m, Specification(ReachAvoid("g")), None), ValueIteration(precompute=False))
    assert sol.converged and sol.upper[0] < 1e-8 and sol.lower[0] == 0.0


def test_discounted_bracket_contains_reference():
    rng = np.random.default_rng(33)
    m = random_imdp(rng, n_states=15)
    w = rng.normal(size=m.n_states)
    sol = solve(Problem(m, Specification(DiscountedReward(w, 0.8))), ValueIteration(1e-9))
    ref = ref_discounted(m, w, 0.8, pessimistic=True)
    assert sol.converged and sol.error < 1e-9
    assert np.all(sol.lower <= ref + 1e-12) and np.all(ref <= sol.upper + 1e-12)


def test_chain_reach_ignores_float_dust_that_closes_a_class():
    # states 0 <-> 1 keep all their mass between them except for a 1e-17 leak into the
    # target 2: numerically a closed class, whose linear system is singular
    import scipy.sparse as sp

    from planner.imdp.evaluate import chain_reach

    for leak_row in (0, 1):
        m = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
        m[leak_row, 2] = 1e-17
        out = chain_reach(sp.csr_matrix(m), np.array([0, 1]), np.array([0.0, 0.0, 1.0]))
        assert np.isfinite(out).all() and out[0] == out[1] == 0.0
    # a real leak is kept
    m = sp.csr_matrix(np.array([[0.0, 0.5, 0.5], [1.0, 0.0, 0.0]]))
    out = chain_reach(m, np.array([0, 1]), np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(out[:2], 1.0)


@pytest.mark.parametrize("zero_lower", [True, False])
@pytest.mark.parametrize("sat", ["pessimistic", "optimistic"])
def test_min_reach_is_certified_and_keeps_its_zero_states(zero_lower, sat):
    # a minimising controller can hover for ever in end components away from the target:
    # those states are settled at 0 (with the action that stays), so the bound from above
    # closes on the rest instead of staying at 1 there
    rng = np.random.default_rng(31 if zero_lower else 32)
    hovering = 0
    for _ in range(6):
        m = random_imdp(rng, n_states=18, zero_lower=zero_lower)
        tgt, avd = m.states_labelled("goal"), m.states_labelled("bad")
        spec = Specification(ReachAvoid("goal", "bad"), sat, "minimize")
        sol = solve(Problem(m, spec))
        ref = ref_reach(m, tgt, avd & ~tgt, pessimistic=sat == "pessimistic", maximize=False)
        assert sol.converged and sol.error < 1e-8
        assert np.all(sol.lower <= ref + 1e-12) and np.all(ref <= sol.upper + 1e-12)
        # the strategy attains the bracket: with only its actions allowed (one per state
        # where it chose one) the same problem has the same value
        allowed = np.zeros((m.n_states, m.n_actions), dtype=bool)
        has = sol.strategy >= 0
        allowed[np.flatnonzero(has), sol.strategy[has]] = True
        allowed[~has] = m.enabled[~has]
        own = solve(Problem(m, spec, allowed=allowed))
        assert np.all(own.lower <= sol.upper + 1e-9)
        zero = (sol.upper == 0) & ~tgt & ~avd
        hovering += int(zero.sum())
        for s in np.flatnonzero(zero):
            r = m.row_index[s, sol.strategy[s]]
            a, b = m.row_ptr[r], m.row_ptr[r + 1]
            succ, lo, up = m.successor[a:b], m.lower[a:b], m.upper[a:b]
            if sat == "pessimistic":  # every successor the adversary may pick is at 0
                assert np.all(sol.upper[succ[up > 0]] == 0)
            else:  # the cooperating adversary can keep all mass at 0
                inside = sol.upper[succ] == 0
                assert np.all(lo[~inside] == 0) and up[inside].sum() >= 1.0
    assert hovering > 0  # the models have such states


@pytest.mark.parametrize("sat", ["pessimistic", "optimistic"])
def test_min_reach_of_slowly_mixing_chains_is_certified(sat):
    # minimal reachability is solved as the maximal reachability of the value-0 states:
    # its bound from above closes where sweeps from 1 alone crept for ever
    rng = np.random.default_rng(3)
    for _ in range(5):
        m = sticky_imdp(rng, 120)
        spec = Specification(ReachAvoid("goal", "bad"), sat, "minimize")
        sol = solve(Problem(m, spec))
        assert sol.converged and sol.error < 1e-8
        assert np.all(sol.values == sol.lower)
        # the values are the maximising side's complement: the same bracket from above
        tgt, avd = m.states_labelled("goal"), m.states_labelled("bad")
        ref = ref_reach(m, tgt, avd & ~tgt, pessimistic=sat == "pessimistic", maximize=False)
        assert np.all(sol.lower <= ref + 1e-9) and np.all(ref <= sol.upper + 1e-9)


def _counted_solves(monkeypatch) -> list[float]:
    once = solve_module._reach_once
    calls: list[float] = []

    def counted(run):
        calls.append(run.alg.tolerance)
        return once(run)

    monkeypatch.setattr(solve_module, "_reach_once", counted)
    return calls


def test_a_bracket_opened_by_the_rounding_widening_is_solved_again(monkeypatch):
    # at a tolerance of 1e-12 the widening for the rounding of long stays can push a
    # closed bracket over it (this chain: 1.012e-12); the solve then runs to a quarter of
    # the tolerance and reports the sweeps of both runs. The uniform raise tried first
    # would be shown here: it stands in for one that fails (the bound from below)
    m = sticky_imdp(np.random.default_rng(3), 120)
    spec = Specification(ReachAvoid("goal", "bad"), "pessimistic", "minimize")
    monkeypatch.setattr(widening, "uniformly_widened", lambda lower, *args: lower.copy())
    calls = _counted_solves(monkeypatch)
    sol = solve(Problem(m, spec), ValueIteration(1e-12))
    assert sol.converged and sol.error < 1e-12
    assert len(calls) == 2 and calls[1] == pytest.approx(calls[0] / 4)


def test_the_uniform_raise_is_shown_and_the_widening_stops(monkeypatch):
    # the same chain: the uniform raise (a share of the room left to the tolerance) needs
    # no stays and is shown in exact arithmetic at once; the widening's search on the
    # second thread is told to stop, and no second solve runs
    m = sticky_imdp(np.random.default_rng(3), 120)
    spec = Specification(ReachAvoid("goal", "bad"), "pessimistic", "minimize")
    calls = _counted_solves(monkeypatch)
    widen = widening.rounding_widened
    stops = []

    def watched(*args, stop=None, **kw):
        stops.append(stop)
        return widen(*args, stop=stop, **kw)

    monkeypatch.setattr(widening, "rounding_widened", watched)
    sol = solve(Problem(m, spec), ValueIteration(1e-12))
    assert sol.converged and sol.error < 1e-12 and len(calls) == 1
    # the search ran beside the check and was told to stop (whether it had ended by then
    # depends on the threads' timing)
    assert len(stops) == 1 and stops[0] is not None and stops[0]()
    tgt, avd = m.states_labelled("goal"), m.states_labelled("bad")
    ref = ref_reach(m, tgt, avd & ~tgt, pessimistic=True, maximize=False)
    assert np.all(sol.lower <= ref + 1e-9) and np.all(ref <= sol.upper + 1e-9)


def _counted_calls(monkeypatch, module, name: str) -> list[int]:
    """``module.name`` replaced by a wrapper that records each call; the record."""
    calls: list[int] = []
    function = getattr(module, name)

    def counted(*args, **kw):
        calls.append(1)
        return function(*args, **kw)

    monkeypatch.setattr(module, name, counted)
    return calls


def _solved_random(rng: np.random.Generator, count: int) -> list:
    """Pessimistic maximal reach-avoid on ``count`` random 60-state models, each solution
    checked to bracket the reference values."""
    out = []
    for _ in range(count):
        m = random_imdp(rng, 60, 3, 5)
        sol = solve(Problem(m, Specification(ReachAvoid("goal", "bad"))))
        ref = ref_reach(m, m.states_labelled("goal"), m.states_labelled("bad"), True)
        assert np.all(sol.lower <= ref + 1e-9) and np.all(ref <= sol.upper + 1e-9)
        out.append(sol)
    return out


@pytest.mark.parametrize("sat", ["pessimistic", "optimistic"])
def test_an_upper_bound_not_shown_is_the_trivial_one(monkeypatch, sat):
    # where the exact check does not show the bound from above, the iteration's bound
    # (only checked in floating point, which over long stays can leave it below the value)
    # is no bound: the solution reports 1 on the free states, is not converged, and keeps
    # the bound from below and the settled states of the shown solve
    rng = np.random.default_rng(11)
    models = [random_imdp(rng, 60, 3, 5) for _ in range(4)]
    spec = Specification(ReachAvoid("goal", "bad"), sat)
    shown = [solve(Problem(m, spec)) for m in models]
    certified = widening.certified_upper
    refused = []

    def refusing(*args):
        shown, bound = certified(*args)
        refused.append(shown)
        return False, bound

    monkeypatch.setattr(solve_module, "certified_upper", refusing)
    for m, first in zip(models, shown, strict=True):
        count = len(refused)
        sol = solve(Problem(m, spec))
        free = ~sol.fixed
        assert first.converged and len(refused) > count and all(refused[count:])
        assert not sol.converged and free.any() and np.all(sol.upper[free] == 1.0)
        np.testing.assert_array_equal(sol.upper[~free], first.upper[~free])
        np.testing.assert_array_equal(sol.lower, first.lower)


def test_a_large_model_widens_along_the_greedy_rows_unless_they_stay_too_long(monkeypatch):
    # beyond SI_MAX_STATES free states (here: any) the widening first takes the rows
    # greedy for the bound from above: on random models they leave soon, and no search
    # for short stays runs. Where the greedy row creeps (a self-loop that keeps the upper
    # bound, 1e9 steps) its widening would not fit in the room left to the tolerance, and
    # the search finds the row that leaves at once
    monkeypatch.setattr(widening, "SI_MAX_STATES", 0)
    searches = _counted_calls(monkeypatch, widening, "_short_stay_chain")
    assert all(sol.converged for sol in _solved_random(np.random.default_rng(3), 4))
    assert not searches
    eps, d = 1e-9, 1e-11
    # state 0: creep (self-loop 1 - 2 eps, eps to each end: value 1/2) or jump (a hair
    # less than 1/2 to the goal)
    p = [1 - 2 * eps, eps, eps, 0.5 - d, 0.5 + d, 1.0, 1.0]
    m = IMDP(
        3,
        [0, 0, 0, 0, 0, 1, 2],
        [0, 0, 0, 1, 1, 0, 0],
        [0, 1, 2, 1, 2, 1, 2],
        p,
        p,
        labels=[(), ("goal",), ("bad",)],
        propositions=("bad", "goal"),
    )
    sol = solve(Problem(m, Specification(ReachAvoid("goal", "bad"))))
    assert searches and sol.converged and sol.lower[0] <= 0.5 <= sol.upper[0]


@pytest.mark.parametrize("share", ["default", "opening"])
def test_an_open_bracket_is_certified_by_the_uniform_raise_before_any_search(monkeypatch, share):
    # stalled solves end with open brackets: the bound from above raised uniformly by a
    # share of the room that the closed states leave is shown in exact arithmetic at once,
    # keeps them closed, and no search for short stays runs. A raise that would open a
    # closed state (a share so large that it lifts every state to 1, which is shown
    # trivially) is refused, and the search and its check run as before
    interval = importlib.import_module("planner.imdp.interval")
    monkeypatch.setattr(interval, "_II_REPAIRS", 0)
    monkeypatch.setattr(interval, "_II_WINDOW", 4)
    monkeypatch.setattr(solve_module, "GLOBAL_REPAIR_STATES", 0)
    if share == "opening":
        monkeypatch.setattr(widening, "UNIFORM_SHARE", 1e12)
    certified = widening.certified_upper
    seen = []

    def watched(m, free_rows, tol, maximize, adv, lower, upper, closed, sweeper):
        before = len(searches)
        out = certified(m, free_rows, tol, maximize, adv, lower, upper, closed, sweeper)
        st = sweeper.states
        seen.append((closed, lower[st], upper[st], out[0], out[1][st], tol, len(searches) - before))
        return out

    monkeypatch.setattr(solve_module, "certified_upper", watched)
    searches = _counted_calls(monkeypatch, widening, "rounding_widened")
    _solved_random(np.random.default_rng(7), 8)
    opened = [s for s in seen if not s[0]]
    assert opened
    for _, lower, upper, shown, bound, tol, searched in opened:
        closed = upper - lower < tol
        assert shown and closed.any() and np.all(bound >= upper)
        assert np.all(bound[closed] - lower[closed] < tol)
        assert searched == (0 if share == "default" else 1)


@pytest.mark.parametrize("cheap", [True, False])
def test_a_stalled_interval_iteration_is_finished(monkeypatch, cheap):
    # interval iteration stopped at its first stalled window (no repairs): on few free
    # states the sweeps with their certificate attempts close the bracket; above
    # ``GLOBAL_REPAIR_STATES`` the solve ends after at most ``_STALLED_SWEEPS`` sweeps from
    # below, open where the candidate fails, and sound either way
    interval = importlib.import_module("planner.imdp.interval")
    monkeypatch.setattr(interval, "_II_REPAIRS", 0)
    monkeypatch.setattr(interval, "_II_WINDOW", 4)
    if not cheap:
        monkeypatch.setattr(solve_module, "GLOBAL_REPAIR_STATES", 0)
    finish = solve_module._ReachSweeps.finish_stalled
    finished: list[int] = []

    def counted(run):
        start = run.it
        finish(run)
        finished.append(run.it - start)

    monkeypatch.setattr(solve_module._ReachSweeps, "finish_stalled", counted)
    rng = np.random.default_rng(7)
    outcomes = []
    for _ in range(8):
        m = random_imdp(rng, 60, 3, 5)
        count = len(finished)
        sol = solve(Problem(m, Specification(ReachAvoid("goal", "bad"))))
        ref = ref_reach(m, m.states_labelled("goal"), m.states_labelled("bad"), True)
        assert np.all(sol.lower <= ref + 1e-9) and np.all(ref <= sol.upper + 1e-9)
        if len(finished) > count:
            outcomes.append(sol.converged)
    assert outcomes
    if cheap:
        assert all(outcomes)
    else:
        assert max(finished) <= solve_module._STALLED_SWEEPS and not any(outcomes)


def test_the_stalled_finish_certifies_its_bound_beside_the_sweeps(monkeypatch):
    # above GLOBAL_REPAIR_STATES the bound from above that interval iteration gave up with
    # is certified on a second thread while the sweeps settle the bound from below: the
    # solutions are those of running the two in turn, and that certificate is the one
    # reported unless the candidate lowered the bound meanwhile
    interval = importlib.import_module("planner.imdp.interval")
    monkeypatch.setattr(interval, "_II_REPAIRS", 0)
    monkeypatch.setattr(interval, "_II_WINDOW", 4)
    monkeypatch.setattr(solve_module, "GLOBAL_REPAIR_STATES", 0)
    rng = np.random.default_rng(7)
    problems = [
        Problem(random_imdp(rng, 60, 3, 5), Specification(ReachAvoid("goal", "bad")))
        for _ in range(8)
    ]
    certificate = solve_module._certificate
    calls: list[list[str]] = []

    def counted(*args):
        calls[-1].append(threading.current_thread().name)
        return certificate(*args)

    monkeypatch.setattr(solve_module, "_certificate", counted)

    def solved():
        out = []
        for problem in problems:
            calls.append([])
            out.append(solve(problem))
        return out

    at_once, where = solved(), calls[:]
    # a stalled solve: certified on the worker only (the first finish's bound kept)
    assert ["hopnav-upper_0"] in where
    monkeypatch.setattr(solve_module, "concurrently", lambda back, fore, _: (back(), fore()))
    calls.clear()
    in_turn = solved()
    assert [len(c) for c in where] == [len(c) for c in calls]
    for a, b in zip(at_once, in_turn, strict=True):
        assert np.array_equal(a.lower, b.lower) and np.array_equal(a.upper, b.upper)
        assert a.converged == b.converged


@pytest.mark.parametrize("zero_lower", [True, False])
def test_sweeps_in_halves_reach_the_reference_values_and_repeat_exactly(zero_lower, monkeypatch):
    # full sweeps (and the light sweeps of plain value iteration) in two halves on two
    # threads (large models) forced on small ones: every bracket holds the reference,
    # certified ones within the tolerance, and a second solve gives the same bits whatever
    # the threads' timing
    from planner.imdp.kernels import sweeps

    monkeypatch.setattr(sweeps, "HALVES_SWEEP_ENTRIES", 1)
    rng = np.random.default_rng(41 if zero_lower else 42)
    for _ in range(3):
        m = random_imdp(rng, n_states=30, zero_lower=zero_lower)
        tgt, avd = m.states_labelled("goal"), m.states_labelled("bad")
        for sat in ("pessimistic", "optimistic"):
            for strategy in ("maximize", "minimize"):
                got = reach(m, "goal", "bad", sat=sat, strategy=strategy)
                again = reach(m, "goal", "bad", sat=sat, strategy=strategy)
                ref = ref_reach(
                    m, tgt, avd & ~tgt, sat == "pessimistic", maximize=strategy == "maximize"
                )
                assert (got.lower <= ref + 1e-9).all() and (ref <= got.upper + 1e-9).all()
                if got.converged:
                    assert got.values == pytest.approx(ref, abs=1e-8)
                np.testing.assert_array_equal(got.lower, again.lower)
                np.testing.assert_array_equal(got.upper, again.upper)
                np.testing.assert_array_equal(got.strategy, again.strategy)
        # uncertified: plain sweeps, whose light sweeps run in halves too; still lower
        # bounds, at the fixed point (a residual of 1e-13 on these fast-mixing models)
        spec = Specification(ReachAvoid("goal", "bad"))
        fast = ValueIteration(1e-13, certified=False)
        got, again = (solve(Problem(m, spec), fast) for _ in range(2))
        ref = ref_reach(m, tgt, avd & ~tgt, True)
        assert (got.values <= ref + 1e-12).all()
        assert got.values == pytest.approx(ref, abs=1e-9)
        np.testing.assert_array_equal(got.values, again.values)


class _HeldFuture(Future):
    """A future whose work runs only when :meth:`run` is called, or when its result is
    asked for (the searches of a guessed layout ending whenever a test decides)."""

    def __init__(self, fn, at_once: bool) -> None:
        super().__init__()
        self._fn = fn
        if at_once:
            self.run()

    def run(self) -> None:
        if not self.done():
            self.set_result(self._fn())

    def result(self, timeout=None):
        self.run()
        return super().result(timeout)


@pytest.mark.parametrize("ends", ["at once", "after 1 sweep", "after 3 sweeps", "at the end"])
def test_the_searches_may_end_at_any_sweep_of_a_guessed_layout(ends, monkeypatch):
    """Whenever the graph searches beside a guessed layout end (before the first sweep,
    between sweeps, or only when the solve asks for them), the solve equals the one that
    searched first: the sweeps are abandoned and started again where the guess was wrong,
    and kept where it was right."""
    solve_mod = importlib.import_module("planner.imdp.solve")
    guess_mod = importlib.import_module("planner.imdp.guess")
    sweeper_cls = importlib.import_module("planner.imdp.kernels.sweeps").ReachSweeper
    sweep = sweeper_cls.sweep
    held: list[_HeldFuture] = []

    class Held:
        def submit(self, fn):
            held.append(_HeldFuture(fn, ends == "at once"))
            return held[-1]

    after = {"after 1 sweep": 1, "after 3 sweeps": 3}.get(ends)
    count = [0]

    def counted_sweep(self, *args, **kwargs):
        count[0] += 1
        if after is not None and count[0] > after and held:
            held[-1].run()
        return sweep(self, *args, **kwargs)

    rng = np.random.default_rng(12)
    outcomes, abandoned = set(), set()
    for trial in range(10):
        m = random_imdp(rng, n_states=40, n_actions=3, max_succ=4, zero_lower=True)
        target, avoid = m.states_labelled("goal"), m.states_labelled("bad")
        problem = Problem(m, Specification(ReachAvoid(target, avoid)))
        alg = ValueIteration(certified=trial % 2 == 0)
        monkeypatch.setattr(solve_mod, "GUESS_ENTRIES", 10**12)
        want = solve(problem, alg)
        monkeypatch.setattr(solve_mod, "GUESS_ENTRIES", 0)
        monkeypatch.setattr(guess_mod, "worker", lambda purpose: Held())
        monkeypatch.setattr(sweeper_cls, "sweep", counted_sweep)
        restarts = []
        run = solve_mod._solve

        def recorded(*a, restarts=restarts, run=run):
            restarts.append((len(a) > 3, count[0]))
            return run(*a)

        monkeypatch.setattr(solve_mod, "_solve", recorded)
        count[0] = 0
        held.clear()
        got = solve(problem, alg)
        monkeypatch.undo()
        for field in ("values", "strategy", "lower", "upper", "fixed"):
            np.testing.assert_array_equal(getattr(got, field), getattr(want, field))
        assert got.iterations == want.iterations
        assert len(held) == 1 and held[0].done()
        assert [again for again, _ in restarts] in ([False], [False, True])
        failed = len(restarts) == 2
        outcomes.add(failed)
        if failed and ends == "at once":
            assert restarts[1][1] == 0  # abandoned before the first sweep
        elif failed and after is not None:
            # at the first sweep after the searches ended (or at the end, if sooner)
            assert restarts[1][1] <= after + 1
            abandoned.add(restarts[1][1] == after + 1)
    assert outcomes == {False, True}
    assert after is None or True in abandoned


@pytest.mark.parametrize("certified", [False, True])
def test_the_layout_built_beside_the_probability_1_search_changes_nothing(certified, monkeypatch):
    """The sweeps' layout built on a second thread while the graph searches run (as if
    every state that can reach the target at all did so with positive probability against
    every adversary and none outside the target almost surely) gives the solve of a layout
    built after them, where the guess comes true and where it does not."""
    solve_mod = importlib.import_module("planner.imdp.solve")
    layout = solve_module.sweep_layout
    rng = np.random.default_rng(11)
    outcomes = set()
    for _ in range(12):
        m = random_imdp(rng, n_states=40, n_actions=3, max_succ=4, zero_lower=True)
        target, avoid = m.states_labelled("goal"), m.states_labelled("bad")
        problem = Problem(m, Specification(ReachAvoid(target, avoid)))
        alg = ValueIteration(certified=certified)
        monkeypatch.setattr(solve_mod, "GUESS_ENTRIES", 10**12)
        want = solve(problem, alg)
        monkeypatch.setattr(solve_mod, "GUESS_ENTRIES", 0)
        built: list[int] = []

        def counted(*args, built=built):
            built.append(1)
            return layout(*args)

        monkeypatch.setattr(solve_module, "sweep_layout", counted)
        got = solve(problem, alg)
        monkeypatch.setattr(solve_module, "sweep_layout", layout)
        for field in ("values", "strategy", "lower", "upper", "fixed"):
            np.testing.assert_array_equal(getattr(got, field), getattr(want, field))
        assert got.iterations == want.iterations
        rows = np.ones(m.n_rows, dtype=bool)
        possible = graph.possible_reach(m, target, avoid, rows) & ~target & ~avoid
        wrong = bool((want.fixed & (want.values == 1.0) & ~target).any()) or bool(
            (possible & want.fixed & (want.values == 0.0)).any()
        )
        # built anew after the search only where the guess was wrong
        assert len(built) == wrong
        outcomes.add(wrong)
    assert outcomes == {False, True}


@pytest.mark.parametrize("seed", range(3))
def test_plain_sweeps_evaluate_every_row_once_the_light_sweeps_have_settled(seed, monkeypatch):
    # plain sweeps (uncertified, no strategy iteration): every row at the first sweep,
    # then once the light sweeps since the last full one brought the change below
    # LIGHT_FALL of that full sweep's, or after FULL_EVERY_MOST sweeps, or after a sweep
    # below the tolerance (the stopping rule's full sweep); never otherwise
    from planner.imdp.kernels import sweeps

    log = []
    plain_sweep = sweeps.ReachSweeper.sweep

    def sweep(self, v, full=True, bound=None, split=False):
        residual = plain_sweep(self, v, full, bound, split)
        log.append((full, residual))
        return residual

    monkeypatch.setattr(sweeps.ReachSweeper, "sweep", sweep)
    rng = np.random.default_rng(900 + seed)
    m = sticky_imdp(rng, 80) if seed == 2 else random_imdp(rng, n_states=60, zero_lower=seed == 1)
    tgt, avd = m.states_labelled("goal"), m.states_labelled("bad")
    alg = ValueIteration(1e-12, certified=False, strategy_iteration=False)
    got = solve(Problem(m, Specification(ReachAvoid(tgt, avd))), alg)
    assert got.converged and len(log) == got.iterations
    np.testing.assert_allclose(got.values, ref_reach(m, tgt, avd & ~tgt, True), atol=1e-8)
    assert log[0][0]
    last_full, fell = 0, 0
    for i in range(1, len(log)):
        full, (_, before) = log[i][0], log[i - 1]
        since = i - last_full
        by_fall = since > 1 and before < interval.LIGHT_FALL * log[last_full][1]
        due = since >= interval.FULL_EVERY_MOST or by_fall or before < alg.tolerance
        assert full == due, (i, log[max(0, i - 4) : i + 1])
        if full:
            fell += by_fall and since < interval.FULL_EVERY_MOST
            last_full = i
    assert sum(f for f, _ in log) >= 2
    if seed < 2:
        assert fell > 0  # the light sweeps settled before the longest gap
