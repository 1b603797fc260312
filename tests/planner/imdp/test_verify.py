"""The exact superharmonicity check (planner.imdp.kernels.verify, certify.verify_upper)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from planner.imdp.kernels.verify import row_excess


def _exact_excess(succ, lo, up, u, us, minimizes):
    """``T_r(U) - U(s)`` in rational arithmetic: the adversary's greedy vertex."""
    order = sorted(range(len(succ)), key=lambda i: u[succ[i]], reverse=not minimizes)
    p = [Fraction(x) for x in lo]
    rem = 1 - sum(p)
    for i in order:
        give = min(Fraction(up[i]) - Fraction(lo[i]), rem)
        p[i] += give
        rem -= give
    assert rem == 0
    return sum(p[i] * Fraction(u[succ[i]]) for i in range(len(succ))) - Fraction(us)


def _dyadic_row(rng, k, n):
    """``k`` successors among ``n`` states, bounds multiples of 2^-40 around a
    distribution that sums to exactly 1."""
    q = 2**40
    w = rng.dirichlet(np.ones(k))
    c = np.floor(w * q).astype(np.int64)
    c[0] += q - c.sum()
    lo = np.floor(c * rng.uniform(0.0, 1.0, k)).astype(np.int64)
    lo[rng.random(k) < 0.3] = 0
    up = np.minimum(q, c + np.floor(rng.uniform(0.0, 0.3, k) * q).astype(np.int64))
    succ = rng.choice(n, size=k, replace=False)
    return succ, lo / q, up / q


@pytest.mark.parametrize("seed", range(6))
def test_row_excess_bounds_the_exact_excess_from_both_sides(seed):
    # values spread, nearly equal (differences of an ulp) and equal: the bound is never
    # below the rational excess and above it by at most a few ulps of the differences;
    # with ``below`` the same from underneath
    rng = np.random.default_rng(seed)
    n = 12
    idx, keys, work = np.empty(n, dtype=np.int64), np.empty(2 * n), np.empty(2 * n + 8)
    checked = 0
    for trial in range(300):
        kind = trial % 3
        if kind == 0:
            u = rng.uniform(0.0, 1.0, n)
        elif kind == 1:
            u = 0.9 + rng.integers(-3, 4, n) * np.finfo(float).eps
        else:
            u = np.full(n, 0.75)
        k = int(rng.integers(1, 8))
        succ, lo, up = _dyadic_row(rng, k, n)
        s = int(rng.integers(n))
        for minimizes in (True, False):
            got = row_excess(0, k, succ, lo, up, u, u[s], minimizes, idx, keys, work)
            exact = _exact_excess(succ, lo, up, u, u[s], minimizes)
            assert Fraction(got) >= exact
            assert got - float(exact) <= 1e-14 * max(1.0, float(np.ptp(u)))
            low = row_excess(0, k, succ, lo, up, u, u[s], minimizes, idx, keys, work, True)
            assert Fraction(low) <= exact
            assert float(exact) - low <= 1e-14 * max(1.0, float(np.ptp(u)))
            checked += 1
            if kind == 2 and s in succ:
                assert got == 0.0  # equal values: exact, nothing added
    assert checked == 600


def test_a_self_loop_adds_no_rounding_to_the_excess():
    # a state keeps 1 - 2**-40 on itself, sends 2**-44 to the goal and 15 * 2**-44 to the
    # sink; at its value 1/16 the excess is exactly 0. Pivoted on the critical successor
    # (the sink) the kept mass's term alone is 1/16 and its rounding ~1e-16; pivoted on the
    # state itself it is exactly 0 and the bounds are as tight as the exits
    succ = np.array([0, 1, 2])
    lo = np.array([1 - 2.0**-40, 2.0**-44, 15 * 2.0**-44])
    u = np.array([1 / 16, 1.0, 0.0])
    idx, keys, work = np.empty(3, dtype=np.int64), np.empty(6), np.empty(14)
    for minimizes in (True, False):
        hi = row_excess(0, 3, succ, lo, lo, u, u[0], minimizes, idx, keys, work)
        low = row_excess(0, 3, succ, lo, lo, u, u[0], minimizes, idx, keys, work, True)
        assert low <= 0.0 <= hi and hi - low < 1e-26


