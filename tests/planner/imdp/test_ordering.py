from fractions import Fraction

import numpy as np
import pytest

from planner.imdp import IMDP, OrderingAdversary, best_case_expectation, worst_case_expectation
from planner.imdp.kernels.rows import order_rows, unordered_rows
from tests.planner.imdp.reference import random_imdp, ref_expectation, rows_of


def test_single_row_exact():
    # successors 0, 1, 2 with values 0, 1/2, 1; l = (.1, .2, .3), u = (.5, .6, .7)
    m = IMDP(
        3,
        [0, 0, 0, 1, 2],
        [0, 0, 0, 0, 0],
        [0, 1, 2, 1, 2],
        [0.1, 0.2, 0.3, 1, 1],
        [0.5, 0.6, 0.7, 1, 1],
    )
    v = np.array([0.0, 0.5, 1.0])
    # worst: remaining 0.4 all to successor 0 -> p = (.5, .2, .3)
    worst = Fraction(1, 2) * 0 + Fraction(2, 10) * Fraction(1, 2) + Fraction(3, 10)
    # best: .4 to successor 2 -> p = (.1, .2, .7)
    best = Fraction(2, 10) * Fraction(1, 2) + Fraction(7, 10)
    assert worst_case_expectation(m, v)[0] == pytest.approx(float(worst), abs=1e-15)
    assert best_case_expectation(m, v)[0] == pytest.approx(float(best), abs=1e-15)


@pytest.mark.parametrize("zero_lower", [True, False])
def test_matches_reference_on_random_rows(zero_lower):
    rng = np.random.default_rng(3)
    m = random_imdp(rng, n_states=40, max_succ=7, zero_lower=zero_lower)
    rows = rows_of(m)
    for _ in range(3):
        v = rng.random(m.n_states)
        v[rng.random(m.n_states) < 0.3] = 0.5  # ties
        w = worst_case_expectation(m, v)
        b = best_case_expectation(m, v)
        for r in range(m.n_rows):
            row = rows[(int(m.row_state[r]), int(m.row_action[r]))]
            assert w[r] == pytest.approx(ref_expectation(row, v, True), abs=1e-12)
            assert b[r] == pytest.approx(ref_expectation(row, v, False), abs=1e-12)
        assert np.all(w <= b + 1e-12)


def test_cached_order_follows_changing_values():
    rng = np.random.default_rng(5)
    m = random_imdp(rng, n_states=30, max_succ=6)
    adv = OrderingAdversary(m, minimize=True)
    for _ in range(6):
        v = rng.random(m.n_states)
        # perturb only a few states so that partial re-sorts happen
        got = adv.expectation(v)
        assert np.allclose(got, worst_case_expectation(m, v), atol=1e-13)
        d = adv.matrix(v)
        assert np.allclose(np.asarray(d.sum(axis=1)).ravel(), 1.0, atol=1e-12)
        v2 = v.copy()
        v2[rng.integers(m.n_states)] = rng.random()
        assert np.allclose(adv.expectation(v2), worst_case_expectation(m, v2), atol=1e-13)


@pytest.mark.parametrize("lens", [[3, 1, 4, 2], [1, 1, 1, 200]])
def test_order_rows_sorts_stably_from_the_current_order_and_hands_out_the_mass(lens):
    rng = np.random.default_rng(2)
    lens = np.array(lens)
    n = int(lens.sum())
    ptr = np.concatenate(([0], np.cumsum(lens))).astype(np.int64)
    row = np.repeat(np.arange(lens.size), lens)
    successor = rng.integers(0, 5, size=n).astype(np.int64)
    values = rng.integers(0, 3, size=5).astype(float)  # many ties
    lower = rng.uniform(0.0, 0.1, size=n) / lens[row]
    gap = rng.uniform(0.0, 1.0, size=n) / lens[row]
    remaining = 1.0 - np.bincount(row, weights=lower)
    start = np.concatenate(
        [rng.permutation(np.arange(ptr[i], ptr[i + 1])) for i in range(lens.size)]
    )
    perm, prob, succ = start.copy(), np.empty(n), np.empty(n, dtype=np.int64)
    upper = lower + gap
    order_rows(
        np.arange(lens.size), ptr, successor, lower, upper, remaining, values, perm, prob, succ
    )
    # stable from the current order: ties keep the order they had in ``start``
    expected = start[np.lexsort((np.arange(n), values[successor[start]], row))]
    assert perm.tolist() == expected.tolist()
    assert succ.tolist() == successor[perm].tolist()
    for r in range(lens.size):
        e = perm[ptr[r] : ptr[r + 1]]
        before = np.concatenate(([0.0], np.cumsum(gap[e])[:-1]))
        want = lower[e] + np.clip(remaining[r] - before, 0.0, upper[e] - lower[e])
        np.testing.assert_allclose(prob[ptr[r] : ptr[r + 1]], want, rtol=0, atol=1e-15)


def test_unordered_rows_flags_rows_out_of_order_beyond_the_slack():
    ptr = np.array([0, 3, 4, 7, 9])
    keys = np.array([0.0, 1.0, 2.0, 2.0 - 1e-9, 3.0])
    succ = np.array([0, 1, 2, 4, 2, 3, 1, 1, 1])  # rows: sorted, single, 2 > 2-1e-9 > 1, ties
    assert unordered_rows(ptr, succ, keys, 0.0).tolist() == [2]
    assert unordered_rows(ptr, succ, keys, 1e-8).tolist() == [2]  # 2 - 1e-9 > 1 by ~1
    succ[4:7] = [2, 3, 0]  # 2 then 2 - 1e-9: out of order by 1e-9 only, then 0 after it
    assert unordered_rows(ptr, succ, keys, 0.0).tolist() == [2]
    succ[6] = 4
    assert unordered_rows(ptr, succ, keys, 1e-8).tolist() == []
    assert unordered_rows(ptr, succ, keys, 0.0).tolist() == [2]
