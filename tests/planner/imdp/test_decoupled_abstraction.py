"""The decoupled grid abstraction against the product-interval IMDP of the same
:class:`~planner.intervals.CellErrorBounds` (residual std included): the same per-axis
intervals, a value never below the product-interval one, strictly above it where a hazard
lies diagonal to the target, sound for every fixed mean error inside the bounds."""

import numpy as np
import pytest

from planner.errors import IntervalError, ModelError, ProductError
from planner.imdp import Problem, ReachAvoid, Specification, solve
from planner.imdp.analysis import satisfaction, winning_states
from planner.imdp.decoupled import DecoupledProduct, decoupled_from_axes, grid_decoupled_model
from planner.imdp.grid import ACTIONS, GridWorld
from planner.imdp.product import ProductIMDP
from planner.intervals import (
    CellErrorBounds,
    ResidualNoise,
    TruncatedGaussianNoise,
    axis_intervals,
    transition_intervals,
)
from planner.ltl.translate import translate
from planner.modes import Adversary
from tests.planner.imdp.helpers import until_automaton
from tests.planner.imdp.rabin_reference import vertices

NOISE = TruncatedGaussianNoise()
NA = len(ACTIONS)


def grid_case(seed: int, layout: int = 0) -> tuple[GridWorld, CellErrorBounds]:
    """A 6 x 5 world (one of three hazard/goal layouts) with random per-(cell, action)
    error bounds and a random nonzero residual std per (action, axis)."""
    labels = [()] * 30
    haz, goal = ([7], 18) if layout == 0 else ([8, 13], 14) if layout == 1 else ([7, 22], 12)
    for h in haz:
        labels[h] = ("Haz",)
    labels[goal] = ("Goal",)
    g = GridWorld(6, 5, 1.0, labels)
    rng = np.random.default_rng(seed)
    width = rng.uniform(0.0, 0.5, size=(g.n_cells, NA, 2))
    centre = rng.uniform(-0.2, 0.2, size=(g.n_cells, NA, 2))
    resid = rng.uniform(0.01, 0.08, size=(NA, 2))
    return g, CellErrorBounds(centre - width, centre + width, resid, 0.0, 0.01, 1)


def interval_product(g: GridWorld, bounds: CellErrorBounds, initial=(0,)) -> ProductIMDP:
    """The runner's product-interval IMDP of ``bounds`` with ``!Haz U Goal``."""
    ti = transition_intervals(bounds, g, NOISE)
    return ProductIMDP(g.imdp_from_intervals(*ti.coo(), initial=initial), until_automaton())


def decoupled_product(g: GridWorld, bounds: CellErrorBounds, initial=(0,)) -> DecoupledProduct:
    return DecoupledProduct(grid_decoupled_model(g, bounds, NOISE, initial), until_automaton())


def axis_entries(dm, r: int, d: int) -> list[tuple[int, float, float]]:
    """``(bin, lower, upper)`` of row ``r`` on axis ``d`` of a decoupled model."""
    ptr, b, lo, up = dm.axes[d]
    sl = slice(ptr[r], ptr[r + 1])
    return list(zip(b[sl].tolist(), lo[sl].tolist(), up[sl].tolist(), strict=True))


def test_axis_products_are_the_product_interval_bounds():
    # both abstractions describe the same per-axis uncertainty: for every enabled pair, the
    # products of the decoupled model's per-axis bounds are the product-interval bounds of
    # each cell, 1 - (1 - out_x)(1 - out_y) those of out, and the pairs it can reach are the
    # successors the product-interval model keeps
    for seed in range(3):
        g, b = grid_case(seed)
        dm = grid_decoupled_model(g, b, NOISE)
        ti = transition_intervals(b, g, NOISE)
        key = (ti.state * NA + ti.action) * g.n_states + ti.successor
        for c, a in zip(*np.nonzero(g.enabled[: g.n_cells]), strict=True):
            r = int(dm.row_index[c, a])
            (bx, lx, ux), (by, ly, uy) = (np.array(axis_entries(dm, r, d)).T for d in (0, 1))
            bx, by = bx.astype(int), by.astype(int)
            inx, iny = bx < g.nx, by < g.ny
            succ = (bx[inx][:, None] * g.ny + by[iny][None, :]).ravel()
            lo = (lx[inx][:, None] * ly[iny][None, :]).ravel()
            up = (ux[inx][:, None] * uy[iny][None, :]).ravel()
            out_lo = 1 - (1 - lx[~inx].sum()) * (1 - ly[~iny].sum())
            out_hi = 1 - (1 - ux[~inx].sum()) * (1 - uy[~iny].sum())
            if (~inx).any() or (~iny).any():
                succ, lo, up = np.append(succ, g.out), np.append(lo, out_lo), np.append(up, out_hi)
            k = np.searchsorted(key, (c * NA + a) * g.n_states + succ)
            assert np.array_equal(key[k], (c * NA + a) * g.n_states + succ)
            assert np.count_nonzero((ti.state == c) & (ti.action == a)) == succ.size
            assert ti.lower[k] == pytest.approx(lo, abs=1e-12)
            assert ti.upper[k] == pytest.approx(up, abs=1e-12)


