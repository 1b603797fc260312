"""Worst-case satisfaction of Rabin objectives: minimal cases, and the game value against
brute-force references on tiny random models (tests/planner/imdp/rabin_reference.py)."""

import importlib

import numpy as np
import pytest

from planner.imdp import IMDP, graph
from planner.imdp.analysis import accepting_states, satisfaction
from planner.imdp.grid import GridWorld
from planner.imdp.product import ProductIMDP
from planner.imdp.solve import solve
from planner.ltl.translate import translate
from tests.planner.imdp import rabin_reference as ref
from tests.planner.imdp.helpers import corridor_intervals, until_automaton

rabin = importlib.import_module("planner.imdp.rabin")


def value(model: IMDP, formula: str) -> float:
    aut = translate(formula, [p for p in model.propositions if p in formula])
    prod = ProductIMDP(model, aut)
    sol = satisfaction(prod)
    assert sol.converged and sol.error < 1e-8
    return float(sol.values[prod.initial])


def test_safety_with_no_bad_state_is_one():
    # 0 -> {0, 1} and 1 -> {1, 2} with [0, 1] each: the adversary can hold the run in 0 or
    # 1 for ever, outside every robustly accepting end component; no state is labelled c
    m = IMDP(
        3,
        [0, 0, 1, 1, 2],
        [0] * 5,
        [0, 1, 1, 2, 2],
        [0, 0, 0, 0, 1],
        [1, 1, 1, 1, 1],
        labels=[(), ("a",), ()],
        propositions=("a", "c"),
    )
    assert value(m, "G !c") == 1.0


def test_disjunction_of_recurrence_and_persistence_on_two_states():
    # a <-> b with [0, 1] each way: every run visits a infinitely often or ends in b
    m = IMDP(2, [0, 0, 1, 1], [0] * 4, [0, 1, 0, 1], [0.0] * 4, [1.0] * 4, labels=[("a",), ("b",)])
    assert value(m, "(G F a) | (F G b)") == 1.0
    # either disjunct alone: the adversary defeats it (stays in b, resp. keeps going to a)
    assert value(m, "G F a") == 0.0
    assert value(m, "F G b") == 0.0


def test_staying_outside_the_winning_region_counts():
    # c: [0, 1] to itself and to d; d: to w (safe sink) [.5, 1], to x (bad sink) [0, .5].
    # Staying at c for ever satisfies G !x; the adversary must leave to d: value 1/2
    # (the reachability of the almost-sure region {w} alone would give 0)
    m = IMDP(
        4,
        [0, 0, 1, 1, 2, 3],
        [0] * 6,
        [0, 1, 2, 3, 2, 3],
        [0, 0, 0.5, 0, 1, 1],
        [1, 1, 1, 0.5, 1, 1],
        labels=[(), (), (), ("x",)],
    )
    assert value(m, "G !x") == pytest.approx(0.5, abs=1e-8)


def test_until_formula_unchanged_on_a_corridor():
    g = GridWorld(5, 1, labels=[(), ("Haz",), (), (), ("Goal",)])
    prod = ProductIMDP(g.imdp_from_intervals(*corridor_intervals(g, 0.2)), until_automaton())
    sol = satisfaction(prod)
    acc = accepting_states(prod)
    from planner.imdp import Problem, ReachAvoid, Specification, solve

    old = solve(Problem(prod.model, Specification(ReachAvoid(acc))))
    assert sol.values == pytest.approx(old.values, abs=1e-9)


def test_dynamic_adversary_below_static_resolutions():
    # the controller chooses A or B, then s lands in x or y ([0, 1] each); the formula
    # wants F x after A and F y after B. A static resolution of s (one distribution for
    # ever) lets the controller pick the right branch (value 1 at the vertices); the
    # dynamic adversary, which sees the branch, defeats both: value 0.
    # states: 0 start, 1 A, 2 B, 3 s, 4 x, 5 y
    s = [0, 0, 1, 2, 3, 3, 4, 5]
    a = [0, 1, 0, 0, 0, 0, 0, 0]
    t = [1, 2, 3, 3, 4, 5, 4, 5]
    lo = [1, 1, 1, 1, 0, 0, 1, 1]
    up = [1, 1, 1, 1, 1, 1, 1, 1]
    m = IMDP(6, s, a, t, lo, up, labels=[(), ("a",), ("b",), (), ("x",), ("y",)])
    formula = "(F a & F x) | (F b & F y)"
    aut = translate(formula, ["a", "b", "x", "y"])
    assert value(m, formula) == pytest.approx(0.0, abs=1e-9)
    assert ref.static_value(m, aut) == pytest.approx(1.0, abs=1e-9)
    assert ref.game_value(ref.Product(m, aut))[0] == pytest.approx(0.0, abs=1e-9)


