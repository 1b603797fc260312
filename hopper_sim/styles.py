"""Colours of scenario labels, shared by the figures and the rerun recordings.

Colours are RGB in 0..255, in the style of the paper's Figure 4: initial region blue, goal
green, hazards red, optional regions ``A``/``B`` purple, weak hazards pink. Other labels get
colours from a fixed cycle, in the order of the scenario's labels.
"""

from __future__ import annotations

from collections.abc import Sequence

INITIAL_COLOR = (70, 120, 230)
LABEL_COLORS: dict[str, tuple[int, int, int]] = {
    "Goal": (60, 170, 75),
    "Haz": (215, 50, 45),
    "A": (120, 60, 170),
    "B": (175, 130, 215),
    "weak": (250, 175, 205),
}
_CYCLE = ((240, 160, 40), (40, 170, 170), (140, 100, 60), (120, 120, 120), (200, 200, 60))
TRAJECTORY_COLOR = (20, 20, 20)
LANDING_COLOR = (255, 140, 0)


def label_colors(
    labels: Sequence[str], goal: str = "Goal", hazard: str = "Haz"
) -> dict[str, tuple[int, int, int]]:
    """Colour of each label; the scenario's own goal and hazard labels get green and red."""
    out: dict[str, tuple[int, int, int]] = {}
    k = 0
    for label in labels:
        if label == goal:
            out[label] = LABEL_COLORS["Goal"]
        elif label == hazard:
            out[label] = LABEL_COLORS["Haz"]
        elif label in LABEL_COLORS:
            out[label] = LABEL_COLORS[label]
        else:
            out[label] = _CYCLE[k % len(_CYCLE)]
            k += 1
    return out


def draw_order(labels: Sequence[str], goal: str = "Goal", hazard: str = "Haz") -> list[str]:
    """Labels from background to foreground: the others, then goal, then hazard on top."""
    rest = [lab for lab in labels if lab not in (goal, hazard)]
    return rest + [lab for lab in (goal, hazard) if lab in labels]
