"""Compiled (numba) kernels for the sequential parts of robust value iteration and of the
graph analyses: the robust expectation of a row (:mod:`.rows`), Gauss-Seidel sweeps
(:mod:`.gauss_seidel`) and their layout (:mod:`.sweeps`) in breadth-first layers
(:mod:`.layers`), passes from above (:mod:`.upper`), end components (:mod:`.components`),
graph searches (:mod:`.search`), the pruning cascade (:mod:`.pruning`), double-double
residuals of strategy evaluation (:mod:`.exact`) and the superharmonicity check in exact
arithmetic (:mod:`.verify`)."""

from planner.imdp.kernels.components import component_exit_bound, maximal_end_components_kernel
from planner.imdp.kernels.exact import chain_exit_residual
from planner.imdp.kernels.gauss_seidel import gauss_seidel_sweep
from planner.imdp.kernels.layers import layers
from planner.imdp.kernels.pruning import drop_states, prune_kernel, rows_staying_in
from planner.imdp.kernels.rows import all_row_values, gather_rows
from planner.imdp.kernels.search import (
    attractor,
    attractor_of_rows,
    counting_order,
    forward_reach,
    incoming_index,
    surest_exit_choice,
)
from planner.imdp.kernels.sweeps import ReachSweeper
from planner.imdp.kernels.upper import upper_sweep

__all__ = [
    "ReachSweeper",
    "all_row_values",
    "attractor",
    "attractor_of_rows",
    "chain_exit_residual",
    "component_exit_bound",
    "counting_order",
    "drop_states",
    "forward_reach",
    "gather_rows",
    "gauss_seidel_sweep",
    "incoming_index",
    "layers",
    "maximal_end_components_kernel",
    "prune_kernel",
    "rows_staying_in",
    "surest_exit_choice",
    "upper_sweep",
]
