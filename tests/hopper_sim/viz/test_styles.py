import numpy as np
import pytest

from hopper_sim.viz.styles import (
    INITIAL_COLOR,
    INITIAL_LETTER,
    LABEL_COLORS,
    PHASE_COLORS,
    VISION_TYPES,
    WHITE,
    label_colors,
    legend_entries,
    min_distance,
    region_components,
    region_letters,
    simulate_cvd,
)
from planner.scenario import load_scenario


def test_region_and_route_colours_stay_apart_under_colour_blindness():
    colors = [
        WHITE,
        INITIAL_COLOR,
        *LABEL_COLORS.values(),
        PHASE_COLORS["exploration"],
        PHASE_COLORS["goal_reaching"],
    ]
    distance, kind, i, j = min_distance(colors)
    assert distance >= 20.0, (kind, colors[i], colors[j])


def test_colour_vision_simulation():
    for kind in VISION_TYPES:
        lab = simulate_cvd([[255, 255, 255], [0, 0, 0]], kind)
        np.testing.assert_allclose(lab[0], [100.0, 0.0, 0.0], atol=0.5)
        np.testing.assert_allclose(lab[1], [0.0, 0.0, 0.0], atol=1e-9)
    red, green = [230, 30, 30], [30, 160, 30]
    normal = np.linalg.norm(simulate_cvd(red, "normal") - simulate_cvd(green, "normal"))
    deutan = np.linalg.norm(simulate_cvd(red, "deutan") - simulate_cvd(green, "deutan"))
    assert deutan < 0.5 * normal  # red and green collapse for a deuteranope
    blue, yellow = [0, 0, 255], [255, 255, 0]
    assert np.linalg.norm(simulate_cvd(blue, "deutan") - simulate_cvd(yellow, "deutan")) > 80


def test_letters_are_unique_and_cover_custom_labels():
    letters = region_letters(["Haz", "Goal", "hill", "Hut", "H", "I", "coin", "charger"])
    assert letters["Haz"] == "H" and letters["Goal"] == "G"
    assert letters["hill"] == "Hi" and letters["Hut"] == "Hu"
    assert letters["coin"] == "C" and letters["charger"] == "Ch"
    assert len(set(letters.values())) == len(letters)
    assert INITIAL_LETTER not in letters.values()


def test_legend_names_every_region_class_with_its_reward():
    sc = load_scenario("a")
    entries = legend_entries(sc)
    texts = [t for _, t, _ in entries]
    assert texts[0] == "initial region"
    assert "A: optional task, reward +20" in texts
    assert "B: optional task, reward +5" in texts
    assert "weak: penalty, reward -0.5" in texts
    assert "Goal: goal, reward 0" in texts and "Haz: hazard, reward 0" in texts
    assert len(entries) == 1 + len(sc.regions)
    colors = label_colors(sc.labels, sc.goal, sc.hazard)
    assert {c for _, _, c in entries} == {INITIAL_COLOR, *colors.values()}


def test_region_components_one_cell_per_connected_region():
    mask = np.zeros((6, 5), dtype=bool)
    mask[0:3, 0:2] = True  # a block
    mask[5, 4] = True  # a lone cell
    cells = region_components(mask)
    assert sorted(cells) == [(1, 0), (5, 4)] or sorted(cells) == [(1, 1), (5, 4)]
    cover = np.zeros((6, 5))
    cover[1, :] = 1.0
    picked = region_components(mask, cover)
    assert all(cover[c] == 0 for c in picked if c != (5, 4))


@pytest.mark.parametrize("name", ["a", "b", "c", "d"])
def test_every_shipped_label_has_a_paper_colour(name):
    sc = load_scenario(name)
    colors = label_colors(sc.labels, sc.goal, sc.hazard)
    assert colors[sc.goal] == LABEL_COLORS["Goal"] and colors[sc.hazard] == LABEL_COLORS["Haz"]
    assert colors["A"] == LABEL_COLORS["A"] and colors["weak"] == LABEL_COLORS["weak"]
