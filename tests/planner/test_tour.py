"""The in-component tour: it keeps moving, heads for rewarding cells first, then covers."""

from __future__ import annotations

import numpy as np
import pytest

from planner.errors import PolicyError
from planner.imdp import IMDP
from planner.imdp.graph import EndComponent
from planner.tour import ComponentTour

N = 5  # a 5 x 5 grid of states, state i * N + j; actions N, E, S, W move one cell
MOVES = np.array([(0, 1), (1, 0), (0, -1), (-1, 0)])


def _grid(spill: float = 0.0) -> IMDP:
    """Each action lands on its neighbour (lower = 1 - spill) and, with ``spill > 0``, may
    also land on the cell beside the mover (upper = spill): a small-probability sideways
    successor, as learned intervals have."""
    s, a, t, lo, up = [], [], [], [], []
    for i in range(N):
        for j in range(N):
            for k, (di, dj) in enumerate(MOVES):
                ti, tj = i + di, j + dj
                if not (0 <= ti < N and 0 <= tj < N):
                    continue
                s.append(i * N + j), a.append(k), t.append(ti * N + tj)
                lo.append(1.0 - spill), up.append(1.0)
                side = (i + dj, j + di)  # one cell across the move's direction
                if spill > 0 and 0 <= side[0] < N and 0 <= side[1] < N:
                    s.append(i * N + j), a.append(k), t.append(side[0] * N + side[1])
                    lo.append(0.0), up.append(spill)
    return IMDP(N * N, np.array(s), np.array(a), np.array(t), np.array(lo), np.array(up),
                n_actions=4)  # fmt: skip


def _tour(model: IMDP, reward=None, mode="reward", uncertainty=None, aim=None) -> ComponentTour:
    comp = EndComponent(np.arange(model.n_states), np.arange(model.n_rows))
    n = model.n_states
    return ComponentTour(
        model,
        comp,
        model.enabled.copy(),
        np.arange(n),
        np.zeros(n) if reward is None else reward,
        np.zeros(n) if uncertainty is None else uncertainty,
        mode,
        aim=aim,
    )


def _walk(model: IMDP, tour: ComponentTour, start: int, steps: int, seed: int = 0):
    """Follow the tour's action (its aimed successor, which has the largest upper bound)."""
    rng = np.random.default_rng(seed)
    last = np.full(model.n_states, -1)
    s, path = start, [start]
    for k in range(steps):
        last[s] = k
        a = tour.action(s, last, rng)
        row = model.row_index[s, a]
        s = int(tour.aim[row])
        path.append(s)
    return path


def test_coverage_visits_every_state_without_shuttling():
    model = _grid()
    path = _walk(model, _tour(model, mode="coverage"), start=12, steps=40)
    assert set(path) == set(range(N * N))  # 25 states in 40 hops
    first = {s: path.index(s) for s in set(path)}
    assert max(first.values()) <= 35
    # the lowest-index in-component action (N, then E...) would shuttle between two cells
    assert len(set(path[-10:])) > 2


def test_reward_mode_heads_for_the_highest_rewards_first():
    model = _grid()
    reward = np.zeros(N * N)
    reward[[0 * N + 4, 4 * N + 4]] = 20.0  # two far corners
    reward[2 * N + 1] = 5.0  # next to the start, away from the 20s
    tour = _tour(model, reward=reward)
    rng = np.random.default_rng(0)
    last = np.full(N * N, -1)
    s, seen = 2 * N + 2, []
    for k in range(30):
        last[s] = k
        s = int(tour.aim[model.row_index[s, tour.action(s, last, rng)]])
        if tour.reward[s] > 0:
            seen.append(s)
            tour = tour.with_reward(np.where(np.arange(N * N) == s, 0.0, tour.reward))
        if len(seen) == 3:
            break
    assert seen[:2] in ([0 * N + 4, 4 * N + 4], [4 * N + 4, 0 * N + 4])
    assert seen[2] == 2 * N + 1  # the 5 only once the 20s are collected


def test_targets_skip_the_current_cell_and_prefer_the_least_known():
    model = _grid()
    unc = np.zeros(N * N)
    unc[[3, 21]] = 1.0
    tour = _tour(model, mode="coverage", uncertainty=unc)
    last = np.arange(N * N)  # every state visited; state 0 longest ago
    t = tour.targets(0, last)
    assert t.sum() == 1 and t[1]  # not the current state 0: the next oldest
    never = np.full(N * N, -1)
    assert np.flatnonzero(tour.targets(3, never)).tolist() == [21]


def test_aim_beats_upper_bound_distances_under_small_sideways_uppers():
    # with sideways successors of small upper bound, distances along every upper > 0 edge
    # make a sideways hop look as good as a straight one; aiming follows the straight hop
    model = _grid(spill=0.05)
    aim = np.full(model.n_rows, -1)  # none given: the successor of largest upper bound
    tour = _tour(model, mode="coverage", aim=aim)
    for r in range(model.n_rows):
        e = slice(model.row_ptr[r], model.row_ptr[r + 1])
        assert tour.aim[r] == model.successor[e][np.argmax(model.upper[e])]
    path = _walk(model, tour, start=12, steps=40)
    assert set(path) == set(range(N * N))


def test_outside_the_component_and_bad_input():
    model = _grid()
    half = np.flatnonzero(np.arange(N * N) < 10)
    rows = np.flatnonzero(np.isin(model.row_state, half))
    stays = [r for r in rows if model.successor[model.row_ptr[r]] in half]
    comp = EndComponent(half, np.array(stays))
    n = N * N
    tour = ComponentTour(model, comp, model.enabled, np.arange(n), np.zeros(n), np.zeros(n))
    assert tour.covers(3) and not tour.covers(20)
    assert tour.action(20, np.full(n, -1), np.random.default_rng(0)) == -1
    a = tour.action(3, np.full(n, -1), np.random.default_rng(0))
    assert model.successor[model.row_ptr[model.row_index[3, a]]] in half
    with pytest.raises(PolicyError, match="mode"):
        ComponentTour(model, comp, model.enabled, np.arange(n), np.zeros(n), np.zeros(n), "x")
    with pytest.raises(PolicyError, match="shape"):
        ComponentTour(model, comp, model.enabled, np.arange(n), np.zeros(3), np.zeros(n))
    with pytest.raises(PolicyError, match="aim"):
        ComponentTour(model, comp, model.enabled, np.arange(n), np.zeros(n), np.zeros(n),
                      aim=np.zeros(2, dtype=int))  # fmt: skip
