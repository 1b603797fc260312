"""Graphviz (DOT) text of a deterministic Rabin automaton."""

from __future__ import annotations

from planner.automaton import RabinAutomaton
from planner.ltl.boolean import cover


def _label(letters: list[int], props: tuple[str, ...]) -> str:
    if len(letters) == 1 << len(props):
        return "true"
    parts = []
    for mask, val in cover(letters, len(props)):
        lits = [("" if val >> b & 1 else "!") + p for b, p in enumerate(props) if mask >> b & 1]
        parts.append(" & ".join(lits) if lits else "true")
    return " | ".join(parts)


def _esc(text: str) -> str:
    return text.replace("\\", "\\\\").replace('"', '\\"')


def to_dot(automaton: RabinAutomaton, title: str | None = None) -> str:
    """DOT text: one node per state (its name and its pair memberships, ``+i`` for
    ``G_i`` and ``-i`` for ``B_i``), one edge per successor with a Boolean label."""
    a = automaton
    lines = [
        "digraph rabin {",
        "  rankdir=LR;",
        '  node [shape=box, style=rounded, fontname="monospace"];',
    ]
    if title is not None:
        lines.append(f'  label="{_esc(title)}"; labelloc=t;')
    lines.append('  init [shape=point, label=""];')
    lines.append(f"  init -> s{a.initial};")
    for s in a.states:
        acc = [f"+{i}" for i, p in enumerate(a.pairs) if s in p.good]
        acc += [f"-{i}" for i, p in enumerate(a.pairs) if s in p.bad]
        text = _esc(f"{s}: {a.state_names[s]}") + (f"\\n{{{' '.join(acc)}}}" if acc else "")
        lines.append(f'  s{s} [label="{text}"];')
    for s in a.states:
        groups: dict[int, list[int]] = {}
        for letter, t in enumerate(a.transitions[s].tolist()):
            groups.setdefault(t, []).append(letter)
        for t, letters in sorted(groups.items()):
            lines.append(f'  s{s} -> s{t} [label="{_esc(_label(letters, a.propositions))}"];')
    lines.append("}")
    return "\n".join(lines) + "\n"