def test_row_excess_refuses_a_vertex_it_cannot_show_feasible():
    # the bounds bracket 1 only within 1e-12 (not tightened as the model's constructor
    # would): the minimising adversary has no feasible vertex to show
    succ = np.array([0, 1])
    lo = np.array([0.5, 0.5 - 1e-12])
    up = lo.copy()
    u = np.array([0.25, 0.75])
    idx, keys, work = np.empty(2, dtype=np.int64), np.empty(4), np.empty(12)
    assert row_excess(0, 2, succ, lo, up, u, 0.6, True, idx, keys, work) == np.inf
    # the maximising adversary's bound needs no vertex (weak duality)
    assert row_excess(0, 2, succ, lo, up, u, 0.6, False, idx, keys, work) < np.inf


def test_a_slow_exit_is_not_certified_away():
    # state 0: action 0 keeps 1 - 2^-47 and leaves with 7 * 2^-50 to the goal, 2^-50 to
    # the trap (minimal probability 7/8); action 1 reaches the goal surely. Solved as the
    # dual (maximal reachability of the trap), the checks' rounding allowance hid the
    # trap's 2^-50 per step, and the widening's short-stay stand-in (action 1) hid the
    # stay: [0.9999999975, 0.99999999999994] was certified. A bracket counts only once its
    # bound from above is shown superharmonic in exact arithmetic.
    from planner.imdp import Problem, ReachAvoid, Specification, solve

    m, goal, trap = _slow_exit_model()
    spec = Specification(ReachAvoid("goal", "bad"), "pessimistic", "minimize")
    sol = solve(Problem(m, spec))
    exact = Fraction(goal) / (Fraction(goal) + Fraction(trap))
    assert Fraction(sol.lower[0]) <= exact <= Fraction(sol.upper[0])
    assert not sol.converged


@pytest.mark.parametrize("sat", ["pessimistic", "optimistic"])
def test_a_slow_exit_keeps_the_trivial_bound_from_above(sat):
    # the same model solved as the maximal reachability of the trap (1/8, by action 0 for
    # ever): the iteration's bound from above, checked in floating point only, was
    # 2.5e-9 (5.0e-9 optimistic) and was reported although the exact check refused it.
    # A bound not shown is 1
    from planner.imdp import Problem, ReachAvoid, Specification, solve

    m, goal, trap = _slow_exit_model()
    sol = solve(Problem(m, Specification(ReachAvoid("bad", "goal"), sat, "maximize")))
    exact = Fraction(trap) / (Fraction(goal) + Fraction(trap))
    assert Fraction(sol.lower[0]) <= exact <= Fraction(sol.upper[0])
    assert not sol.converged and sol.upper[0] == 1.0


def _slow_exit_model():
    """The model of the slow-exit tests, with its per-step masses to the goal and the trap."""
    from planner.imdp import IMDP

    q = 2.0**-50
    goal, trap = 7 * q, q
    s, act = [0, 0, 0, 0, 0, 1, 2], [0, 0, 0, 1, 1, 0, 0]
    t, p = [0, 1, 2, 0, 1, 1, 2], [1 - goal - trap, goal, trap, 0.75, 0.25, 1.0, 1.0]
    m = IMDP(3, s, act, t, p, p, labels=[(), ("goal",), ("bad",)], propositions=("bad", "goal"))
    return m, goal, trap


def test_verify_upper_shows_a_certified_bound_and_refuses_a_low_one():
    from planner.imdp import Problem, ReachAvoid, Specification, solve
    from planner.imdp.certify import verify_upper

    from .reference import random_imdp

    m = random_imdp(np.random.default_rng(3), n_states=15, zero_lower=True)
    sol = solve(Problem(m, Specification(ReachAvoid("goal", "bad"))))
    assert sol.converged
    free_rows = np.flatnonzero(~sol.fixed[m.row_state])
    shown, u = verify_upper(m, free_rows, sol.upper, True, True)
    assert shown and np.all(u >= sol.upper) and np.max(u - sol.upper) < 1e-12
    low = sol.upper.copy()
    free = ~sol.fixed
    low[free] = np.maximum(0.0, sol.lower[free] - 1e-3)
    assert (sol.lower[free] > 1e-3).any()
    shown, _ = verify_upper(m, free_rows, low, True, True, passes=2)
    assert not shown