def test_the_residual_widens_the_decoupled_intervals():
    # the decoupled model takes the bounds' residual: zero it and the intervals change,
    # keep it and they are those of the residual-including noise
    g, b = grid_case(1)
    with_resid = grid_decoupled_model(g, b, NOISE)
    nu_only = grid_decoupled_model(
        g, CellErrorBounds(b.lower, b.upper, np.zeros((NA, 2)), 0.0, 0.01, 1), NOISE
    )
    c, a = 2 * g.ny + 2, 0  # N1 from (2, 2): target (2, 3)
    r = int(with_resid.row_index[c, a])
    (bx, lx, ux), _ = (np.array(axis_entries(with_resid, r, d)).T for d in (0, 1))
    w = ResidualNoise(NOISE, float(b.residual_std[a, 0]))
    t = 2.5
    e_lo, e_hi = b.lower[c, a, 0], b.upper[c, a, 0]
    for col, lo, up in zip(bx.astype(int), lx, ux, strict=True):
        if col < g.nx:
            es = np.linspace(e_lo, e_hi, 2001)
            p = w.cdf(col + 1 - t - es) - w.cdf(col - t - es)
            assert lo == pytest.approx(p.min(), abs=1e-9)
            assert up == pytest.approx(p.max(), abs=1e-4)
    assert axis_entries(with_resid, r, 0) != axis_entries(nu_only, r, 0)


def test_grid_decoupled_never_below_product_interval():
    # the decoupled adversary's product distributions lie inside the product-interval
    # bounds: worst case never lower, best case never higher (up to the certified brackets)
    gains = []
    for layout in (0, 1, 2):
        for seed in range(3):
            g, b = grid_case(seed, layout)
            dp, ip = decoupled_product(g, b), interval_product(g, b)
            d, pint = dp.satisfaction(), satisfaction(ip)
            # the decoupled bracket is certified only where the exact check through its
            # expansion shows the bound from above (not on layout 1, seed 0); its values
            # are bounds from below either way
            assert pint.converged
            assert np.all(d.values >= pint.values - 1e-8)
            d_best = dp.satisfaction(Adversary.OPTIMISTIC)
            p_best = satisfaction(ip, Adversary.OPTIMISTIC)
            assert np.all(d_best.values <= p_best.values + 1e-8)
            # a bracket, never crossed (the shown bound lay up to 6.7e-16 below the
            # bound from below at some states of the best-case solves)
            for sol in (d, d_best):
                assert np.all(sol.lower <= sol.upper) and np.all(sol.values <= sol.upper)
            gains.append(float(np.max(d.values - pint.values)))
    assert max(gains) > 1e-3


def diagonal_case() -> tuple[GridWorld, CellErrorBounds, int]:
    """A 4 x 4 world: from the start (0, 0), ``E1`` aims at (1, 0) and every mean error
    lies in ``[0, 0.5]`` per axis, so it lands in columns 1..2 and rows 0..1: the target
    (1, 0) (unlabelled), the hazards (2, 0) and (1, 1) beside it and the goal (2, 1)
    diagonal to it. Returns the world, the bounds and the row's action."""
    labels = [()] * 16
    labels[2 * 4 + 0] = labels[1 * 4 + 1] = ("Haz",)
    labels[2 * 4 + 1] = ("Goal",)
    g = GridWorld(4, 4, 1.0, labels)
    lo = np.zeros((g.n_cells, NA, 2))
    b = CellErrorBounds(lo, lo + 0.5, np.full((NA, 2), 0.02), 0.0, 0.01, 1)
    return g, b, ACTIONS.index("E1")


