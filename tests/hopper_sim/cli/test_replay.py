import json
import subprocess
import sys
from pathlib import Path

import pytest

from hopper_sim.cli import main, replay
from hopper_sim.viz.recording import RerunRecorder
from planner.scenario import load_scenario
from tests.hopper_sim.synthetic_runs import feed, run_events

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def rrd(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "run.rrd"
    with RerunRecorder(path) as rec:
        feed(rec, run_events(load_scenario("b"), 0, 4, "violation"))
    return path


def test_replay_prints_summary_headlessly(rrd, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert replay.viewer_command() is None
    assert main(["replay", str(rrd)]) == 0
    out = capsys.readouterr().out
    assert "run 1: 4 hops, outcome violation" in out and "with blueprint" in out
    assert "run_1/hop/com_arc" in out and "world/cells/Haz" in out


def test_replay_json(rrd, capsys):
    assert main(["replay", "--json", str(rrd)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["runs"][0]["hops"] == 4 and data["runs"][0]["outcome"] == "violation"
    assert data["runs"][0]["run"] == 1 and data["blueprint"] is True


def test_replay_bad_file_fails_with_message(tmp_path, capsys):
    bad = tmp_path / "bad.rrd"
    bad.write_text("nope")
    assert main(["replay", str(bad)]) == 2
    assert "not a readable rerun recording" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "none.rrd")]) == 2


def test_replay_script_wrapper(rrd):
    env = {"PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "replay.py"), "--summary", str(rrd)],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    ).stdout
    assert "outcome violation" in out


def test_replay_opens_viewer_when_display_exists(rrd, monkeypatch, capsys):
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setattr(replay, "viewer_command", lambda: ["fake-rerun"])
    calls = []
    monkeypatch.setattr(replay.subprocess, "call", lambda cmd: calls.append(cmd) or 0)
    assert main(["replay", str(rrd)]) == 0
    assert calls == [["fake-rerun", str(rrd)]]
    assert capsys.readouterr().out == ""
    assert main(["replay", "--summary", str(rrd)]) == 0
    assert len(calls) == 1 and "outcome violation" in capsys.readouterr().out


def test_viewer_command_needs_a_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.setenv("WAYLAND_DISPLAY", "wayland-0")
    cmd = replay.viewer_command()
    assert cmd is None or Path(cmd[0]).name == "rerun"
