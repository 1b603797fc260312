import struct
from pathlib import Path

import numpy as np
import pytest
from matplotlib.collections import LineCollection, PathCollection
from matplotlib.quiver import Quiver

from hopper_sim.navigation.events import HopEvent, RunEnd
from hopper_sim.viz.figures import (
    PNG_DPI,
    FigureError,
    FigureWriter,
    Panel,
    Route,
    build_figure,
    check_destination,
    region_image,
    render_figure,
    render_run_figure,
    scenario_title,
)
from hopper_sim.viz.styles import LABEL_COLORS, PHASE_COLORS
from planner.scenario import load_scenario
from tests.hopper_sim.synthetic_runs import feed, run_events

ROOT = Path(__file__).resolve().parents[3]
PNG = b"\x89PNG\r\n\x1a\n"


def _png_info(path: Path) -> tuple[tuple[int, int], float]:
    """(width, height) in pixels and dots per inch of a PNG."""
    data = path.read_bytes()
    assert data[:8] == PNG and data[12:16] == b"IHDR"
    size = struct.unpack(">II", data[16:24])
    at = data.index(b"pHYs")
    ppm_x, _, unit = struct.unpack(">IIB", data[at + 4 : at + 13])
    assert unit == 1  # metres
    return size, ppm_x * 0.0254


def _run(name="a", n=8):
    scenario = load_scenario(name)
    events = run_events(scenario, 0, n)
    return scenario, [e for e in events if isinstance(e, HopEvent)], events[-1]


def _texts(fig) -> list[str]:
    legend = fig.legends[0] if fig.legends else fig.axes[0].get_legend()
    return [t.get_text() for t in legend.get_texts()]


def test_format_follows_the_extension(tmp_path: Path):
    scenario, hops, end = _run()
    png = render_run_figure(scenario, hops, tmp_path / "a.png", end=end)
    assert _png_info(png) == ((8 * PNG_DPI, int(5.6 * PNG_DPI)), pytest.approx(200, abs=0.1))
    svg = render_run_figure(scenario, hops, tmp_path / "a.svg", end=end).read_bytes()
    assert svg.startswith(b"<?xml") and b"<svg" in svg[:1000]
    pdf = render_run_figure(scenario, hops, tmp_path / "a.PDF", end=end).read_bytes()
    assert pdf.startswith(b"%PDF-")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.PDF", "a.png", "a.svg"]


def test_vector_files_are_reproducible(tmp_path: Path):
    scenario, hops, end = _run()
    for ext in ("svg", "pdf"):
        one = render_run_figure(scenario, hops, tmp_path / f"1.{ext}", end=end).read_bytes()
        two = render_run_figure(scenario, hops, tmp_path / f"2.{ext}", end=end).read_bytes()
        assert one == two


def test_bad_destinations_fail_before_drawing(tmp_path: Path):
    scenario = load_scenario("a")
    with pytest.raises(FigureError, match=r"unknown figure format '\.jpg'"):
        render_run_figure(scenario, [], tmp_path / "x.jpg")
    with pytest.raises(FigureError, match="no extension"):
        check_destination(tmp_path / "figure")
    with pytest.raises(FigureError, match="folder"):
        render_run_figure(scenario, [], tmp_path / "no" / "x.png")
    with pytest.raises(FigureError, match="positive"):
        render_run_figure(scenario, [], tmp_path / "x.png", size_inches=(0, 3))
    with pytest.raises(FigureError, match="RunStart"):
        FigureWriter(tmp_path / "x.png").on_run_end(
            RunEnd(3, "success", 1, 0.0, None, None, 0, 1.0)
        )
    with pytest.raises(FigureError, match="unknown figure format"):
        FigureWriter(tmp_path / "x.gif")
    assert list(tmp_path.iterdir()) == []


def test_route_is_drawn_once_with_direction_phases_and_marks():
    scenario, hops, end = _run(n=8)
    route = Route.from_hops(hops, scenario.start, end.switch_step)
    fig = build_figure([Panel(scenario, route, "t")])
    ax = fig.axes[0]
    lines = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert sum(len(c.get_segments()) for c in lines) == len(hops)  # each hop once
    by_color = {tuple(np.round(c.get_colors()[0][:3] * 255)): len(c.get_segments()) for c in lines}
    n_goal = sum(h.phase == "goal_reaching" for h in hops)
    assert by_color[PHASE_COLORS["goal_reaching"]] == n_goal
    assert by_color[PHASE_COLORS["exploration"]] == len(hops) - n_goal
    (quiver,) = [c for c in ax.collections if isinstance(c, Quiver)]
    assert quiver.N == len(hops)
    chords = np.array([h.landing - h.start_pos for h in hops])
    assert np.all(np.sum(np.column_stack([quiver.U, quiver.V]) * chords, axis=1) > 0)
    marks = [c for c in ax.collections if isinstance(c, PathCollection)]
    offsets = {round(c.get_zorder()): c.get_offsets()[0] for c in marks}
    top = max(c.get_zorder() for c in ax.collections)
    np.testing.assert_allclose(offsets[round(top)], scenario.start)  # the start is on top
    assert max(c.get_zorder() for c in [*lines, quiver]) < min(c.get_zorder() for c in marks)
    np.testing.assert_allclose(offsets[6], hops[end.switch_step].start_pos)  # the switch
    np.testing.assert_allclose(offsets[7], hops[-1].com_path[-1, :2])  # the end
    assert ax.get_title() == "t"


