"""Storm's explicit DRN format with interval values (``@value_type: double-interval``).

A state block is ``state s [labels...]`` followed by ``action NAME`` blocks whose lines are
``t : [lo, hi]`` (or ``t : p``, read as ``[p, p]``). The label ``init`` marks the initial
states. Reward annotations ``[r]`` on state or action lines are skipped when reading.
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

_TRANSITION = re.compile(r"^(\d+)\s*:\s*(?:\[\s*([^,\]]+)\s*,\s*([^\]]+)\])?\s*([^\s\]]*)$")


def write_drn(model: IMDP, path: str | os.PathLike[str]) -> None:
    """Write ``model`` as an interval MDP in DRN."""
    m = model
    init = np.zeros(m.n_states, dtype=bool)
    init[m.initial] = True

    def fill(f) -> None:
        f.write("// exported by hopnav\n@type: MDP\n@value_type: double-interval\n")
        f.write("@parameters\n\n@reward_models\n\n")
        f.write(f"@nr_states\n{m.n_states}\n@nr_choices\n{m.n_rows}\n@model\n")
        for s in range(m.n_states):
            labels = (["init"] if init[s] else []) + [
                p for p, on in zip(m.propositions, m.label_matrix[s], strict=True) if on
            ]
            f.write(f"state {s}{''.join(' ' + x for x in labels)}\n")
            for r in range(m.state_ptr[s], m.state_ptr[s + 1]):
                f.write(f"\taction {m.action_names[m.row_action[r]]}\n")
                for e in range(m.row_ptr[r], m.row_ptr[r + 1]):
                    f.write(
                        f"\t\t{m.successor[e]} : [{number(m.lower[e])}, {number(m.upper[e])}]\n"
                    )

    atomic_write(path, fill)


def read_drn(path: str | os.PathLike[str], action_names: tuple[str, ...] | None = None) -> IMDP:
    """Read a DRN file (interval or point values).

    Raises:
        ModelFormatError: a malformed line (file and line number in the message).
    """
    path = Path(path)
    n_states = None
    in_model = False
    section = None
    s_list, a_names, t_list, lo, up = [], [], [], [], []
    labels: list[set[str]] = []
    initial: list[int] = []
    state = action = None
    for no, text in lines(path):
        if text.startswith("//"):
            continue
        if text.startswith("@"):
            section = (text.split(":")[0].split() or ["@"])[0]
            if section == "@model":
                if n_states is None:
                    raise fail(path, no, "@model before @nr_states")
                in_model = True
            elif section == "@value_type":
                vt = text.split(":", 1)[1].strip() if ":" in text else ""
                if vt not in ("double-interval", "double", "interval"):
                    raise fail(path, no, f"unsupported value type {vt!r}")
            elif section == "@type":
                kind = text.split(":", 1)[1].strip() if ":" in text else ""
                if kind not in ("MDP", "DTMC"):
                    raise fail(path, no, f"unsupported model type {kind!r}")
            continue
        if not in_model:
            if section == "@nr_states":
                try:
                    n_states = int(text)
                except ValueError:
                    raise fail(path, no, f"expected a state count, got {text!r}") from None
                check_count(path, no, "states", n_states, MAX_STATES)
                labels = [set() for _ in range(n_states)]
            continue
        words = text.split()
        if words[0] == "state":
            try:
                state = int(words[1])
            except (IndexError, ValueError):
                raise fail(path, no, f"expected 'state <index> ...', got {text!r}") from None
            if not 0 <= state < n_states:
                raise fail(path, no, f"state {state} is not in [0, {n_states})")
            for w in words[2:]:
                if w.startswith("[") or w.endswith("]"):
                    continue  # a state reward
                if w == "init":
                    initial.append(state)
                else:
                    labels[state].add(w.strip('"'))
            action = None
        elif words[0] == "action":
            if state is None:
                raise fail(path, no, "action before the first state")
            action = words[1] if len(words) > 1 and not words[1].startswith("[") else "0"
        else:
            mt = _TRANSITION.match(text)
            if mt is None or state is None or action is None:
                raise fail(path, no, f"expected 'successor : [lo, hi]', got {text!r}")
            try:
                if mt.group(2) is not None:
                    lo.append(float(mt.group(2)))
                    up.append(float(mt.group(3)))
                else:
                    p = float(mt.group(4))
                    lo.append(p)
                    up.append(p)
            except ValueError:
                raise fail(path, no, f"cannot read the probability in {text!r}") from None
            s_list.append(state)
            a_names.append(action)
            t_list.append(check_index(path, no, "successor", int(mt.group(1)), n_states))
            if len(s_list) > MAX_ENTRIES:
                raise fail(path, no, f"more than {MAX_ENTRIES} transitions (the limit)")
    if n_states is None:
        raise fail(path, 1, "no @nr_states section")
    if action_names is None:
        action_names = tuple(dict.fromkeys(a_names))
    if len(action_names) > MAX_ACTIONS:
        raise fail(
            path, 1, f"{len(action_names)} action names, more than the limit of {MAX_ACTIONS}"
        )
    index = {n: i for i, n in enumerate(action_names)}
    unknown = [n for n in a_names if n not in index]
    if unknown:
        raise fail(path, 1, f"action {unknown[0]!r} not in {action_names}")
    return IMDP(
        n_states,
        s_list,
        [index[n] for n in a_names],
        t_list,
        lo,
        up,
        n_actions=max(len(action_names), 1),
        labels=labels,
        initial=initial or [0],
        action_names=action_names or ("a0",),
    )
