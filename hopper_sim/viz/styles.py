"""Colours, letters and legend text of scenario regions, shared by figures and recordings.

The classes follow the paper's Figure 4: initial region blue, goal green, hazards red, optional
regions ``A`` (dark) and ``B`` (light) purple, weak hazards pink. The exact shades are
colour-blind-safe variants: they were chosen by a random search (in HLS, within each paper hue)
that maximises the smallest CIELAB distance (Delta E 1976) between any two of them, white and
the route colours, under normal vision and under simulated protanopia, deuteranopia and
tritanopia (:func:`simulate_cvd`, Machado, Oliveira and Fernandes 2009, severity 1). The
smallest such distance is about 21 (``tests/hopper_sim/test_styles.py`` checks it is at least
20). Colours alone never carry a class: every region also gets a letter
(:func:`region_letters`) drawn on the map and in the legend. Other labels take colours from a
fixed cycle, in the order of the scenario's labels.

Colours are RGB in 0..255.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from planner.modes import Phase

if TYPE_CHECKING:
    from planner.scenario import Scenario

Rgb = tuple[int, int, int]


def hex_rgb(text: str) -> Rgb:
    """``"#RRGGBB"`` -> ``(r, g, b)``."""
    s = text.lstrip("#")
    return (int(s[0:2], 16), int(s[2:4], 16), int(s[4:6], 16))


INITIAL_COLOR: Rgb = hex_rgb("#1A58E1")
GOAL_COLOR: Rgb = hex_rgb("#2B9752")
HAZARD_COLOR: Rgb = hex_rgb("#BE3828")
LABEL_COLORS: dict[str, Rgb] = {
    "Goal": GOAL_COLOR,
    "Haz": HAZARD_COLOR,
    "A": hex_rgb("#8D1E9B"),
    "B": hex_rgb("#CB89D0"),
    "weak": hex_rgb("#FE9AA5"),
}
"""Colours of the paper's label names (a scenario's own goal/hazard labels get green/red)."""

_CYCLE: tuple[Rgb, ...] = tuple(
    hex_rgb(c) for c in ("#88CCEE", "#44AA99", "#999933", "#BBBBBB", "#882255", "#AA7744")
)

PHASE_COLORS: dict[str, Rgb] = {
    Phase.EXPLORATION: hex_rgb("#EFD643"),
    Phase.GOAL_REACHING: (0, 0, 0),
    Phase.FALLBACK: hex_rgb("#00A0B0"),
}
"""Route colours per phase: exploration yellow, goal reaching black, fallback teal (dashed)."""

PHASE_NAMES: dict[str, str] = {
    Phase.EXPLORATION: "exploration",
    Phase.GOAL_REACHING: "goal reaching",
    Phase.FALLBACK: "fallback",
}
PHASE_CODES: dict[str, float] = {
    Phase.EXPLORATION: 0.0,
    Phase.GOAL_REACHING: 1.0,
    Phase.FALLBACK: 2.0,
}
"""Numeric codes of the phases in time-series plots."""

WHITE: Rgb = (255, 255, 255)
_COLOR_NAMES: dict[Rgb, str] = {
    INITIAL_COLOR: "blue",
    GOAL_COLOR: "green",
    HAZARD_COLOR: "red",
    LABEL_COLORS["A"]: "dark purple",
    LABEL_COLORS["B"]: "light purple",
    LABEL_COLORS["weak"]: "pink",
    PHASE_COLORS[Phase.EXPLORATION]: "yellow",
    PHASE_COLORS[Phase.GOAL_REACHING]: "black",
    PHASE_COLORS[Phase.FALLBACK]: "teal",
    **dict(
        zip(_CYCLE, ("light blue", "teal green", "olive", "grey", "wine", "brown"), strict=True)
    ),
}


def color_name(color: Sequence[int]) -> str:
    """A word for one of the palette's colours (``#rrggbb`` for any other)."""
    rgb = tuple(int(c) for c in color)
    return _COLOR_NAMES.get(rgb, "#{:02x}{:02x}{:02x}".format(*rgb))  # type: ignore[arg-type]


GRID_COLOR: Rgb = (190, 190, 190)
INITIAL_LETTER = "I"


def label_colors(labels: Sequence[str], goal: str = "Goal", hazard: str = "Haz") -> dict[str, Rgb]:
    """Colour of each label; the scenario's own goal and hazard labels get green and red."""
    out: dict[str, Rgb] = {}
    k = 0
    for label in labels:
        if label == goal:
            out[label] = GOAL_COLOR
        elif label == hazard:
            out[label] = HAZARD_COLOR
        elif label in LABEL_COLORS and label not in ("Goal", "Haz"):
            out[label] = LABEL_COLORS[label]
        else:
            out[label] = _CYCLE[k % len(_CYCLE)]
            k += 1
    return out


def draw_order(labels: Sequence[str], goal: str = "Goal", hazard: str = "Haz") -> list[str]:
    """Labels from background to foreground: the others, then goal, then hazard on top."""
    rest = [lab for lab in labels if lab not in (goal, hazard)]
    return rest + [lab for lab in (goal, hazard) if lab in labels]


