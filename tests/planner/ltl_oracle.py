"""Independent LTL semantics on lasso words, for tests only.

Shares no code with :mod:`planner.ltl`: formulas are plain tuples, e.g. ``("U", ("!",
("ap", "Haz")), ("ap", "Goal"))``, and are evaluated by fixpoint iteration on the positions
of lasso words ``u v^omega`` (position ``|u| + |v| - 1`` is followed by position ``|u|``).
Everything is vectorised over a batch of lassos of the same shape.
"""

from __future__ import annotations

import itertools

import numpy as np

PROPS = ("a", "b", "c")


def render(f: tuple) -> str:
    """Fully parenthesised text in the project's (Spot) syntax."""
    op = f[0]
    if op == "ap":
        return f[1]
    if op in ("true", "false"):
        return op
    if len(f) == 2:
        return f"({op} {render(f[1])})" if op != "!" else f"(!{render(f[1])})"
    return f"({render(f[1])} {op} {render(f[2])})"


def evaluate(f: tuple, letters: np.ndarray, loop_start: int) -> np.ndarray:
    """Truth of ``f`` at every position: bool array shaped like ``letters`` (N, length)."""
    n, length = letters.shape
    nxt = np.append(np.arange(1, length), loop_start)
    iters = length + 1

    def ev(g: tuple) -> np.ndarray:
        op = g[0]
        if op == "true":
            return np.ones((n, length), dtype=bool)
        if op == "false":
            return np.zeros((n, length), dtype=bool)
        if op == "ap":
            return (letters >> PROPS.index(g[1]) & 1).astype(bool)
        if op == "!":
            return ~ev(g[1])
        if op == "X":
            return ev(g[1])[:, nxt]
        if op in ("F", "G"):
            x = ev(g[1])
            z = np.zeros_like(x) if op == "F" else np.ones_like(x)
            for _ in range(iters):
                z = (x | z[:, nxt]) if op == "F" else (x & z[:, nxt])
            return z
        x, y = ev(g[1]), ev(g[2])
        if op == "&":
            return x & y
        if op == "|":
            return x | y
        if op == "->":
            return ~x | y
        if op == "<->":
            return x == y
        if op == "xor":
            return x != y
        least = op in ("U", "M")
        z = np.zeros_like(x) if least else np.ones_like(x)
        for _ in range(iters):
            if op in ("U", "W"):
                z = y | (x & z[:, nxt])
            else:  # R, M: y holds up to and including the first x
                z = y & (x | z[:, nxt])
        return z

    return ev(f)


def lasso_batches(shapes, n_props: int = 3):
    """``(letters, loop_start)`` for all lassos of each (prefix, loop) length shape."""
    n_letters = 1 << n_props
    for p, q in shapes:
        words = np.array(list(itertools.product(range(n_letters), repeat=p + q)), dtype=np.int64)
        yield words.reshape(-1, p + q), p


def automaton_accepts(table, initial, pairs, letters: np.ndarray, loop_start: int) -> np.ndarray:
    """Acceptance of a Rabin automaton (raw table/pairs) on a batch of lassos."""
    table = np.asarray(table)
    n_states = table.shape[0]
    s = np.full(letters.shape[0], initial)
    for i in range(loop_start):
        s = table[s, letters[:, i]]
    loop = letters[:, loop_start:]
    for _ in range(n_states):
        for i in range(loop.shape[1]):
            s = table[s, loop[:, i]]
    seen = np.zeros((letters.shape[0], n_states), dtype=bool)
    rows = np.arange(letters.shape[0])
    for _ in range(n_states):
        for i in range(loop.shape[1]):
            s = table[s, loop[:, i]]
            seen[rows, s] = True
    ok = np.zeros(letters.shape[0], dtype=bool)
    for good, bad in pairs:
        g = np.zeros(n_states, dtype=bool)
        b = np.zeros(n_states, dtype=bool)
        g[list(good)] = True
        b[list(bad)] = True
        ok |= (seen & g).any(axis=1) & ~(seen & b).any(axis=1)
    return ok
