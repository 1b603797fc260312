"""PRISM's explicit interval-MDP files: ``.tra`` (transitions) and ``.lab`` (labels).

``.tra``: a header ``n_states n_choices n_transitions``, then one line per interval
``s c t [lo,hi] [action]`` with ``c`` the choice index local to ``s`` (0, 1, ...) and the
optional action name. ``.lab``: a header ``0="init" 1="name" ...`` and lines
``s: i j ...`` listing the label indices of state ``s``. A point value ``p`` is read as
``[p,p]``.
"""

from __future__ import annotations

import os
import re
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

_INTERVAL = re.compile(r"^\[\s*([^,\]]+)\s*,\s*([^\]]+)\s*\]$")


def write_prism(model: IMDP, tra_path: str | os.PathLike[str], lab_path=None) -> None:
    """Write ``model`` to ``tra_path`` and (default: same name, ``.lab``) ``lab_path``."""
    tra_path = Path(tra_path)
    lab_path = tra_path.with_suffix(".lab") if lab_path is None else Path(lab_path)
    m = model
    local = np.arange(m.n_rows) - m.state_ptr[m.row_state]

    def fill_tra(f) -> None:
        f.write(f"{m.n_states} {m.n_rows} {m.n_entries}\n")
        r = m.entry_row
        s, c, a = m.row_state[r], local[r], m.row_action[r]
        names = m.action_names
        for i in range(m.n_entries):
            f.write(
                f"{s[i]} {c[i]} {m.successor[i]} [{number(m.lower[i])},"
                f"{number(m.upper[i])}] {names[a[i]]}\n"
            )

    def fill_lab(f) -> None:
        names = ["init", *m.propositions]
        f.write(" ".join(f'{i}="{n}"' for i, n in enumerate(names)) + "\n")
        init = np.zeros(m.n_states, dtype=bool)
        init[m.initial] = True
        flags = np.column_stack([init, m.label_matrix])
        for s in np.flatnonzero(flags.any(axis=1)):
            f.write(f"{s}: " + " ".join(str(i) for i in np.flatnonzero(flags[s])) + "\n")

    atomic_write(tra_path, fill_tra)
    atomic_write(lab_path, fill_lab)


def read_prism(
    tra_path: str | os.PathLike[str],
    lab_path: str | os.PathLike[str] | None = None,
    action_names: tuple[str, ...] | None = None,
) -> IMDP:
    """Read a ``.tra`` file (and its ``.lab``, if it exists or is given).

    Actions: if the lines carry action names, they are mapped through ``action_names``
    (default: in order of first appearance); otherwise the local choice index is the action.

    Raises:
        ModelFormatError: a malformed line (file and line number in the message).
    """
    tra_path = Path(tra_path)
    it = lines(tra_path)
    try:
        no, head = next(it)
    except StopIteration:
        raise fail(tra_path, 1, "empty file, expected 'n_states n_choices n_transitions'") from None
    try:
        n_states, _, n_trans = (int(x) for x in head.split())
    except ValueError:
        raise fail(
            tra_path, no, f"expected 'n_states n_choices n_transitions', got {head!r}"
        ) from None
    check_count(tra_path, no, "states", n_states, MAX_STATES)
    check_count(tra_path, no, "transitions", n_trans, MAX_ENTRIES)
    s, c, t, lo, up, names = [], [], [], [], [], []
    for no, text in it:
        parts = text.split()
        if len(parts) >= 4 and parts[3].startswith("[") and not parts[3].endswith("]"):
            j = next((k for k in range(4, len(parts)) if parts[k].endswith("]")), None)
            if j is not None:
                parts = [*parts[:3], "".join(parts[3 : j + 1]), *parts[j + 1 :]]
        if len(parts) not in (4, 5):
            raise fail(tra_path, no, f"expected 's c t [lo,hi] [action]', got {text!r}")
        try:
            ids = (int(parts[0]), int(parts[1]), int(parts[2]))
            m = _INTERVAL.match(parts[3])
            if m:
                lo.append(float(m.group(1)))
                up.append(float(m.group(2)))
            else:
                p = float(parts[3])
                lo.append(p)
                up.append(p)
        except ValueError:
            raise fail(tra_path, no, f"cannot read numbers in {text!r}") from None
        s.append(check_index(tra_path, no, "state", ids[0], n_states))
        c.append(check_index(tra_path, no, "choice", ids[1], MAX_ACTIONS))
        t.append(check_index(tra_path, no, "successor", ids[2], n_states))
        names.append(parts[4] if len(parts) == 5 else None)
        if len(s) > n_trans:
            raise fail(tra_path, no, f"more transitions than the {n_trans} of the header")
    if len(s) != n_trans:
        raise fail(tra_path, 1, f"header announces {n_trans} transitions, file has {len(s)}")
    if any(n is not None for n in names):
        if any(n is None for n in names):
            raise fail(tra_path, 2, "some lines carry an action name and others do not")
        if action_names is None:
            action_names = tuple(dict.fromkeys(names))
        index = {n: i for i, n in enumerate(action_names)}
        unknown = [n for n in names if n not in index]
        if unknown:
            raise fail(tra_path, 2, f"action {unknown[0]!r} not in {action_names}")
        actions = [index[n] for n in names]
        n_actions = len(action_names)
    else:
        actions = c
        n_actions = max(c) + 1 if c else 1
        action_names = None
    labels, initial = None, [0]
    if lab_path is None and tra_path.with_suffix(".lab").exists():
        lab_path = tra_path.with_suffix(".lab")
    props = None
    if lab_path is not None:
        labels, initial, props = read_lab(lab_path, n_states)
    return IMDP(
        n_states,
        s,
        actions,
        t,
        lo,
        up,
        n_actions=n_actions,
        labels=labels,
        propositions=props,
        initial=initial,
        action_names=action_names,
    )


def read_lab(path: str | os.PathLike[str], n_states: int):
    """Read a ``.lab`` file: ``(labels per state, initial states, propositions)``."""
    it = lines(path)
    try:
        no, head = next(it)
    except StopIteration:
        raise fail(path, 1, "empty label file") from None
    decl = re.findall(r'(\d+)="([^"]*)"', head)
    if not decl:
        raise fail(path, no, f'expected declarations like 0="init", got {head!r}')
    names = {int(i): n for i, n in decl}
    labels: list[set[str]] = [set() for _ in range(n_states)]
    initial = []
    for no, text in it:
        state, _, rest = text.partition(":")
        try:
            s = int(state)
            idx = [int(x) for x in rest.split()]
        except ValueError:
            raise fail(path, no, f"expected 's: i j ...', got {text!r}") from None
        if not 0 <= s < n_states:
            raise fail(path, no, f"state {s} is not in [0, {n_states})")
        for i in idx:
            if i not in names:
                raise fail(path, no, f"label index {i} is not declared")
            if names[i] == "init":
                initial.append(s)
            elif names[i] != "deadlock":
                labels[s].add(names[i])
    props = tuple(n for _, n in sorted(names.items()) if n not in ("init", "deadlock"))
    return labels, (initial or [0]), props
