"""`hopnav figure`: Figure 4 from recordings or from runs, formats, errors."""

import struct

import pytest

from hopper_sim.cli import main
from hopper_sim.viz.recording import RerunRecorder
from hopper_sim.viz.recording_reader import summarize_recording
from planner.scenario import load_scenario
from tests.hopper_sim.synthetic_runs import feed, run_events


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rrd")
    paths = []
    for name in "abcd":
        sc = load_scenario(name)
        path = folder / f"{name}.rrd"
        with RerunRecorder(path) as rec:
            for k in range(3 if name in "cd" else 1):
                feed(rec, run_events(sc, k, 4 + k, "success"))
        paths.append(str(path))
    return paths


def test_panel_from_recordings_in_three_formats(recordings, tmp_path, capsys):
    outs = [tmp_path / f"fig4.{ext}" for ext in ("pdf", "svg", "png")]
    args = ["figure", "--rrd", *recordings]
    for out in outs:
        args += ["--out", str(out)]
    assert main(args) == 0
    assert capsys.readouterr().out.split() == [str(p) for p in outs]
    pdf, svg, png = (p.read_bytes() for p in outs)
    assert pdf.startswith(b"%PDF-") and svg.startswith(b"<?xml") and png.startswith(b"\x89PNG")
    width, height = struct.unpack(">II", png[16:24])
    assert width == 2 * 5 * 200 and height > 2 * 5 * 200  # two columns of 5 in, a legend below


def test_run_choice_is_one_based(recordings, tmp_path, capsys):
    out = tmp_path / "c2.svg"
    assert main(["figure", "--rrd", recordings[2], "--run", "2", "--out", str(out)]) == 0
    assert out.read_bytes().startswith(b"<?xml")
    assert main(["figure", "--rrd", recordings[2], "--run", "4", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--run 4" in err and "runs 1, 2, 3" in err and len(err.strip().splitlines()) == 1


def test_bad_input_fails_before_any_work(tmp_path, capsys, recordings):
    bad = [
        (["--scenarios", "a", "--out", str(tmp_path / "x.jpg")], "unknown figure format"),
        (["--scenarios", "zz", "--out", str(tmp_path / "x.png")], "no scenario 'zz'"),
        (["--rrd", str(tmp_path / "no.rrd"), "--out", str(tmp_path / "x.png")], "not found"),
        (["--scenarios", "a", "--runs", "0", "--out", str(tmp_path / "x.png")], "at least 1"),
        (["--scenarios", "c", "--run", "11", "--out", str(tmp_path / "x.png")], "runs 1..10"),
    ]
    for args, message in bad:
        assert main(["figure", *args]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    assert list(tmp_path.iterdir()) == []


def test_panel_from_short_real_runs(tmp_path, capsys):
    out, rrd = tmp_path / "ab.png", tmp_path / "rrd"
    args = ["figure", "--scenarios", "a,b", "--max-steps", "3", "--seed", "2", "--quiet"]
    assert main([*args, "--out", str(out), "--save-rrd", str(rrd)]) == 0
    assert out.read_bytes().startswith(b"\x89PNG")
    for name in "ab":
        (run,) = summarize_recording(rrd / f"{name}.rrd")["runs"]
        assert run["run"] == 1 and 1 <= run["steps"] <= 3