def tiny_imdp(rng: np.random.Generator, n: int = 2, zero_lower: float = 0.3) -> IMDP:
    """``n`` transient states (1-2 actions, 2-3 successors, sometimes a ``[0, u]``
    self-loop the adversary can hold) and two absorbing sinks, labelled ``a`` and ``b``;
    the transient states carry random labels."""
    s, a, t, lo, up = [], [], [], [], []
    total = n + 2
    for q in range(n):
        for act in range(int(rng.integers(1, 3))):
            k = int(rng.integers(2, 4))
            succ = rng.choice(total, size=k, replace=False)
            p = rng.dirichlet(np.ones(k))
            lower = p * rng.uniform(0.5, 1.0, size=k)
            lower[rng.random(k) < zero_lower] = 0.0
            upper = np.minimum(1.0, p + rng.uniform(0.0, 0.3, size=k))
            if q not in succ and rng.random() < 0.5:
                succ = np.append(succ, q)
                lower = np.append(lower, 0.0)
                upper = np.append(upper, rng.uniform(0.3, 1.0))
            s += [q] * succ.size
            a += [act] * succ.size
            t += succ.tolist()
            lo += lower.tolist()
            up += upper.tolist()
    for q in (n, n + 1):
        s.append(q)
        a.append(0)
        t.append(q)
        lo.append(1.0)
        up.append(1.0)
    labels = [tuple(x for x in ("a", "b") if rng.random() < 0.4) for _ in range(n)]
    labels += [("a",), ("b",)]
    return IMDP(total, s, a, t, lo, up, labels=labels, propositions=("a", "b"))


FORMULAS = [
    "G (a -> X b)",
    "G F a",
    "F G b",
    "(G F a) -> (G F b)",
    "(G F a) | (F G b)",
    "!a U b",
    "F a & F b",
    "G (a -> X (!a U b))",
    "G !a",
]


def _checked(rng, formula, n_models, n=2, max_states=9):
    aut = translate(formula, ["a", "b"])
    out = []
    while len(out) < n_models:
        m = tiny_imdp(rng, n=n)
        prod_ref = ref.Product(m, aut)
        if len(prod_ref.states) <= max_states:
            out.append((m, aut, prod_ref))
    return out


@pytest.mark.parametrize("formula", FORMULAS)
def test_game_value_matches_brute_force(formula):
    # the exact game value is the best memoryless strategy's worst case (each evaluated
    # by the adversary's Streett MDP on the vertices), at every reachable product state
    rng = np.random.default_rng(sum(map(ord, formula)))
    for m, aut, prod_ref in _checked(rng, formula, 4):
        _, _, per_state = ref.game_value(prod_ref)
        prod = ProductIMDP(m, aut)
        sol = satisfaction(prod)
        assert sol.converged
        idx = [prod.state_index(s, q) for s, q in prod_ref.states]
        assert sol.values[idx] == pytest.approx(per_state, abs=1e-7)
        assert np.all(sol.upper[idx] >= per_state - 1e-9)
        # the static reference (the issue's) bounds it from above
        assert float(sol.values[prod.initial]) <= ref.static_value(m, aut) + 1e-7


@pytest.mark.parametrize("formula", ["G (a -> X b)", "G F a", "(G F a) | (F G b)", "G !a"])
def test_strategy_improvement_from_scratch(formula, monkeypatch):
    # without the almost-sure region and the reachability shortcut, strategy improvement
    # alone (strict switches, then the value-preserving sub-game) must find the value
    real = rabin.almost_sure_region
    calls = []

    def first_empty(model, good, bad, rows=None):
        if not calls:
            calls.append(1)
            return np.zeros(model.n_states, bool), np.full(model.n_states, -1)
        return real(model, good, bad, rows)

    monkeypatch.setattr(rabin, "_stays_accepting_outside", lambda *args: True)
    rng = np.random.default_rng(5 + len(formula))
    for m, aut, prod_ref in _checked(rng, formula, 3):
        calls.clear()
        monkeypatch.setattr(rabin, "almost_sure_region", first_empty)
        _, _, per_state = ref.game_value(prod_ref)
        prod = ProductIMDP(m, aut)
        sol = satisfaction(prod)
        monkeypatch.setattr(rabin, "almost_sure_region", real)
        idx = [prod.state_index(s, q) for s, q in prod_ref.states]
        assert sol.values[idx] == pytest.approx(per_state, abs=1e-7)


