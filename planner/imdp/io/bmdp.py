"""bmdp-tool's text format.

``n_states``, ``n_actions``, ``n_terminal`` on the first three lines, then the terminal
states one per line, then one line ``s a t lo hi`` per interval. There are no labels: the
terminal states are read back with the label ``terminal``; a state without transitions
(typically a terminal one) is given an absorbing self-loop on action 0.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from planner.imdp.io._common import (
    MAX_ACTIONS,
    MAX_ENTRIES,
    MAX_STATES,
    atomic_write,
    check_count,
    check_index,
    fail,
    lines,
    number,
)
from planner.imdp.model import IMDP

TERMINAL = "terminal"


def write_bmdp(model: IMDP, path: str | os.PathLike[str], terminal: np.ndarray) -> None:
    """Write ``model`` with the boolean state mask ``terminal`` (e.g. the target states)."""
    m = model
    term = np.flatnonzero(np.asarray(terminal, dtype=bool))

    def fill(f) -> None:
        f.write(f"{m.n_states}\n{m.n_actions}\n{term.size}\n")
        for s in term:
            f.write(f"{s}\n")
        s, a = m.row_state[m.entry_row], m.row_action[m.entry_row]
        for i in range(m.n_entries):
            f.write(f"{s[i]} {a[i]} {m.successor[i]} {number(m.lower[i])} {number(m.upper[i])}\n")

    atomic_write(path, fill)


def read_bmdp(path: str | os.PathLike[str]) -> IMDP:
    """Read a bmdp-tool file; terminal states carry the label ``terminal``.

    Raises:
        ModelFormatError: a malformed line (file and line number in the message).
    """
    path = Path(path)
    it = lines(path)
    head = []
    limits = (MAX_STATES, MAX_ACTIONS, MAX_STATES)
    no = 0
    for what, limit in zip(
        ("number of states", "number of actions", "number of terminal states"), limits, strict=True
    ):
        try:
            no, text = next(it)
        except StopIteration:
            raise fail(path, no + 1, f"missing the {what}") from None
        try:
            value = int(text)
        except ValueError:
            raise fail(path, no, f"expected the {what}, got {text!r}") from None
        head.append(check_count(path, no, what, value, limit))
    n, n_act, n_term = head
    terminal = []
    for _ in range(n_term):
        try:
            no, text = next(it)
        except StopIteration:
            raise fail(path, no + 1, "missing terminal states") from None
        try:
            value = int(text)
        except ValueError:
            raise fail(path, no, f"expected a terminal state, got {text!r}") from None
        terminal.append(check_index(path, no, "terminal state", value, n))
    s, a, t, lo, up = [], [], [], [], []
    for no, text in it:
        parts = text.split()
        if len(parts) != 5:
            raise fail(path, no, f"expected 's a t lo hi', got {text!r}")
        try:
            ids = (int(parts[0]), int(parts[1]), int(parts[2]))
            bounds = (float(parts[3]), float(parts[4]))
        except ValueError:
            raise fail(path, no, f"cannot read numbers in {text!r}") from None
        s.append(check_index(path, no, "state", ids[0], n))
        a.append(check_index(path, no, "action", ids[1], max(n_act, 1)))
        t.append(check_index(path, no, "successor", ids[2], n))
        lo.append(bounds[0])
        up.append(bounds[1])
        if len(s) > MAX_ENTRIES:
            raise fail(path, no, f"more than {MAX_ENTRIES} transitions (the limit)")
    has = np.zeros(n, dtype=bool)
    src = np.asarray(s, dtype=np.int64)
    has[src[(src >= 0) & (src < n)]] = True
    loops = np.flatnonzero(~has)
    labels = [set() for _ in range(n)]
    for x in terminal:
        labels[x].add(TERMINAL)
    return IMDP(
        n,
        np.concatenate([src, loops]),
        np.concatenate([np.asarray(a, dtype=np.int64), np.zeros(loops.size, np.int64)]),
        np.concatenate([np.asarray(t, dtype=np.int64), loops]),
        np.concatenate([np.asarray(lo, dtype=float), np.ones(loops.size)]),
        np.concatenate([np.asarray(up, dtype=float), np.ones(loops.size)]),
        n_actions=max(n_act, 1),
        labels=labels,
        propositions=(TERMINAL,),
    )
