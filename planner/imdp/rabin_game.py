"""The almost-sure winning region of a Rabin condition on an interval MDP, as a game:
Zielonka's recursive algorithm on the condition's Zielonka tree, adapted to the interval
game (step 1 of :mod:`planner.imdp.rabin`): the controller wins almost surely, the adversary
plays for positive probability of losing."""

from __future__ import annotations

import numpy as np

from planner.imdp import graph
from planner.imdp.kernels import attractor, counting_order, drop_states, rows_staying_in
from planner.imdp.model import IMDP, first_of_runs


class _Game:
    """The interval game of a model with a Rabin condition: its arrays, the reverse index
    of the entries, and the attractors of a sub-game ``(region, rows_ok, entry_ok)``.

    A sub-game keeps a set of states, the rows available there and the entries allowed
    in those rows; the invariant is that every available row's polytope restricted to its
    allowed entries is non-empty (the ``lower > 0`` entries are allowed and the allowed
    upper bounds sum to at least 1, exactly), so every run stays in the region.
    """

    def __init__(self, model: IMDP, good: np.ndarray, bad: np.ndarray) -> None:
        self.m = model
        self.good = np.asarray(good, dtype=bool).reshape(-1, model.n_states)
        self.bad = np.asarray(bad, dtype=bool).reshape(-1, model.n_states)
        # the model's reverse index (and, on demand, the entries' order in it)
        self.inc_ptr, self.inc_row, self.inc_state, _, _ = model.reverse_index()
        self._order: np.ndarray | None = None

    # -- colours
    def accepting(self, region: np.ndarray, won: np.ndarray) -> bool:
        if (won & region).any():
            return True
        g = (self.good & region).any(axis=1)
        b = (self.bad & region).any(axis=1)
        return bool((g & ~b).any())

    def may_win(self, region: np.ndarray, won: np.ndarray) -> bool:
        """Whether :meth:`solve` of a sub-game on ``region`` can win anything: it holds a
        ``won`` state or a state of some ``G_i`` outside ``B_i`` (else the game is lost
        from every state of it, without looking at its rows)."""
        if (won & region).any():
            return True
        return bool((self.good & ~self.bad & region).any())

    def max_rejecting(self, region: np.ndarray, won: np.ndarray) -> np.ndarray:
        """States of ``region`` whose colours lie in the largest rejecting colour subset
        (unique: Rabin-rejecting sets are closed under union)."""
        z = region & ~won
        while True:
            g = (self.good & z).any(axis=1)
            b = (self.bad & z).any(axis=1)
            sat = g & ~b
            if not sat.any():
                return z
            z = z & ~self.good[sat].any(axis=0)

    # -- attractors (``entry_ok=None``: every entry allowed)
    def _eff(self, entry_ok: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """Lower and upper bounds with the disallowed entries zeroed, in entry order and in
        the reverse index's order."""
        m = self.m
        if entry_ok is None:
            _, _, inc_lo, inc_up = m.incoming()
            return m.lower, m.upper, inc_lo, inc_up
        if self._order is None:
            self._order, _ = counting_order(m.successor, m.n_states)
        lo = np.where(entry_ok, m.lower, 0.0)
        up = np.where(entry_ok, m.upper, 0.0)
        return lo, up, lo[self._order], up[self._order]

    def controller_attractor(
        self, region, rows_ok, entry_ok, start
    ) -> tuple[np.ndarray, np.ndarray]:
        m = self.m
        lo, up, inc_lo, inc_up = self._eff(entry_ok)
        cand = rows_ok & region[m.row_state] & ~start[m.row_state]
        x, choice, _ = attractor(
            start & region,
            cand,
            m.row_state,
            m.row_ptr,
            m.successor,
            lo,
            up,
            self.inc_ptr,
            self.inc_row,
            self.inc_state,
            inc_lo,
            inc_up,
            False,
            True,
        )
        return x & region, choice

    def adversary_attractor(self, region, rows_ok, entry_ok, won, start) -> np.ndarray:
        """States of ``region`` from which the adversary reaches ``start`` with positive
        probability whatever the controller does: every available row has an allowed
        ``upper > 0`` entry into the set; ``won`` states (absorbing) join only if in
        ``start``. The pruning cascade from ``start`` (a state joins once no row is left
        that avoids the set)."""
        m = self.m
        _, _, _, inc_up = self._eff(entry_ok)
        rows = rows_ok & region[m.row_state]
        live = np.bincount(m.row_state[rows], minlength=m.n_states)
        member = np.zeros(m.n_states, dtype=bool)
        index = (m.row_state, m.state_ptr, self.inc_ptr, self.inc_row, inc_up)
        drop_states(np.flatnonzero(start & region), member, rows, live, *index, won)
        return member

    def closed_rows(self, region, rows_ok, entry_ok) -> np.ndarray:
        m = self.m
        _, up, _, _ = self._eff(entry_ok)
        none = np.zeros(m.n_states, dtype=bool)
        return rows_staying_in(region, rows_ok, m.row_state, m.row_ptr, m.successor, up, none)

    # -- Zielonka
    def solve(
        self,
        region: np.ndarray,
        rows_ok: np.ndarray,
        entry_ok: np.ndarray,
        won: np.ndarray,
        strategy: np.ndarray,
    ) -> np.ndarray:
        """The controller's almost-sure winning region of the sub-game; writes a winning
        row into ``strategy`` for its states."""
        m = self.m
        region = region.copy()
        won = won & region
        while region.any():
            if self.accepting(region, won):
                u = region & ~self.max_rejecting(region, won)
                a, choice = self.controller_attractor(region, rows_ok, entry_ok, u)
                h = region & ~a
                if self.may_win(h, won & h):
                    # the adversary can keep the run in h: restrict the entries to it
                    rows_h = rows_ok & h[m.row_state]
                    inside = h[m.successor] & rows_h[m.entry_row]
                    entry_h = inside if entry_ok is None else entry_ok & inside
                    w_h = self.solve(h, rows_h, entry_h, won & h, strategy)
                else:
                    w_h = np.zeros_like(h)
                if np.array_equal(w_h, h):
                    att = a & ~u & (choice >= 0)
                    strategy[att] = choice[att]
                    rest = np.flatnonzero(u & ~won)
                    if rest.size:
                        avail = np.flatnonzero(rows_ok & u[m.row_state] & ~won[m.row_state])
                        first = avail[first_of_runs(m.row_state[avail])]
                        strategy[m.row_state[first]] = first
                    return region
                lose = self.adversary_attractor(region, rows_ok, entry_ok, won, h & ~w_h)
                region &= ~lose
                won &= region
                rows_ok = self.closed_rows(region, rows_ok, entry_ok)
                continue
            grew = False
            for i in range(self.good.shape[0]):
                if not (self.good[i] & ~self.bad[i] & region).any():
                    continue
                bad = self.adversary_attractor(region, rows_ok, entry_ok, won, self.bad[i] & region)
                y = region & ~bad
                if not y.any():
                    continue
                rows_y = self.closed_rows(y, rows_ok, entry_ok)
                w_y = self.solve(y, rows_y, entry_ok, won & y, strategy)
                if w_y.any():
                    won = won | w_y
                    grew = True
                    break
            if not grew:
                return np.zeros_like(region)
        return region


def almost_sure_region(
    model: IMDP,
    good: np.ndarray,
    bad: np.ndarray,
    rows: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """States from which the controller satisfies the Rabin condition with probability 1
    against every adversary, and a memoryless strategy that does.

    Args:
        model: the (product) interval MDP.
        good, bad: ``(n_pairs, n_states)`` masks of the pairs' ``G_i`` and ``B_i``.
        rows: optional row mask of the controller's allowed rows.

    Returns:
        ``(mask, row)``: the region and, per state of it, a row (-1 elsewhere).
    """
    m = model
    game = _Game(m, good, bad)
    rows_ok = np.ones(m.n_rows, dtype=bool) if rows is None else np.asarray(rows, bool).copy()
    region = graph.has_row(m, rows_ok)
    # states without an allowed row take no part (a run there is stopped: losing); only
    # then can a row leave the region and need dropping
    outside = ~region
    if outside.any():
        lose = game.adversary_attractor(
            np.ones(m.n_states, bool), rows_ok, None, np.zeros(m.n_states, bool), outside
        )
        region &= ~lose
        rows_ok = game.closed_rows(region, rows_ok, None)
    strategy = np.full(m.n_states, -1, dtype=np.int64)
    win = game.solve(region, rows_ok, None, np.zeros(m.n_states, bool), strategy)
    strategy[~win] = -1
    return win, strategy
