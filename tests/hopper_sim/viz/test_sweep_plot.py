import json

import numpy as np
import pytest
from matplotlib.container import ErrorbarContainer

import hopper_sim.experiments.sweep as sw
import hopper_sim.experiments.sweep_files as sf
from hopper_sim.cli import main as hopnav
from hopper_sim.experiments.sweep import PAPER_TABLE_I, SweepRow, SweepSpec, summarize
from hopper_sim.viz.figures import FigureError
from hopper_sim.viz.sweep_plot import PLOT_FILE, build_table_plot, write_table_plot
from tests.hopper_sim.experiments.test_sweep import fake_run


def _rows(seed: int = 0) -> list[SweepRow]:
    rng = np.random.default_rng(seed)
    rows = []
    for c in sw.PAPER_CS:
        for e in sw.PAPER_EPSS:
            for r in range(4):
                steps = int(rng.integers(10, 200))
                rows.append(
                    SweepRow(c, e, c, r, r, "success", steps, float(rng.normal(100 * c, 10)),
                             None, None, 0, 1.0)
                )  # fmt: skip
    return rows


def test_plot_overlays_the_paper_on_means_with_intervals():
    cells = summarize(_rows(), SweepSpec())
    fig = build_table_plot(cells)
    reward_ax, steps_ax = fig.axes
    for ax, k, attr in ((reward_ax, 0, "reward"), (steps_ax, 1, "steps")):
        bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
        assert len(bars) == 3  # one series per C
        for bar, c in zip(bars, sw.PAPER_CS, strict=True):
            line, _, (segments,) = bar.lines
            row = sorted((s for s in cells if s.c == c), key=lambda s: s.eps)
            np.testing.assert_allclose(line.get_ydata(), [getattr(s, attr).mean for s in row])
            spans = np.array([seg[:, 1] for seg in segments.get_segments()])
            np.testing.assert_allclose(spans[:, 0], [getattr(s, attr).low for s in row])
            np.testing.assert_allclose(spans[:, 1], [getattr(s, attr).high for s in row])
        paper = {
            ln.get_label(): ln.get_ydata() for ln in ax.get_lines() if "paper" in ln.get_label()
        }
        for c in sw.PAPER_CS:
            want = [PAPER_TABLE_I[(c, e)][k] for e in sw.PAPER_EPSS]
            np.testing.assert_allclose(paper[f"C = {c:g} (paper)"], want)
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "C = 0.25 (hopnav)" in labels and "C = 0.75 (paper)" in labels


def test_plot_of_a_grid_off_the_paper_has_no_paper_series():
    rows = [r for r in _rows() if r.c == 0.5]
    rows = [SweepRow(**{**r.__dict__, "c": 0.6, "p_rl_ee": 0.6}) for r in rows]
    fig = build_table_plot(summarize(rows))
    assert not any("paper" in ln.get_label() for ln in fig.axes[0].get_lines())
    with pytest.raises(FigureError, match="at least one cell"):
        build_table_plot([])


def test_formats_and_bad_destinations(tmp_path):
    cells = summarize(_rows())
    for ext, magic in (("png", b"\x89PNG"), ("svg", b"<?xml"), ("pdf", b"%PDF-")):
        assert write_table_plot(cells, tmp_path / f"t.{ext}").read_bytes().startswith(magic)
    with pytest.raises(FigureError, match="unknown figure format"):
        write_table_plot(cells, tmp_path / "t.txt")


def test_sweep_writes_the_plot_next_to_its_csv(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sw, "default_run_function", lambda: fake_run)
    out = tmp_path / "sweep"
    args = ["sweep", "--runs", "2", "--backend", "serial", "--out", str(out), "--json"]
    assert hopnav([*args, "--cs", "0.25,0.5", "--epss", "0.005,0.0075"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["files"]["plot"] == str(out / PLOT_FILE)
    assert (out / PLOT_FILE).read_bytes().startswith(b"\x89PNG")
    assert (out / sf.ROWS_FILE).is_file()
    # and `hopnav figure --table-i` redraws it from the rows
    svg = tmp_path / "table_i.svg"
    assert hopnav(["figure", "--table-i", str(out / sf.ROWS_FILE), "--out", str(svg)]) == 0
    assert svg.read_bytes().startswith(b"<?xml")
    assert hopnav(["figure", "--table-i", str(tmp_path / "none.csv"), "--out", str(svg)]) == 2
    err = capsys.readouterr().err
    assert "none.csv" in err and len(err.strip().splitlines()) == 1