def region_letters(labels: Sequence[str]) -> dict[str, str]:
    """A short, unique code per label, drawn on its regions: the label's first letter in
    upper case (``Haz`` -> ``H``, ``weak`` -> ``W``), else its first two letters, else the
    whole label. ``I`` is kept for the initial region."""
    taken = {INITIAL_LETTER}
    out: dict[str, str] = {}
    for label in labels:
        for code in (label[:1].upper(), label[:1].upper() + label[1:2].lower(), label):
            if code and code not in taken:
                break
        else:
            code = f"{label}{len(out)}"
        taken.add(code)
        out[label] = code
    return out


def role(scenario: Scenario, label: str) -> str:
    """What a label is to the tasks: ``goal`` or ``hazard`` (the LTL task's labels), else by
    its reward ``optional task`` (positive), ``penalty`` (negative) or ``label`` (none)."""
    if label == scenario.goal:
        return "goal"
    if label == scenario.hazard:
        return "hazard"
    reward = float(scenario.rewards.get(label, 0.0))
    return "optional task" if reward > 0 else "penalty" if reward < 0 else "label"


def format_reward(reward: float) -> str:
    """``+20``, ``-0.5``, ``0``."""
    return f"{reward:+g}" if reward else "0"


def legend_entries(scenario: Scenario) -> list[tuple[str, str, Rgb]]:
    """``(letter, text, colour)`` of every region class of ``scenario``: the initial region,
    the goal, the hazard, then the other labels in the scenario's order; the text names the
    label, its role and its reward (``"A: optional task, reward +20"``). Labels without cells
    are left out."""
    letters = region_letters(scenario.labels)
    colors = label_colors(scenario.labels, scenario.goal, scenario.hazard)
    out = [(INITIAL_LETTER, "initial region", INITIAL_COLOR)]
    order = [scenario.goal, scenario.hazard]
    order += [lab for lab in scenario.labels if lab not in order]
    for label in order:
        if label not in letters or not scenario.region_mask(label).any():
            continue
        reward = float(scenario.rewards.get(label, 0.0))
        text = f"{label}: {role(scenario, label)}, reward {format_reward(reward)}"
        out.append((letters[label], text, colors[label]))
    return out


def region_components(mask: np.ndarray, cost: np.ndarray | None = None) -> list[tuple[int, int]]:
    """One cell ``(i, j)`` per 4-connected component of ``mask``, where its letter is drawn:
    the cell of least ``cost`` (``(nx, ny)``, e.g. how much of a route crosses it; default
    none), and among those the one nearest to the component's centroid."""
    from scipy import ndimage

    labelled, n = ndimage.label(mask)
    out = []
    for k in range(1, n + 1):
        cells = np.argwhere(labelled == k)
        c = np.zeros(len(cells)) if cost is None else cost[cells[:, 0], cells[:, 1]]
        pool = cells[c == c.min()]
        centre = cells.mean(axis=0)
        out.append(tuple(int(v) for v in pool[np.argmin(((pool - centre) ** 2).sum(axis=1))]))
    return out


# --------------------------------------------------------------------------- colour vision
_CVD: dict[str, np.ndarray] = {
    "normal": np.eye(3),
    "protan": np.array(
        [
            [0.152286, 1.052583, -0.204868],
            [0.114503, 0.786281, 0.099216],
            [-0.003882, -0.048116, 1.051998],
        ]
    ),
    "deutan": np.array(
        [
            [0.367322, 0.860646, -0.227968],
            [0.280085, 0.672501, 0.047413],
            [-0.011820, 0.042940, 0.968881],
        ]
    ),
    "tritan": np.array(
        [
            [1.255528, -0.076749, -0.178779],
            [-0.078411, 0.930809, 0.147602],
            [0.004733, 0.691367, 0.303900],
        ]
    ),
}
VISION_TYPES: tuple[str, ...] = tuple(_CVD)


def simulate_cvd(rgb: np.ndarray | Sequence[int], kind: str) -> np.ndarray:
    """CIELAB (D65) coordinates of sRGB colours ``(..., 3)`` in 0..255 as seen with colour
    vision ``kind`` (``normal``, ``protan``, ``deutan``, ``tritan``): the Machado et al. (2009)
    matrix of severity 1 applied in linear RGB, clipped to the gamut, then converted to Lab."""
    c = np.asarray(rgb, dtype=float) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    seen = np.clip(linear @ _CVD[kind].T, 0.0, 1.0)
    to_xyz = np.array(
        [[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]
    )
    t = (seen @ to_xyz.T) / np.array([0.95047, 1.0, 1.08883])
    d = 6.0 / 29.0
    f = np.where(t > d**3, np.cbrt(t), t / (3 * d * d) + 4.0 / 29.0)
    return np.stack(
        [116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])],
        axis=-1,
    )


def min_distance(colors: Sequence[Rgb]) -> tuple[float, str, int, int]:
    """Smallest CIELAB distance between two of ``colors`` over all vision types:
    ``(distance, vision type, index, index)``."""
    best = (np.inf, "", -1, -1)
    arr = np.asarray(colors, dtype=float)
    iu = np.triu_indices(len(arr), k=1)
    for kind in VISION_TYPES:
        lab = simulate_cvd(arr, kind)
        d = np.linalg.norm(lab[:, None] - lab[None], axis=-1)[iu]
        k = int(np.argmin(d))
        if d[k] < best[0]:
            best = (float(d[k]), kind, int(iu[0][k]), int(iu[1][k]))
    return best