def test_decoupled_is_strictly_higher_with_a_diagonal_goal():
    # per axis the hop stays in its target column (row) with [l, u] and moves on with
    # [1 - u, 1 - l]. The product-interval adversary puts the upper bounds on both hazards
    # and only the lower bound l_x l_y on the target, nothing on the goal; a product of
    # per-axis distributions that loads both hazards also loads the goal (p_x p_y on it):
    # with values 1 on the goal, 0 on the hazards and v on the target, the decoupled
    # expectation is at least min over the vertices, above the product-interval one
    g, b, e1 = diagonal_case()
    dm = grid_decoupled_model(g, b, NOISE)
    r = int(dm.row_index[0, e1])
    v = np.zeros(g.n_states)
    v[1 * 4 + 0], v[2 * 4 + 1] = 0.5, 1.0
    q_dec = dm.expectation(v)[r]
    brute = min(
        sum(px * py * v[dm.maps[0, i, j]] for i, px in vx.items() for j, py in vy.items())
        for vx in vertices(axis_entries(dm, r, 0))
        for vy in vertices(axis_entries(dm, r, 1))
    )
    assert q_dec == pytest.approx(brute, abs=1e-12)
    ti = transition_intervals(b, g, NOISE)
    sel = (ti.state == 0) & (ti.action == e1)
    assert sorted(ti.successor[sel].tolist()) == [4, 5, 8, 9]
    order = np.argsort(v[ti.successor[sel]], kind="stable")
    lo, up, vals = ti.lower[sel][order], ti.upper[sel][order], v[ti.successor[sel]][order]
    p = lo + np.diff(np.minimum(np.cumsum(np.append(0, up - lo)), 1 - lo.sum()))
    q_int = float(p @ vals)
    assert q_dec > q_int + 0.05
    # and so is the solved worst-case value at the start, the rest never below
    dp, ip = decoupled_product(g, b), interval_product(g, b)
    d, pint = dp.satisfaction(), satisfaction(ip)
    assert np.all(d.values >= pint.values - 1e-8)
    assert d.values[dp.initial] > pint.values[ip.initial] + 0.01


def test_decoupled_value_is_sound_for_fixed_mean_errors():
    # for a mean error fixed per (cell, action) inside the bounds, the hop's distribution is
    # the product of the per-axis ones of the residual-including noise: its MDP's optimal
    # satisfaction is at least the decoupled worst case
    g, b = grid_case(0, 2)
    d = decoupled_product(g, b).satisfaction()
    rng = np.random.default_rng(4)
    for _ in range(3):
        e = rng.uniform(b.lower, b.upper)
        point = CellErrorBounds(e, e, b.residual_std, 0.0, 0.01, 1)
        exact = satisfaction(interval_product(g, point))
        assert np.all(exact.values >= d.values - 1e-8)


def test_point_errors_give_the_interval_model():
    # zero-width error bounds: per-axis point distributions, both models the same chain
    g, b = grid_case(3)
    point = CellErrorBounds(b.lower, b.lower, b.residual_std, 0.0, 0.01, 1)
    dec = decoupled_product(g, point).satisfaction()
    ip = interval_product(g, point)
    assert dec.values == pytest.approx(satisfaction(ip).values, abs=1e-8)
    reach = solve(Problem(ip.model, Specification(ReachAvoid(winning_states(ip)))))
    assert dec.values == pytest.approx(reach.values, abs=1e-8)


def test_errors():
    g, b = grid_case(0)
    with pytest.raises(IntervalError, match="shape"):
        grid_decoupled_model(
            g, CellErrorBounds(b.lower[1:], b.upper[1:], b.residual_std, 0, 0.01, 1)
        )
    with pytest.raises(IntervalError, match="residual_std"):
        grid_decoupled_model(g, CellErrorBounds(b.lower, b.upper, -b.residual_std, 0, 0.01, 1))
    ax = axis_intervals(b, g, NOISE)
    with pytest.raises(ModelError, match="every enabled"):
        decoupled_from_axes(g, type(ax)(ax.state[1:], *(getattr(ax, f) for f in _FIELDS)))
    dm = grid_decoupled_model(g, b, NOISE)
    with pytest.raises(ProductError, match="co-safe"):
        DecoupledProduct(dm, translate("G F Goal")).satisfaction()


_FIELDS = ("action", "x_lower", "x_upper", "y_lower", "y_upper", "inside_x", "inside_y")
