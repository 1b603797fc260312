"""Deterministic Rabin automata (DRA) over the alphabet 2^AP.

A DRA is ``R = (S, s0, 2^AP, delta, F)`` with ``F = {(G_1, B_1), ..., (G_n, B_n)}``. This
type is *complete* and *state-based*: ``delta`` is a total function ``S x 2^AP -> S`` stored
as an integer table, and a run ``s_0 s_1 ...`` is accepting iff for some pair ``i``

    inf(run) ∩ G_i ≠ ∅   and   inf(run) ∩ B_i = ∅,

where ``inf(run)`` is the set of states visited infinitely often (the paper's convention:
``G`` good, visited infinitely often; ``B`` bad, visited finitely often).

Letters are encoded as bitmasks: bit ``i`` of a letter is set iff ``propositions[i]`` holds.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from planner.errors import AutomatonError, UnknownPropositionError

Letter = int
Word = Sequence[Iterable[str]]


@dataclass(frozen=True)
class RabinPair:
    """One Rabin pair: ``good`` must be visited infinitely often, ``bad`` finitely often."""

    good: frozenset[int]
    bad: frozenset[int]


class RabinAutomaton:
    """A complete deterministic state-based Rabin automaton.

    Args:
        propositions: atomic proposition names; their order fixes the letter bit order.
        transitions: integer array of shape ``(n_states, 2 ** len(propositions))``;
            ``transitions[s, letter]`` is the successor of ``s`` on ``letter``.
        initial: the initial state.
        pairs: the Rabin pairs ``(G_i, B_i)``.
        state_names: optional human-readable state names (for HOA/dot output).

    Raises:
        AutomatonError: on a malformed table, initial state or pair.
    """

    def __init__(
        self,
        propositions: Sequence[str],
        transitions: np.ndarray,
        initial: int,
        pairs: Iterable[RabinPair | tuple[Iterable[int], Iterable[int]]],
        state_names: Sequence[str] | None = None,
    ) -> None:
        props = tuple(str(p) for p in propositions)
        if len(set(props)) != len(props):
            raise AutomatonError(f"duplicate propositions in {props}")
        table = np.asarray(transitions)
        if table.ndim != 2 or table.shape[1] != 2 ** len(props):
            raise AutomatonError(
                f"transition table must have shape (n_states, {2 ** len(props)}) for "
                f"{len(props)} propositions, got {table.shape}"
            )
        if table.shape[0] == 0:
            raise AutomatonError("an automaton needs at least one state")
        if not np.issubdtype(table.dtype, np.integer):
            raise AutomatonError(f"transition table must be integer, got {table.dtype}")
        n = table.shape[0]
        bad = np.argwhere((table < 0) | (table >= n))
        if bad.size:
            s, letter = bad[0]
            raise AutomatonError(
                f"transition from state {s} on letter {letter} goes to {table[s, letter]}, "
                f"not a state in [0, {n})"
            )
        if not 0 <= int(initial) < n:
            raise AutomatonError(f"initial state {initial} is not a state in [0, {n})")
        norm_pairs: list[RabinPair] = []
        for i, pair in enumerate(pairs):
            g, b = (pair.good, pair.bad) if isinstance(pair, RabinPair) else pair
            g, b = frozenset(int(x) for x in g), frozenset(int(x) for x in b)
            out = [x for x in g | b if not 0 <= x < n]
            if out:
                raise AutomatonError(f"Rabin pair {i} names states {sorted(out)} not in [0, {n})")
            norm_pairs.append(RabinPair(g, b))
        if state_names is not None and len(state_names) != n:
            raise AutomatonError(f"{len(state_names)} state names for {n} states")
        self.propositions: tuple[str, ...] = props
        self.transitions: np.ndarray = table.astype(np.int64, copy=True)
        self.transitions.setflags(write=False)
        self.initial: int = int(initial)
        self.pairs: tuple[RabinPair, ...] = tuple(norm_pairs)
        self.state_names: tuple[str, ...] = (
            tuple(state_names) if state_names is not None else tuple(str(s) for s in range(n))
        )

    @property
    def n_states(self) -> int:
        return int(self.transitions.shape[0])

    @property
    def states(self) -> range:
        return range(self.n_states)

    @property
    def n_letters(self) -> int:
        return int(self.transitions.shape[1])

    def letter(self, true_props: Iterable[str]) -> Letter:
        """Bitmask of a set of true propositions.

        Raises:
            UnknownPropositionError: if a name is not one of :attr:`propositions`.
        """
        index = {p: i for i, p in enumerate(self.propositions)}
        mask = 0
        for p in true_props:
            if p not in index:
                raise UnknownPropositionError(
                    f"proposition {p!r} is not in the automaton's alphabet {self.propositions}"
                )
            mask |= 1 << index[p]
        return mask

    def step(self, state: int, true_props: Iterable[str]) -> int:
        """``delta(state, {true_props})``."""
        return int(self.transitions[state, self.letter(true_props)])

    def run(self, word: Word, start: int | None = None) -> list[int]:
        """States ``s_0 ... s_n`` visited while reading ``word`` (``s_0`` = start or initial)."""
        s = self.initial if start is None else int(start)
        states = [s]
        for props in word:
            s = self.step(s, props)
            states.append(s)
        return states

    def is_accepting_cycle(self, cycle_states: Iterable[int]) -> bool:
        """Whether a run whose infinitely-often set is ``cycle_states`` is accepting."""
        inf = set(cycle_states)
        return any(inf & p.good and not inf & p.bad for p in self.pairs)

    def accepts(self, prefix: Word, loop: Word) -> bool:
        """Whether the lasso word ``prefix loop^omega`` is accepted.

        Raises:
            AutomatonError: if ``loop`` is empty.
        """
        loop_letters = [self.letter(p) for p in loop]
        if not loop_letters:
            raise AutomatonError("the loop of a lasso word must be non-empty")
        s = self.run(prefix)[-1]
        seen: dict[int, int] = {}
        visits: list[list[int]] = []
        while s not in seen:
            seen[s] = len(visits)
            block = []
            for letter in loop_letters:
                s = int(self.transitions[s, letter])
                block.append(s)
            visits.append(block)
        inf = {x for block in visits[seen[s] :] for x in block}
        return self.is_accepting_cycle(inf)

    def __repr__(self) -> str:
        return (
            f"RabinAutomaton(states={self.n_states}, propositions={self.propositions}, "
            f"pairs={len(self.pairs)})"
        )
