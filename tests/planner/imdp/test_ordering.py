from fractions import Fraction

import numpy as np
import pytest

from planner.imdp import IMDP, OrderingAdversary, best_case_expectation, worst_case_expectation
from planner.imdp.ordering import segmented_cumsum
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


def test_segmented_cumsum_restarts_per_segment():
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    pos = np.array([0, 1, 2, 0, 1, 0])
    assert segmented_cumsum(x, pos, 3).tolist() == [1, 3, 6, 4, 9, 6]


@pytest.mark.parametrize("lens", [[3, 1, 4, 2], [1, 1, 1, 200]])
def test_row_sort_padded_and_long_row_paths(lens):
    from planner.imdp.ordering import _sort_rows

    rng = np.random.default_rng(2)
    lens = np.array(lens)
    keys = rng.integers(0, 3, size=lens.sum()).astype(float)  # many ties
    row = np.repeat(np.arange(lens.size), lens)
    pos = np.arange(lens.sum()) - np.repeat(np.cumsum(lens) - lens, lens)
    got = _sort_rows(keys, lens, pos, int(lens.max()))
    assert got.tolist() == np.lexsort((keys, row)).tolist()
