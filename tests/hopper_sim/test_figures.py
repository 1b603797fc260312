import struct
from pathlib import Path

import numpy as np
import pytest

from hopper_sim.events import HopEvent, RunEnd
from hopper_sim.figures import FigureError, FigureWriter, region_image, render_run_figure
from hopper_sim.styles import LABEL_COLORS
from planner.scenario import load_scenario
from tests.hopper_sim.synthetic_runs import feed, run_events


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_render_writes_png_of_requested_size(tmp_path: Path):
    scenario = load_scenario("a")
    events = run_events(scenario, 0, 6)
    hops = [e for e in events if isinstance(e, HopEvent)]
    out = render_run_figure(
        scenario, hops, tmp_path / "a.png", end=events[-1], size_inches=(4, 3), dpi=50
    )
    assert _png_size(out) == (200, 150)
    assert [p.name for p in tmp_path.iterdir()] == ["a.png"]


def test_region_image_colours_cells_by_label():
    scenario = load_scenario("a")
    image = region_image(scenario)
    assert image.shape == (15, 15, 3)
    # cell (7, 0) is in the hazard wall, (13, 7) in the goal; image rows are y
    np.testing.assert_allclose(image[0, 7], np.array(LABEL_COLORS["Haz"]) / 255)
    np.testing.assert_allclose(image[7, 13], np.array(LABEL_COLORS["Goal"]) / 255)
    np.testing.assert_allclose(image[0, 0], [1.0, 1.0, 1.0])


def test_figure_writer_writes_one_png_per_run(tmp_path: Path):
    scenario = load_scenario("b")
    writer = FigureWriter(tmp_path / "run_{run}.png", size_inches=(3, 3), dpi=40)
    feed(writer, run_events(scenario, 0, 3, "timeout"))
    feed(writer, run_events(scenario, 1, 0, "violation"))
    assert writer.written == [tmp_path / "run_0.png", tmp_path / "run_1.png"]
    assert all(_png_size(p) == (120, 120) for p in writer.written)


def test_bad_figure_requests_raise(tmp_path: Path):
    scenario = load_scenario("a")
    with pytest.raises(FigureError, match="folder"):
        render_run_figure(scenario, [], tmp_path / "no" / "x.png")
    with pytest.raises(FigureError, match="positive"):
        render_run_figure(scenario, [], tmp_path / "x.png", size_inches=(0, 3))
    with pytest.raises(FigureError, match="RunStart"):
        FigureWriter(tmp_path / "x.png").on_run_end(
            RunEnd(3, "success", 1, 0.0, None, None, 0, 1.0)
        )