@pytest.mark.parametrize("sides", [(True, True), (True, False), (False, True), (False, False)])
def test_checks_made_ahead_on_two_threads_give_the_same_check(monkeypatch, sides):
    # above HALVES_ENTRIES the first pass's checks are made ahead on two threads from U as
    # it is, and the pass re-checks only the states whose successors it raised before
    # them: the same raises, passes and verdicts as checking every state in the pass
    from planner.imdp import Problem, ReachAvoid, Specification, certify, solve

    from .reference import random_imdp

    maximize, adversary_minimizes = sides
    sat = "pessimistic" if maximize == adversary_minimizes else "optimistic"
    spec = Specification(ReachAvoid("goal", "bad"), sat, "maximize" if maximize else "minimize")
    rng = np.random.default_rng(11)
    cases = []
    for _ in range(8):
        m = random_imdp(rng, n_states=40, n_actions=3, max_succ=6, zero_lower=True)
        sol = solve(Problem(m, spec))
        free = ~sol.fixed
        free_rows = np.flatnonzero(free[m.row_state])
        # a certified bound lowered a little (raised back: shown), and a random one
        low = sol.upper.copy()
        low[free] = np.maximum(0.0, low[free] - 1e-13)
        rand = sol.upper.copy()
        rand[free] = rng.uniform(0.0, 1.0, int(free.sum()))
        cases += [(m, free_rows, low), (m, free_rows, rand)]
    pass_counts: dict[int, list[int]] = {0: [], 1: []}
    raise_pass = certify.raise_pass

    def counted(*args):
        bad = raise_pass(*args)
        pass_counts[int(certify.HALVES_ENTRIES == 0)].append(bad)
        return bad

    monkeypatch.setattr(certify, "raise_pass", counted)
    results = {}
    for ahead in (0, 1):
        monkeypatch.setattr(certify, "HALVES_ENTRIES", 0 if ahead else 10**12)
        results[ahead] = [certify.verify_upper(m, rows, u, *sides) for m, rows, u in cases]
    assert pass_counts[0] == pass_counts[1] and max(pass_counts[0]) > 0
    for (shown_a, u_a), (shown_b, u_b) in zip(results[0], results[1], strict=True):
        assert shown_a == shown_b and np.array_equal(u_a, u_b)
    assert any(shown for shown, _ in results[0]) and not all(shown for shown, _ in results[0])
    # the warm-up's way of asking for it
    ahead = certify.verify_upper(*cases[0], *sides, halves_entries=0)[1]
    assert np.array_equal(results[1][0][1], ahead)


def _exact_chain_values(n, s, t, p, target):
    """Reachability of ``target`` in a Markov chain with rational (dyadic) probabilities
    over the states ``0..n-1``."""
    from .reference import solve_rational

    a = [[Fraction(int(i == j)) for j in range(n)] + [Fraction(0)] for i in range(n)]
    for x, y, q in zip(s, t, p, strict=True):
        if x < n:
            if y == target:
                a[x][n] += Fraction(q)
            elif y < n:
                a[x][y] -= Fraction(q)
    return solve_rational(a)


def test_lower_bounds_are_rounded_downwards():
    # a chain with exits of 5e-15 .. 8e-12 per step and probabilities that are multiples of
    # 2^-50 (exact values rational): with round-to-nearest sweeps the certified lower bound
    # of state 0 sat one ulp (1.6e-27 at 1.27e-11) above its exact value
    from planner.imdp import IMDP, Problem, ReachAvoid, Specification, solve

    s = [0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 2, 2, 3, 3, 3, 3, 3, 4, 5]
    t = [0, 1, 3, 4, 5, 0, 1, 2, 4, 5, 2, 5, 0, 1, 2, 4, 5, 4, 5]
    p = [
        0.020158841072023925, 0.006143072676962902, 0.9736980862466265, 4.381384144380718e-12,
        5.329070518200751e-15, 0.07506169968100451, 0.2943476644109264, 0.6305906359080371,
        5.329070518200751e-15, 2.6645352591003757e-14, 0.9999999999999574,
        4.263256414560601e-14, 0.02888897984132832, 0.2889102886097481, 0.6822007315411032,
        7.546852032191964e-12, 2.7355895326763857e-13, 1.0, 1.0,
    ]  # fmt: skip
    labels = [()] * 4 + [("goal",), ("bad",)]
    m = IMDP(6, s, [0] * len(s), t, p, p, labels=labels, propositions=("bad", "goal"))
    exact = _exact_chain_values(4, s, t, p, 4)
    sol = solve(Problem(m, Specification(ReachAvoid("goal", "bad"))))
    for x in range(4):
        assert Fraction(sol.lower[x]) <= exact[x] <= Fraction(sol.upper[x])


