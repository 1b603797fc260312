"""Tests of the trade-off trend statistics and of ``benchmarks/tradeoff.py``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from hopper_sim.experiments.sweep import SweepRow
from hopper_sim.experiments.sweep_files import atomic_write_text, read_rows_csv, rows_csv
from hopper_sim.experiments.tradeoff import (
    Slope,
    TrendDataError,
    check_tradeoff,
    classify,
    format_trends,
    paper_points,
    slope_ci,
)

ROOT = Path(__file__).resolve().parents[3]


def test_slope_ci_matches_scipy_linregress():
    rng = np.random.default_rng(0)
    x = np.repeat([0.0025, 0.005, 0.0075], 10)
    y = 100 - 3000 * x + rng.normal(0, 5, x.size)
    s = slope_ci(x, y)
    ref = stats.linregress(x, y)
    half = stats.t.ppf(0.975, x.size - 2) * ref.stderr
    assert s.slope == pytest.approx(ref.slope, rel=1e-10)
    assert s.stderr == pytest.approx(ref.stderr, rel=1e-10)
    assert (s.low, s.high) == pytest.approx((ref.slope - half, ref.slope + half), rel=1e-10)
    assert s.n == 30 and s.level == 0.95
    wider = slope_ci(x, y, level=0.99)
    assert wider.low < s.low and wider.high > s.high


@pytest.mark.parametrize(
    ("x", "y", "match"),
    [
        ([1.0, 2.0], [1.0, 2.0], ">= 3 points"),
        ([1.0, 1.0, 1.0], [1.0, 2.0, 3.0], "all x values are equal"),
        ([1.0, 2.0, 3.0], [1.0, 2.0], "x has 3 values but y has 2"),
        ([1.0, 2.0, np.nan], [1.0, 2.0, 3.0], "finite"),
    ],
)
def test_slope_ci_rejects_bad_data(x, y, match):
    with pytest.raises(TrendDataError, match=match):
        slope_ci(x, y)


def test_classify():
    up = Slope(2.0, 1.0, 3.0, 0.5, 10)
    down = Slope(-2.0, -3.0, -1.0, 0.5, 10)
    flat = Slope(0.1, -1.0, 1.2, 0.5, 10)
    assert classify(up, +1) == "holds" and classify(up, -1) == "does not hold"
    assert classify(down, -1) == "holds" and classify(down, +1) == "does not hold"
    assert classify(flat, +1) == classify(flat, -1) == "inconclusive"
    with pytest.raises(ValueError, match="predicted_sign"):
        classify(up, 0)


def _rows(steps_per_eps: float, reward_per_c: float, noise: float, seed: int) -> list[SweepRow]:
    """Constructed sweep rows: steps = 90 + steps_per_eps * eps, reward = 10 + reward_per_c * C
    (plus Gaussian noise), ten runs per Table I cell."""
    rng = np.random.default_rng(seed)
    rows = []
    for c in (0.25, 0.5, 0.75):
        for e in (0.0025, 0.005, 0.0075):
            for r in range(10):
                steps = round(90 + steps_per_eps * e + rng.normal(0, noise))
                reward = 10 + reward_per_c * c + rng.normal(0, noise)
                rows.append(
                    SweepRow(c, e, c, r, r, "success", steps, reward, 5, 0.7, 0, 1.0)
                )  # fmt: skip
    return rows


def test_check_tradeoff_on_constructed_data():
    holds = check_tradeoff(_rows(-4000.0, 150.0, 3.0, seed=1))
    names = [t.name for t in holds]
    assert names == [
        "steps vs eps at C = 0.25",
        "steps vs eps at C = 0.5",
        "reward vs C at eps = 0.0025",
        "reward vs C at eps = 0.005",
        "reward vs C at eps = 0.0075",
        "reward vs C, all eps pooled",
    ]
    assert [t.verdict for t in holds] == ["holds"] * 6
    assert holds[0].slope.n == 30 and holds[-1].slope.n == 90
    assert holds[0].slope.slope == pytest.approx(-4000.0, rel=0.3)

    opposite = check_tradeoff(_rows(+4000.0, -150.0, 3.0, seed=2))
    assert [t.verdict for t in opposite] == ["does not hold"] * 6

    flat = check_tradeoff(_rows(0.0, 0.0, 20.0, seed=3), level=0.999)
    assert {t.verdict for t in flat} == {"inconclusive"}


def test_check_tradeoff_reports_missing_cells():
    rows = [r for r in _rows(-4000.0, 150.0, 3.0, seed=4) if r.c != 0.25 and r.eps == 0.005]
    trends = check_tradeoff(rows)
    assert trends[0].verdict == "insufficient data" and trends[0].slope is None
    assert ">= 3 points" in trends[0].reason
    assert trends[1].verdict == "insufficient data"  # C = 0.5 has a single eps
    assert "all x values are equal" in trends[1].reason
    text = format_trends(trends)
    assert "insufficient data" in text and "steps vs eps at C = 0.25" in text


def test_benchmark_script_reads_a_sweep_csv(tmp_path):
    path = atomic_write_text(tmp_path / "runs.csv", rows_csv(_rows(-4000.0, 150.0, 3.0, 5)))
    script = ROOT / "benchmarks" / "tradeoff.py"
    done = subprocess.run(
        [sys.executable, str(script), str(path), "--paper"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    ours, paper = done.stdout.split("The paper's Table I")
    lines = ours.splitlines()
    assert lines[0] == f"90 runs from {path}"
    assert sum(ln.rstrip().endswith("holds") for ln in lines) == 6
    assert sum(ln.rstrip().endswith("inconclusive") for ln in paper.splitlines()) == 4
    missing = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "absent.csv")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert missing.returncode == 2 and "cannot read" in missing.stderr


def test_benchmark_script_runs_a_sweep_when_asked(tmp_path, monkeypatch, capsys):
    import runpy

    from hopper_sim.experiments import sweep
    from tests.hopper_sim.experiments.test_sweep import fake_run

    monkeypatch.setattr(sweep, "default_run_function", lambda: fake_run)
    script = runpy.run_path(str(ROOT / "benchmarks" / "tradeoff.py"), run_name="tradeoff")
    csv_path = tmp_path / "sweep" / "sweep_runs.csv"
    args = [str(csv_path), "--run", "--runs", "2", "--backend", "serial", "--seed", "3"]
    assert script["main"](args) == 0
    out = capsys.readouterr().out
    assert f"18 runs from {csv_path}" in out
    assert "steps vs eps at C = 0.25" in out and "reward vs C, all eps pooled" in out
    assert len(read_rows_csv(csv_path)) == 18


def test_paper_table_trends():
    points = paper_points()
    assert len(points) == 9
    trends = check_tradeoff(points)
    # three equally spaced points: the OLS slope is (y3 - y1) / (x3 - x1)
    assert trends[0].slope.slope == pytest.approx((65.1 - 98.0) / 0.005)
    assert trends[0].slope.n == 3 and trends[-1].slope.n == 9
    assert [t.verdict for t in trends] == ["holds", *["inconclusive"] * 4, "holds"]
