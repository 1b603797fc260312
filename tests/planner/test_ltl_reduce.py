"""Reduction of Rabin automata keeps the language; Boolean covers are exact."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from planner.ltl.boolean import cover
from planner.ltl.reduce import reduce_rabin
from tests.planner.ltl_oracle import automaton_accepts, lasso_batches

BATCHES = list(lasso_batches([(0, 1), (0, 2), (1, 1), (1, 2), (2, 2), (0, 3)], n_props=2))


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.integers(1, 8), st.integers(0, 3), st.integers(0, 2**32 - 1))
def test_reduce_keeps_language(n, n_pairs, seed):
    rng = np.random.default_rng(seed)
    table = rng.integers(0, n, size=(n, 4))
    pairs = [(rng.random(n) < 0.4, rng.random(n) < 0.3) for _ in range(n_pairs)]
    names = [str(i) for i in range(n)]
    t2, init2, pairs2, names2 = reduce_rabin(table, 0, pairs, names)
    assert t2.shape[0] <= n and len(names2) == t2.shape[0]
    p1 = [(set(np.flatnonzero(g)), set(np.flatnonzero(b))) for g, b in pairs]
    p2 = [(set(np.flatnonzero(g)), set(np.flatnonzero(b))) for g, b in pairs2]
    for letters, start in BATCHES:
        assert np.array_equal(
            automaton_accepts(table, 0, p1, letters, start),
            automaton_accepts(t2, init2, p2, letters, start),
        )


@settings(max_examples=100, deadline=None, derandomize=True)
@given(
    st.integers(0, 4).flatmap(lambda k: st.tuples(st.just(k), st.sets(st.integers(0, 2**k - 1))))
)
def test_cover_is_exact(case):
    n_props, letters = case
    cubes = cover(letters, n_props)
    covered = {x for x in range(1 << n_props) if any(x & c == v for c, v in cubes)}
    assert covered == letters
