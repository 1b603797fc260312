"""Orthogonally decoupled interval MDPs (odIMDPs): transitions that are products of
per-axis interval distributions.

A row ``(s, a)`` has per-axis bins with intervals: ``x`` bins ``X_r`` with
``[l^x_b, u^x_b]`` and ``y`` bins ``Y_r`` with ``[l^y_b, u^y_b]``. The adversary picks one
distribution per axis inside its intervals, ``p^x`` and ``p^y`` (each summing to 1), and
the successor is the state ``map[b_x, b_y]`` of the landed bin pair, with probability
``p^x(b_x) p^y(b_y)``. On the grid the bins of an axis are the ``n`` columns plus
*outside*, and a bin pair with either bin outside maps to the absorbing ``out`` state.
This is IntervalMDP.jl's orthogonally decoupled model; it fits the abstraction because the
landing noise and the error bounds are independent per axis. Built from the same per-axis
intervals (:func:`planner.intervals.axis_intervals`, residual included; see
:mod:`planner.imdp.decoupled.abstraction`), it is tighter than the product-interval IMDP
(:func:`planner.intervals.transition_intervals`), whose adversary may pick any joint
distribution inside the products of the per-axis bounds.

**The robust Bellman operator is exact.** For values ``v``,

    min_{p^x, p^y} sum_{b_x, b_y} p^x(b_x) p^y(b_y) v(map[b_x, b_y])

is bilinear: for a fixed ``p^x`` it is linear in ``p^y``, minimised by the state-ordering
adversary on the induced values ``w(b_y) = sum_{b_x} p^x(b_x) v(map[b_x, b_y])``; that
minimum is a concave function of ``p^x`` (a minimum of linear functions), so its minimum
over the polytope of ``p^x`` is attained at a vertex. The operator therefore enumerates the
vertices of one axis's polytope (the axis with fewer bins; a vertex has every bin but one
at a bound, so there are at most ``k 2^(k-1)`` for ``k`` bins, a handful on the grid) and
orders the other. (Ordering both axes in a nested way, letting the inner distribution
depend on the outer bin, lets the adversary pick a different ``p^y`` per ``b_x``: a joint
distribution that is not a product, which only gives a lower bound.) The maximising
adversary is the same with maxima (a maximum of convex functions, again at a vertex).

A dynamic adversary that picks the pair anew at each step and may randomise can realise
every point of the convex hull of the product distributions; the values of reachability
games are the same (randomisation does not help in turn-based games), so value iteration
with this operator computes the game value. Reachability is solved by Gauss-Seidel sweeps
from below, certified from above like :func:`planner.imdp.solve.solve` (a candidate
``min(1, L + tolerance / 2)`` checked superharmonic, which bounds the least fixed point).
"""

from planner.imdp.decoupled.abstraction import decoupled_from_axes, grid_decoupled_model
from planner.imdp.decoupled.model import DecoupledIMDP
from planner.imdp.decoupled.product import DecoupledProduct
from planner.imdp.decoupled.reach import (
    expanded_imdp,
    expanded_size,
    solve_reach,
    strategy_iteration,
)

__all__ = [
    "DecoupledIMDP",
    "DecoupledProduct",
    "decoupled_from_axes",
    "expanded_imdp",
    "expanded_size",
    "grid_decoupled_model",
    "solve_reach",
    "strategy_iteration",
]
