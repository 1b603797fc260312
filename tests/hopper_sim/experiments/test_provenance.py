"""Every written result carries its provenance: scenario digest, checkpoint hash, package
version, git commit (when the code comes from a git checkout)."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest
from PIL import Image

import hopnav
from hopper_sim.cli import main
from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT
from hopper_sim.experiments import sweep as sw
from hopper_sim.experiments.provenance import (
    FIELDS,
    ProvenanceError,
    file_sha256,
    git_state,
    provenance,
    require_same_scenario,
    scenario_digest,
)
from hopper_sim.viz.recording import summarize_recording
from planner.qlearning import RobustQLearner
from planner.scenario import load_scenario, parse_scenario, resolve_scenario_path
from tests.hopper_sim.experiments.test_sweep import fake_run


def expected(name: str) -> dict:
    return provenance(load_scenario(name), DEFAULT_CHECKPOINT)


def test_fields():
    record = expected("a")
    assert tuple(record) == FIELDS
    assert record["scenario"] == "a" and len(record["scenario_sha256"]) == 64
    assert record["checkpoint_sha256"] == file_sha256(DEFAULT_CHECKPOINT)
    assert record["hopnav_version"] == hopnav.__version__
    commit, dirty = git_state()
    assert record["git_commit"] == commit and record["git_dirty"] == dirty
    if commit is not None:
        assert len(commit) == 40 and isinstance(dirty, bool)


def test_scenario_digest_follows_the_definition_not_the_file():
    text = resolve_scenario_path("a").read_text()
    a = load_scenario("a")
    assert scenario_digest(parse_scenario(text + "\n# a comment\n")) == scenario_digest(a)
    assert scenario_digest(parse_scenario(text.replace("p_sat = 0.65", "p_sat = 0.7"))) != (
        scenario_digest(a)
    )
    assert scenario_digest(a.with_runner(max_steps=7)) != scenario_digest(a)
    assert scenario_digest(load_scenario("b")) != scenario_digest(a)
    moved = dataclasses.replace(a, start=(a.start[0], a.start[1] + 1.0))
    assert scenario_digest(moved) != scenario_digest(a)


def test_require_same_scenario():
    a, b = expected("a"), expected("b")
    require_same_scenario(a, a, "x")
    with pytest.raises(ProvenanceError, match="belongs to scenario 'b'"):
        require_same_scenario(b, a, "file.npz")
    with pytest.raises(ProvenanceError, match="carries no scenario digest"):
        require_same_scenario({}, a, "file.npz")


@pytest.mark.slow
def test_run_writes_provenance_everywhere(tmp_path, capsys):
    rrd, png, q = tmp_path / "r.rrd", tmp_path / "r.png", tmp_path / "q.npz"
    args = ["run", "--scenario", "c", "--runs", "1", "--max-steps", "4", "--json"]
    assert main([*args, "--rrd", str(rrd), "--png", str(png), "--q-table", str(q)]) == 0
    want = expected("c")
    runs = json.loads(capsys.readouterr().out)
    assert runs[0]["provenance"] == want  # before --max-steps: the scenario as loaded
    assert summarize_recording(rrd)["provenance"] == {
        k: ("true" if v is True else "false" if v is False else str(v))
        for k, v in want.items()
        if v is not None
    }
    assert main(["replay", str(rrd), "--summary"]) == 0
    shown = capsys.readouterr().out
    assert f"scenario_sha256 {want['scenario_sha256']}" in shown
    text = Image.open(png).text
    assert text["scenario_sha256"] == want["scenario_sha256"]
    assert text["checkpoint_sha256"] == want["checkpoint_sha256"]
    assert text["hopnav_version"] == hopnav.__version__
    assert RobustQLearner.load(q).metadata["provenance"] == want
    # the saved table continues on the same scenario, also with another step cap
    assert main([*args, "--max-steps", "3", "--no-rrd", "--no-png", "--q-table", str(q)]) == 0


def test_scenario_figure_has_provenance(tmp_path):
    png = tmp_path / "w.png"
    assert main(["scenario", "b", "--png", str(png)]) == 0
    assert Image.open(png).text["scenario_sha256"] == scenario_digest(load_scenario("b"))


def test_sweep_files_carry_provenance(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sw, "default_run_function", lambda: fake_run)
    out = tmp_path / "sweep"
    args = ["sweep", "--runs", "2", "--cs", "0.25", "--epss", "0.005,0.0075", "--json"]
    assert main([*args, "--backend", "serial", "--out", str(out)]) == 0
    capsys.readouterr()
    want = provenance(load_scenario("a"), DEFAULT_CHECKPOINT)
    meta = json.loads((out / "sweep_meta.json").read_text())
    assert meta["provenance"] == want and meta["scenario_sha256"] == want["scenario_sha256"]
    for name in ("sweep_runs.csv", "sweep_summary.csv"):
        with (out / name).open(newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert rows and all(r["scenario_sha256"] == want["scenario_sha256"] for r in rows)
        assert all(r["hopnav_version"] == hopnav.__version__ for r in rows)
        assert all(r["checkpoint_sha256"] == want["checkpoint_sha256"] for r in rows)
        assert all(r["git_commit"] == (want["git_commit"] or "") for r in rows)
    assert want["scenario_sha256"] in (out / "table_i.md").read_text()


def test_sweep_resume_refuses_rows_of_another_scenario(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sw, "default_run_function", lambda: fake_run)
    out = tmp_path / "sweep"
    args = ["sweep", "--runs", "1", "--cs", "0.25", "--epss", "0.005", "--json"]
    args += ["--backend", "serial", "--out", str(out)]
    assert main(args) == 0
    capsys.readouterr()
    rows = out / "sweep_runs.csv"
    rows.write_text(rows.read_text().replace(expected("a")["scenario_sha256"], "0" * 64))
    assert main([*args, "--resume"]) == 2
    err = capsys.readouterr().err.strip()
    assert "cannot resume" in err and "a row of" in err and len(err.splitlines()) == 1


def test_checkpoint_records_the_package_version(tmp_path):
    from hopper_sim.controller.checkpoint import load_checkpoint

    out = tmp_path / "c.pt"
    args = ["train-controller", "--samples", "100", "--epochs", "1", "--hidden", "8"]
    assert main([*args, "--nthread", "1", "--out", str(out), "--allow-weak"]) == 0
    meta = load_checkpoint(out).metadata
    assert meta["provenance"]["hopnav_version"] == hopnav.__version__
    assert np.isfinite(meta["metrics"]["dx"]["rmse"])


def test_svg_pdf_and_table_i_figures_carry_provenance(tmp_path, monkeypatch, capsys):
    import re

    want = scenario_digest(load_scenario("b"))
    svg, pdf = tmp_path / "w.svg", tmp_path / "w.pdf"
    assert main(["scenario", "b", "--png", str(svg)]) == 0
    assert main(["scenario", "b", "--png", str(pdf)]) == 0
    description = re.search(r"<dc:description>(.*?)</dc:description>", svg.read_text(), re.S)
    assert description and json.loads(description.group(1))["scenario_sha256"] == want
    assert want.encode() in pdf.read_bytes()  # the Info dictionary's Subject (uncompressed)
    # the Table I plot of `hopnav sweep`, and the one `hopnav figure` redraws from its rows
    monkeypatch.setattr(sw, "default_run_function", lambda: fake_run)
    out = tmp_path / "sweep"
    args = ["sweep", "--runs", "1", "--cs", "0.25", "--epss", "0.005", "--json"]
    assert main([*args, "--backend", "serial", "--out", str(out)]) == 0
    plot = Image.open(out / "table_i.png").text
    assert plot["scenario_sha256"] == expected("a")["scenario_sha256"]
    redrawn = tmp_path / "t.png"
    assert main(["figure", "--table-i", str(out / "sweep_runs.csv"), "--out", str(redrawn)]) == 0
    assert Image.open(redrawn).text["source"] == str(out / "sweep_runs.csv")
    capsys.readouterr()