@pytest.mark.parametrize("seed", range(6))
def test_a_row_shown_clear_in_one_pass_is_clear_exactly(seed):
    # the one-pass filter before the exact excess: where it answers, its bound is at most
    # 0 and at least the rational excess; values spread, clustered near 1 and nearly equal
    from planner.imdp.kernels.verify import clear_excess

    rng = np.random.default_rng(seed)
    n = 12
    answered = far = far_answered = 0
    for trial in range(400):
        kind = trial % 4
        if kind == 0:
            u = rng.uniform(0.0, 1.0, n)
        elif kind == 1:
            u = 1.0 - rng.uniform(0.0, 1e-9, n)
        elif kind == 2:
            u = 0.9 + rng.integers(-3, 4, n) * np.finfo(float).eps
        else:
            u = rng.choice([0.2, 0.5, 0.8], n)
        k = int(rng.integers(1, 10))
        succ, lo, up = _dyadic_row(rng, k, n)
        s = int(rng.integers(n))
        for minimizes in (True, False):
            got = clear_excess(0, k, succ, lo, up, u, u[s], minimizes)
            exact = _exact_excess(succ, lo, up, u, u[s], minimizes)
            if np.isfinite(got):
                answered += 1
                assert got <= 0.0
                assert Fraction(got) >= exact
            else:
                assert got == np.inf
            if exact < -0.05:
                far += 1
                far_answered += int(np.isfinite(got))
    # most rows well below their state are decided here (the pass's savings)
    assert answered > 250 and far > 100 and far_answered > 0.85 * far


def test_a_row_far_below_its_state_is_shown_clear_and_one_at_it_is_left_to_the_exact_check():
    from planner.imdp.kernels.verify import clear_excess

    succ = np.array([0, 1, 2])
    lo = np.array([0.25, 0.25, 0.25])
    up = np.array([0.5, 0.5, 0.5])
    u = np.array([0.1, 0.2, 0.3, 0.6])
    for minimizes in (True, False):
        got = clear_excess(0, 3, succ, lo, up, u, u[3], minimizes)
        assert np.isfinite(got) and got <= -0.3 + 1e-9
        # U(s) at the row's value: the exact check decides
        at = _exact_excess(succ, lo, up, u, 0.0, minimizes)
        assert clear_excess(0, 3, succ, lo, up, u, float(at), minimizes) == np.inf


@pytest.mark.parametrize("sides", [(True, True), (True, False), (False, True), (False, False)])
def test_the_filtered_check_flags_the_same_states_by_the_same_excess(sides):
    # per state, the excess of the pass (the filter first) against the exact excess of
    # every row: a positive excess is the same number, and no violation goes unflagged
    from planner.imdp import Problem, ReachAvoid, Specification, solve
    from planner.imdp.kernels.verify import row_excess, state_excesses
    from planner.imdp.model import first_of_runs

    from .reference import random_imdp

    maximize, adversary_minimizes = sides
    sat = "pessimistic" if maximize == adversary_minimizes else "optimistic"
    spec = Specification(ReachAvoid("goal", "bad"), sat, "maximize" if maximize else "minimize")
    rng = np.random.default_rng(5)
    flagged = clear = 0
    for _ in range(6):
        m = random_imdp(rng, n_states=40, n_actions=3, max_succ=6, zero_lower=True)
        sol = solve(Problem(m, spec))
        free = ~sol.fixed
        rows = np.flatnonzero(free[m.row_state])
        rs = m.row_state[rows]
        seg = first_of_runs(rs)
        state_rows = np.append(seg, rows.size).astype(np.int64)
        n_long = int(np.max(np.diff(m.row_ptr)))
        idx, keys, work = np.empty(n_long, np.int64), np.empty(2 * n_long), np.empty(2 * n_long + 8)
        for u in (sol.upper, np.where(free, sol.upper - 1e-13, sol.upper), rng.random(m.n_states)):
            u = np.where(free, np.minimum(u, 1.0), sol.upper)
            got = np.empty(seg.size)
            args = (rs[seg], state_rows, rows, m.row_ptr, m.successor, m.lower, m.upper, u)
            state_excesses(0, seg.size, *args, maximize, adversary_minimizes, got)
            for k, s in enumerate(rs[seg]):
                if u[s] >= 1.0:
                    continue
                ex = [
                    row_excess(
                        m.row_ptr[r],
                        m.row_ptr[r + 1],
                        m.successor,
                        m.lower,
                        m.upper,
                        u,
                        u[s],
                        adversary_minimizes,
                        idx,
                        keys,
                        work,
                    )
                    for r in rows[state_rows[k] : state_rows[k + 1]]
                ]
                want = max(ex) if maximize else min(ex)
                if want > 0.0:
                    flagged += 1
                    assert got[k] == want
                else:
                    clear += 1
                    assert got[k] <= 0.0
    assert flagged > 20 and clear > 20
