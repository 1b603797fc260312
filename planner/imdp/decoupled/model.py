"""The orthogonally decoupled interval MDP as data (:class:`DecoupledIMDP`): rows with
per-axis bins and intervals, successor maps, labels; validated on construction."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from planner.errors import ModelError, SpecificationError
from planner.imdp.decoupled.operator import all_values, vertices
from planner.imdp.entries import fresh_copy, rows_to_tighten, tighten_rows
from planner.imdp.model import BOUND_TOLERANCE


class DecoupledIMDP:
    """An orthogonally decoupled interval MDP (see :mod:`planner.imdp.decoupled`).

    Args:
        n_states: number of states.
        row_state, row_action: the (state, action) of every row, sorted by state then
            action (each state needs a row).
        x_ptr, x_bin, x_lower, x_upper: CSR of the ``x`` entries of the rows (bin index,
            bounds); ``y_ptr, y_bin, y_lower, y_upper`` likewise.
        maps: ``(n_maps, n_xbins, n_ybins)`` successor state of every bin pair.
        row_map: ``(n_rows,)`` the map each row uses.
        n_actions, labels, propositions, initial, action_names, tolerance: as for
            :class:`planner.imdp.model.IMDP`.

    Raises:
        ModelError: on unsorted rows, out-of-range indices, bounds outside ``[0, 1]``,
            ``lower > upper``, an axis row that does not bracket 1, or a state without rows.
    """

    def __init__(
        self,
        n_states: int,
        row_state: np.ndarray,
        row_action: np.ndarray,
        x_ptr: np.ndarray,
        x_bin: np.ndarray,
        x_lower: np.ndarray,
        x_upper: np.ndarray,
        y_ptr: np.ndarray,
        y_bin: np.ndarray,
        y_lower: np.ndarray,
        y_upper: np.ndarray,
        maps: np.ndarray,
        row_map: np.ndarray,
        *,
        n_actions: int,
        labels: Sequence[Iterable[str]] | None = None,
        propositions: Sequence[str] | None = None,
        label_matrix: np.ndarray | None = None,
        initial: Iterable[int] = (0,),
        action_names: Sequence[str] | None = None,
        tolerance: float = BOUND_TOLERANCE,
    ) -> None:
        n = int(n_states)
        self.n_states = n
        self.n_actions = int(n_actions)
        self.tolerance = float(tolerance)
        self.row_state = np.asarray(row_state, dtype=np.int64)
        self.row_action = np.asarray(row_action, dtype=np.int64)
        self.maps = np.asarray(maps, dtype=np.int64)
        self.row_map = np.asarray(row_map, dtype=np.int64)
        self._check_rows()
        self.axes = [
            self._checked_axis("x", x_ptr, x_bin, x_lower, x_upper, self.maps.shape[1]),
            self._checked_axis("y", y_ptr, y_bin, y_lower, y_upper, self.maps.shape[2]),
        ]
        rs, ra = self.row_state, self.row_action
        counts = np.bincount(rs, minlength=n)
        if np.any(counts == 0):
            raise ModelError(f"state {int(np.flatnonzero(counts == 0)[0])} has no row")
        self.state_ptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        self.enabled = np.zeros((n, self.n_actions), dtype=bool)
        self.enabled[rs, ra] = True
        self.row_index = np.full((n, self.n_actions), -1, dtype=np.int64)
        self.row_index[rs, ra] = np.arange(rs.size)
        self._set_labels(labels, propositions, label_matrix)
        self.initial = np.unique(np.asarray(list(initial), dtype=np.int64))
        self.action_names = tuple(action_names or (f"a{i}" for i in range(self.n_actions)))
        self._prepare()
        self._expanded = None  # reach.expanded_imdp's result, built once

    def _check_rows(self) -> None:
        """Rows sorted by state then action, indices in range, a map for every row."""
        n = self.n_states
        rs, ra = self.row_state, self.row_action
        key = rs * self.n_actions + ra
        if rs.size == 0 or np.any(np.diff(key) <= 0):
            raise ModelError("decoupled rows must be sorted by state then action, no repeats")
        if rs.min() < 0 or rs.max() >= n or ra.min() < 0 or ra.max() >= self.n_actions:
            raise ModelError("a decoupled row names a state or action out of range")
        if self.maps.ndim != 3 or self.maps.min() < 0 or self.maps.max() >= n:
            raise ModelError(f"maps must be (n_maps, nx, ny) state indices in [0, {n})")
        if self.row_map.shape != rs.shape or np.any(
            (self.row_map < 0) | (self.row_map >= self.maps.shape[0])
        ):
            raise ModelError("row_map must name a map for every row")

    def _checked_axis(
        self, name: str, ptr, b, lo, up, size: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One axis's CSR ``(ptr, bin, lower, upper)``, validated: every row has a bin, bins
        in ``[0, size)``, bounds in ``[0, 1]`` with ``lower <= upper`` that bracket 1; then
        made to bracket 1 exactly, with every bin's ``lower > 0`` / ``upper > 0`` exact (a
        copy, :func:`planner.imdp.entries.tighten_rows`)."""
        rs, ra = self.row_state, self.row_action
        ptr = np.asarray(ptr, dtype=np.int64)
        b = np.asarray(b, dtype=np.int64)
        lo = np.asarray(lo, dtype=np.float64)
        up = np.asarray(up, dtype=np.float64)
        if ptr.shape != (rs.size + 1,) or ptr[0] != 0 or np.any(np.diff(ptr) < 1):
            raise ModelError(f"{name}_ptr must give every row at least one {name} bin")
        if b.size != ptr[-1] or b.min() < 0 or b.max() >= size:
            raise ModelError(f"{name} bins must be indices in [0, {size})")
        bad = ~np.isfinite(lo) | ~np.isfinite(up) | (lo < 0) | (up > 1) | (lo > up)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ModelError(f"{name} entry {i}: bounds [{lo[i]}, {up[i]}] are not valid")
        s_lo = np.add.reduceat(lo, ptr[:-1])
        s_up = np.add.reduceat(up, ptr[:-1])
        bad = (s_lo > 1 + self.tolerance) | (s_up < 1 - self.tolerance)
        if bad.any():
            r = int(np.flatnonzero(bad)[0])
            raise ModelError(
                f"state {rs[r]}, action {ra[r]}: the {name} bounds do not bracket 1 "
                f"(sums {s_lo[r]:.12g}, {s_up[r]:.12g})"
            )
        # the same exact support as an IMDP row's (see planner.imdp.entries.tighten_rows)
        loose = rows_to_tighten(ptr, lo, up, s_lo, s_up)
        if loose.size:
            lo, up = fresh_copy(lo), fresh_copy(up)
            tighten_rows(loose, ptr, lo, up, s_lo, s_up)
        return ptr, b, lo, up

    def _set_labels(self, labels, propositions, label_matrix) -> None:
        n = self.n_states
        if label_matrix is not None:
            self.propositions = tuple(propositions or ())
            self.label_matrix = np.asarray(label_matrix, dtype=bool)
            return
        sets = [frozenset(x) for x in labels] if labels is not None else [frozenset()] * n
        self.propositions = (
            tuple(propositions) if propositions else tuple(sorted(set().union(*sets)))
        )
        self.label_matrix = np.array(
            [[p in ls for p in self.propositions] for ls in sets], dtype=bool
        ).reshape(n, len(self.propositions))

    @property
    def n_rows(self) -> int:
        return int(self.row_state.size)

    def states_labelled(self, name: str) -> np.ndarray:
        if name not in self.propositions:
            raise SpecificationError(f"label {name!r} is not among {self.propositions}")
        return self.label_matrix[:, self.propositions.index(name)].copy()

    def _prepare(self) -> None:
        """Per row: the outer axis (fewer bins), its vertices, the inner axis's gaps; the
        kernels' layout (:mod:`planner.imdp.decoupled.operator`)."""
        (xp, xb, xl, xu), (yp, yb, yl, yu) = self.axes
        nx, ny = np.diff(xp), np.diff(yp)
        outer_x = nx <= ny
        # outer / inner axes as per-row CSR (rows keep their own choice), gathered from
        # the x entries followed by the y entries
        o_len = np.where(outer_x, nx, ny)
        i_len = np.where(outer_x, ny, nx)
        optr = np.concatenate(([0], np.cumsum(o_len))).astype(np.int64)
        iptr = np.concatenate(([0], np.cumsum(i_len))).astype(np.int64)
        o_src = np.where(outer_x, xp[:-1], xp[-1] + yp[:-1])
        i_src = np.where(outer_x, xp[-1] + yp[:-1], xp[:-1])
        o_idx = np.repeat(o_src - optr[:-1], o_len) + np.arange(optr[-1])
        i_idx = np.repeat(i_src - iptr[:-1], i_len) + np.arange(iptr[-1])
        bins, lows, ups = np.concatenate((xb, yb)), np.concatenate((xl, yl)), (xu, yu)
        ups = np.concatenate(ups)
        il = lows[i_idx]
        irem = 1.0 - np.add.reduceat(il, iptr[:-1])
        vptr, vval = vertices(
            optr, lows[o_idx], ups[o_idx], np.arange(self.n_rows, dtype=np.int64), self.tolerance
        )
        self.outer_x = outer_x
        self.layout = (
            outer_x,
            optr,
            bins[o_idx],
            vptr,
            vval,
            iptr,
            bins[i_idx],
            il,
            ups[i_idx] - il,
            irem,
            self.maps,
            self.row_map,
        )
        # vertex blocks per row: vptr counts values; the kernel steps by the row length
        self.width = int(max(np.max(i_len), 1))

    def successors(self) -> tuple[np.ndarray, np.ndarray]:
        """``(row, state)`` pairs of every possible successor, deduplicated and sorted by
        row then state: the graph of the best case. Row ``r`` reaches
        ``maps[row_map[r], b_x, b_y]`` for every ``x`` entry ``b_x`` and ``y`` entry ``b_y``
        of ``r`` with ``upper > 0`` (entry pairs enumerated as ``k = i * n_y(r) + j``)."""
        (xp, xb, _, xu), (yp, yb, _, yu) = self.axes
        n_x, n_y = np.diff(xp), np.diff(yp)
        size = n_x * n_y
        row = np.repeat(np.arange(self.n_rows, dtype=np.int64), size)
        k = np.arange(row.size, dtype=np.int64) - np.repeat(np.cumsum(size) - size, size)
        ix = xp[row] + k // n_y[row]
        iy = yp[row] + k % n_y[row]
        keep = (xu[ix] > 0.0) & (yu[iy] > 0.0)
        row, ix, iy = row[keep], ix[keep], iy[keep]
        state = self.maps[self.row_map[row], xb[ix], yb[iy]]
        key = np.unique(row * self.n_states + state)
        return key // self.n_states, key % self.n_states

    def expectation(self, values: np.ndarray, minimize: bool = True) -> np.ndarray:
        """The adversary's (min or max) expectation of ``values`` for every row."""
        return all_values(np.asarray(values, dtype=np.float64), minimize, self.layout, self.width)

    def __repr__(self) -> str:
        return f"DecoupledIMDP(states={self.n_states}, rows={self.n_rows})"