@pytest.mark.parametrize("formula", ["G (a -> X b)", "G (a -> X (!a U b))", "(G F a) | (F G b)"])
def test_between_sampled_resolutions(formula):
    # with 30 % zero lower bounds: never below the worst case of the strategy that is
    # optimal for a sampled static resolution, never above any sampled resolution's value
    rng = np.random.default_rng(7)
    for m, aut, prod_ref in _checked(rng, formula, 3, n=3, max_states=14):
        prod = ProductIMDP(m, aut)
        got = float(satisfaction(prod).values[prod.initial])
        for _ in range(5):
            dist, sigma = ref.sample_resolution(prod_ref, m, aut, rng)
            assert got <= ref.mdp_satisfaction(prod_ref, dist) + 1e-7
            assert got >= float(ref.strategy_value(prod_ref, sigma)[0]) - 1e-7


@pytest.mark.parametrize("formula", ["F a & G !b", "G F a", "(G F a) | (F G b)", "G (a -> X b)"])
def test_almost_sure_region_is_closed_so_the_reachability_skips_its_search(formula, monkeypatch):
    # every state that reaches the almost-sure region almost surely is in it: solving the
    # reachability as closed gives what the full graph precomputation gives
    rng = np.random.default_rng(11 + len(formula))
    for m, aut, _ in _checked(rng, formula, 4, n=3, max_states=14):
        prod = ProductIMDP(m, aut)
        win, _ = rabin.almost_sure_region(prod.model, prod.good_matrix(), prod.bad_matrix())
        sure, _ = graph.robust_almost_sure_reach(prod.model, win)
        np.testing.assert_array_equal(sure, win)
        fast = satisfaction(prod)
        monkeypatch.setattr(rabin, "solve_with", lambda problem, alg, closed: solve(problem, alg))
        slow = satisfaction(prod)
        monkeypatch.undo()
        np.testing.assert_array_equal(fast.lower, slow.lower)
        np.testing.assert_array_equal(fast.upper, slow.upper)
        np.testing.assert_array_equal(fast.strategy, slow.strategy)


@pytest.mark.parametrize("zero_lower", [False, True])
def test_adversary_attractor_is_the_plain_fixpoint(zero_lower):
    """The game's adversary attractor (the pruning cascade from ``start``): a state of the
    region joins when it has an available row and each one has an allowed ``upper > 0``
    entry into the set; ``won`` states join only from ``start``."""
    from planner.imdp.rabin_game import _Game
    from tests.planner.imdp.reference import random_imdp

    rng = np.random.default_rng(11 + zero_lower)
    grown = 0
    for i in range(200):
        m = random_imdp(rng, int(rng.integers(5, 40)), 3, 4, zero_lower)
        region = rng.random(m.n_states) < 0.85
        start = rng.random(m.n_states) < 0.15
        won = rng.random(m.n_states) < 0.1
        rows_ok = rng.random(m.n_rows) < 0.9
        entry_ok = None if i % 3 else rng.random(m.n_entries) < 0.9
        game = _Game(m, np.zeros(m.n_states, bool), np.zeros(m.n_states, bool))
        got = game.adversary_attractor(region, rows_ok, entry_ok, won, start)
        up = m.upper if entry_ok is None else np.where(entry_ok, m.upper, 0.0)
        want = start & region
        avail = rows_ok & region[m.row_state]
        while True:
            enters = np.add.reduceat((up > 0) & want[m.successor], m.row_ptr[:-1]) > 0
            n_avail = np.bincount(m.row_state[avail], minlength=m.n_states)
            n_enter = np.bincount(m.row_state[avail & enters], minlength=m.n_states)
            grow = want | (region & ~won & (n_avail > 0) & (n_enter == n_avail))
            if np.array_equal(grow, want):
                break
            want = grow
        np.testing.assert_array_equal(got, want)
        grown += int(want.sum() > (start & region).sum())
    assert grown > 50
