"""The sweeps' layout of a worst-case maximal reachability problem built on a guess of its
free states, while the graph searches that decide them run on a second thread.

The free states of ``(!avoid) U target`` are those that reach the target with positive
probability against every adversary and not with probability 1
(:func:`planner.imdp.graph.robust_positive_reach`,
:func:`planner.imdp.graph.robust_almost_sure_reach`). The guess: they are the states that
can reach the target at all (a path of ``upper > 0`` entries avoiding ``avoid``). It holds
where every such state reaches the target with positive probability against every
adversary and none almost surely: on the benchmarks of ``benchmarks/bench_vi.py`` (grid
seeds 0-2 and the random model).

On a large model (:data:`GUESS_ENTRIES`) the searches run on the ``"layout"`` worker while
the calling thread builds the layout on the guess and starts the sweeps; each sweep first
looks whether the searches have ended (:meth:`Guess.check`), and the solve confirms the
guess before it returns (:meth:`Guess.confirm`). Where the guess fails, :class:`GuessFailed`
abandons the sweeps, and the solve starts again from the searches' states. The searches
then overlap the sweeps, whose light sweeps leave the second core idle, instead of the
layout alone (on the random benchmark model the layout, 45 ms, and the searches, 45 ms,
ran side by side before the first sweep). The values do not depend on when the searches
end: with the guess right they are those of the sweeps on the searches' states, which are
the same states; with it wrong, those of the solve started again.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future

import numpy as np

from planner._util.threads import worker
from planner.imdp.kernels import ReachSweeper, layers
from planner.imdp.model import IMDP

GUESS_ENTRIES = 100_000
"""Entries of a model from which the sweeps' layout is built on a guess while the graph
searches of the settled states run (:class:`Guess`)."""

Searched = tuple[np.ndarray, np.ndarray, np.ndarray]
"""The graph searches' outcome: ``(positive, almost_sure, choice)``, the states of
positive worst-case probability, those of probability 1 and their rows to the target."""


class GuessFailed(Exception):
    """The guessed free states were not the solve's; ``searched`` holds the searches'
    outcome for the solve that starts again."""

    def __init__(self, searched: Searched) -> None:
        super().__init__("the guessed free states were not the solve's")
        self.searched = searched


class Guess:
    """The guessed free states (a mask), their sweeps' layout, and the searches running
    meanwhile. Start with :meth:`start`."""

    def __init__(
        self,
        free: np.ndarray,
        layout: ReachSweeper,
        searches: Future,
        target: np.ndarray,
        avoid: np.ndarray,
    ) -> None:
        self.free, self.layout, self._searches = free, layout, searches
        self._target, self._avoid = target, avoid
        self._choice: np.ndarray | None = None

    @classmethod
    def start(
        cls,
        m: IMDP,
        rows: np.ndarray,
        target: np.ndarray,
        avoid: np.ndarray,
        searches: Callable[[], Searched],
    ) -> Guess:
        """``searches()`` on the ``"layout"`` worker, and meanwhile the layout of the
        guessed free states here: each has an allowed row, so the mask compares as it is
        with the solve's free states, ``positive & ~target & ~avoid``."""
        m.reverse_index()  # built once, before both threads read it
        future = worker("layout").submit(searches)
        try:
            candidates = np.flatnonzero(rows & ~(target | avoid)[m.row_state])
            dist = layers(m, candidates, target)
            reach = np.isfinite(dist) & ~target
            free = candidates[reach[m.row_state[candidates]]]
            layout = ReachSweeper(m, free, dist, True, True)
        except BaseException:
            future.exception()  # the searches end before the error leaves
            raise
        guess = cls(reach, layout, future, target, avoid)
        layout.before_sweep = guess.check
        return guess

    @property
    def settled(self) -> tuple[np.ndarray, np.ndarray]:
        """``(settled, value)`` as the guess has them: every state but the free ones
        settled, the targets at 1 and the others at 0."""
        return ~self.free, np.where(self._target, 1.0, 0.0)

    def done(self) -> bool:
        """Whether the searches have ended."""
        return self._searches.done()

    def confirm(self) -> np.ndarray:
        """The settled states' rows once the searches have ended (waiting for them), where
        the guess holds; else :class:`GuessFailed`."""
        self.layout.before_sweep = None
        if self._choice is not None:
            return self._choice
        searched = self._searches.result()
        pos, prob1, choice = searched
        if np.any(prob1 & ~self._target) or not np.array_equal(
            self.free, pos & ~self._target & ~self._avoid
        ):
            raise GuessFailed(searched)
        self._choice = np.where(prob1, choice, -1)
        return self._choice

    def check(self) -> None:
        """Before each sweep: once the searches have ended, :meth:`confirm` (raising
        :class:`GuessFailed` where the guess fails)."""
        if self.done():
            self.confirm()
