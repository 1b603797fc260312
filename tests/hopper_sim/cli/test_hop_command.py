"""``hopnav hop``: JSON output keys, JSONL mode, failed hops and bad lines."""

from __future__ import annotations

import io
import json
import subprocess
import sys

import numpy as np
import pytest

from hopper_sim.cli import main

KEYS = {
    "ok", "status", "next_pos", "next_vel", "touchdown_time", "liftoff_time",
    "energy_before", "energy_after",
}  # fmt: skip
GAIT = ["--vel", "2.5", "0", "-2.4", "--alpha", "1.324", "--beta", "0.1"]


def test_json_hop(capsys):
    assert main(["hop", *GAIT, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert KEYS <= set(out)
    assert out["ok"] is True and out["status"] == "ok"
    assert len(out["next_pos"]) == 2 and len(out["next_vel"]) == 3
    assert out["touchdown_time"] < out["liftoff_time"]
    assert out["energy_after"] == pytest.approx(out["energy_before"], rel=1e-5)
    assert out["thrust_command"] == 0.0 and out["terrain_force"] == [0.0, 0.0]


def test_json_hop_with_perturbations(capsys):
    assert (
        main(["hop", *GAIT, "--perturb", "3", "--noise", "0.1", "-0.1", "--thrust", "--json"]) == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] and out["perturb"] == 3 and out["thrust"] is True
    assert out["noise"] == [0.1, -0.1] and np.linalg.norm(out["terrain_force"]) > 0
    assert out["energy_after"] == pytest.approx(out["energy_before"], rel=1e-6)


def test_jsonl_reports_failures_and_bad_lines(monkeypatch, capsys):
    lines = [
        {"pos": [0, 0], "vel": [2.5, 0, -2.4], "alpha": 1.324, "beta": 0.0},
        {"pos": [0, 0], "vel": [1.0, 0, -0.2], "alpha": 0.8, "beta": 0.0},
        {"pos": [0, 0], "vel": [2.5, 0, -2.4], "alpha": 1.324, "beta": 0.0, "noise": [0.2, 0]},
    ]
    text = "\n".join(json.dumps(x) for x in lines) + "\nnot json\n" + '{"pos": [0, 0]}\n'
    text += json.dumps(lines[0] | {"perturb": -3}) + "\n"
    monkeypatch.setattr(sys, "stdin", io.StringIO(text))
    assert main(["hop", "--jsonl"]) == 2
    out = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [o["status"] for o in out] == [
        "ok", "no_touchdown", "ok", "invalid_input", "invalid_input", "invalid_input",
    ]  # fmt: skip
    assert out[1]["ok"] is False and out[1]["next_pos"] is None
    assert np.allclose(np.subtract(out[2]["next_pos"], out[0]["next_pos"]), [0.2, 0.0], atol=1e-6)
    assert out[4]["message"] == "line 5: missing key 'vel'"
    assert "non-negative integer seed" in out[5]["message"]


def test_console_entry_runs_as_a_module():
    proc = subprocess.run(
        [sys.executable, "-m", "hopper_sim.cli", "hop", *GAIT, "--json"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert json.loads(proc.stdout)["ok"] is True
    assert proc.stderr == ""