def test_legend_lists_every_region_class_with_reward_and_the_route():
    scenario, hops, end = _run()
    fig = build_figure([Panel(scenario, Route.from_hops(hops, scenario.start, end.switch_step))])
    texts = _texts(fig)
    for want in (
        "initial region",
        "Goal: goal, reward 0",
        "Haz: hazard, reward 0",
        "A: optional task, reward +20",
        "B: optional task, reward +5",
        "weak: penalty, reward -0.5",
        "exploration (arrow: direction)",
        "goal reaching (arrow: direction)",
        "backup replaced the action",
        "switch to goal reaching",
        "start",
        "end",
    ):
        assert want in texts


def test_every_region_gets_its_letter_also_custom_labels():
    corridor = load_scenario(ROOT / "examples" / "scenarios" / "corridor.toml")
    fig = build_figure([Panel(corridor)])
    letters = [t.get_text() for t in fig.axes[0].texts]
    assert letters.count("C") == 1  # the charger: one connected pair of cells
    assert letters.count("Co") == 3  # three separate coins
    assert letters.count("G") == 1 and letters.count("I") == 1
    assert letters.count("H") == 2  # the top wall; the bottom wall with its pillar
    texts = _texts(fig)
    assert "coin: optional task, reward +3" in texts and "charger: label, reward 0" in texts


def test_scenario_map_is_titled_and_has_no_route_legend(tmp_path: Path):
    scenario = load_scenario("d")
    fig = build_figure([Panel(scenario)])
    assert fig.axes[0].get_title() == scenario_title(scenario)
    assert "unknown reward" in scenario_title(scenario) and "hops" not in scenario_title(scenario)
    texts = _texts(fig)
    assert not any("exploration" in t or "goal reaching" in t or t == "end" for t in texts)
    assert "start" in texts


def test_panel_of_four_scenarios(tmp_path: Path):
    panels = []
    for name in "abcd":
        scenario, hops, end = _run(name, 4)
        panels.append(Panel(scenario, Route.from_hops(hops, scenario.start, end.switch_step), name))
    fig = build_figure(panels)
    assert [ax.get_title() for ax in fig.axes] == list("abcd")
    positions = [ax.get_position() for ax in fig.axes]
    assert positions[0].y0 == pytest.approx(positions[1].y0)  # a, b on the top row
    assert positions[2].y0 < positions[0].y0 and positions[2].x0 == pytest.approx(positions[0].x0)
    assert len(fig.legends) == 1  # one shared legend
    out = render_figure(panels, tmp_path / "fig4.pdf")
    assert out.read_bytes().startswith(b"%PDF-")


def test_region_image_colours_cells_by_label():
    scenario = load_scenario("a")
    image = region_image(scenario)
    assert image.shape == (15, 15, 3)
    # cell (7, 0) is in the hazard wall, (13, 7) in the goal; image rows are y
    np.testing.assert_allclose(image[0, 7], np.array(LABEL_COLORS["Haz"]) / 255)
    np.testing.assert_allclose(image[7, 13], np.array(LABEL_COLORS["Goal"]) / 255)
    np.testing.assert_allclose(image[0, 0], [1.0, 1.0, 1.0])


def test_figure_writer_names_runs_from_one(tmp_path: Path):
    scenario = load_scenario("b")
    writer = FigureWriter(tmp_path / "run_{run}.svg", n_runs=2)
    feed(writer, run_events(scenario, 0, 3, "timeout"))
    feed(writer, run_events(scenario, 1, 0, "violation"))
    assert writer.written == [tmp_path / "run_1.svg", tmp_path / "run_2.svg"]
    assert all(p.read_bytes().startswith(b"<?xml") for p in writer.written)


def test_run_titles_number_runs_from_one():
    from hopper_sim.viz.figures import run_title

    scenario, _, end = _run("c", 5)
    assert (
        run_title(scenario, run_number=end.run_index + 1, n_runs=10, end=end)
        == f"scenario c, run 1 of 10: success, 5 hops, reward {end.reward:g}"
    )
    assert run_title(scenario, hops=0) == "scenario c: 0 hops"


def test_figure_writer_with_a_fixed_path_writes_the_last_run_once(tmp_path: Path, monkeypatch):
    import hopper_sim.viz.figures as figures

    drawn = []
    real = figures.render_run_figure
    monkeypatch.setattr(
        figures,
        "render_run_figure",
        lambda *a, **k: drawn.append(k["end"].run_index) or real(*a, **k),
    )
    scenario = load_scenario("c")
    writer = FigureWriter(tmp_path / "c.png", n_runs=3)
    for k in range(3):
        feed(writer, run_events(scenario, k, 2 + k))
    assert writer.written == [] and list(tmp_path.iterdir()) == []
    writer.close()
    assert writer.written == [tmp_path / "c.png"] and drawn == [2]  # the third run
    writer.close()  # nothing more to write
    assert writer.written == [tmp_path / "c.png"]
