"""Numbering the states of an automaton while exploring it breadth first."""

from __future__ import annotations

from collections.abc import Hashable
from typing import TypeVar

from planner.ltl.budget import count_state, tick

K = TypeVar("K", bound=Hashable)


def intern(key: K, index: dict[K, int], keys: list[K]) -> int:
    """The number of ``key``: its position in ``keys``, appending it (and recording it in
    ``index``) when it is new, so that the explorer visits it later. Each call is a step of
    the translation's budget (:mod:`planner.ltl.budget`), each new key a state."""
    j = index.get(key)
    if j is None:
        j = len(keys)
        index[key] = j
        keys.append(key)
        count_state(len(keys))
    tick()
    return j
