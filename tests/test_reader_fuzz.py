"""Every reader against random bytes, truncations and mutations of valid files (hypothesis):
it returns a result or raises one of the project's own error types, nothing else (no
``UnicodeDecodeError``, ``RecursionError``, ``MemoryError``, ``IndexError``...)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hopper_sim.controller.errors import ControllerError
from hopper_sim.experiments.sweep_files import SweepFileError
from hopper_sim.viz.recording import RecordingError
from planner.errors import PlannerError
from tests.hopnav.hostile import BMDP, DRN, LAB, TRA, scenario

FAST = settings(
    max_examples=120,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
SLOW = settings(FAST, max_examples=40)


def hostile(valid: bytes) -> st.SearchStrategy[bytes]:
    """Random bytes, truncations of ``valid`` (with a random tail) and byte-level mutations."""
    cut = st.builds(
        lambda n, tail: valid[: n % (len(valid) + 1)] + tail,
        st.integers(0, len(valid)),
        st.binary(max_size=16),
    )
    flips = st.builds(
        _mutate,
        st.just(valid),
        st.lists(st.tuples(st.integers(0), st.integers(0, 255)), max_size=4),
    )
    return st.one_of(st.binary(max_size=2048), cut, flips)


def _mutate(data: bytes, edits: list[tuple[int, int]]) -> bytes:
    out = bytearray(data)
    for pos, value in edits:
        if out:
            out[pos % len(out)] = value
    return bytes(out)


def _write(folder: Path, name: str, data: bytes) -> Path:
    path = folder / name
    path.write_bytes(data)
    return path


def _only_own_errors(call, *own: type[BaseException]) -> None:
    try:
        call()
    except own:
        pass


# --------------------------------------------------------------------------- planner


@FAST
@given(data=hostile(TRA.encode()))
def test_prism_reader(tmp_path, data):
    from planner.imdp.io import read_prism

    _only_own_errors(lambda: read_prism(_write(tmp_path, "m.tra", data)), PlannerError)


@FAST
@given(data=hostile(LAB.encode()))
def test_prism_label_reader(tmp_path, data):
    from planner.imdp.io import read_prism

    _write(tmp_path, "m.tra", TRA.encode())
    _write(tmp_path, "m.lab", data)
    _only_own_errors(lambda: read_prism(tmp_path / "m.tra"), PlannerError)


@FAST
@given(data=hostile(DRN.encode()))
def test_drn_reader(tmp_path, data):
    from planner.imdp.io import read_drn

    _only_own_errors(lambda: read_drn(_write(tmp_path, "m.drn", data)), PlannerError)


@FAST
@given(data=hostile(BMDP.encode()))
def test_bmdp_reader(tmp_path, data):
    from planner.imdp.io import read_bmdp

    _only_own_errors(lambda: read_bmdp(_write(tmp_path, "m.bmdp", data)), PlannerError)


def _hoa_text() -> str:
    from planner.ltl.hoa import to_hoa
    from planner.ltl.translate import translate

    return to_hoa(translate("G F a & (b U c)"))


@FAST
@given(data=hostile(_hoa_text().encode()))
def test_hoa_reader(data):
    from planner.ltl.hoa import from_hoa

    text = data.decode("utf-8", errors="replace")
    _only_own_errors(lambda: from_hoa(text), PlannerError)


@FAST
@given(text=st.text(max_size=300))
def test_ltl_parser(text):
    from planner.ltl.parser import parse

    _only_own_errors(lambda: parse(text), PlannerError)


_ATOMS = st.sampled_from(["a", "b", "c", "true", "false"])
_FORMULAS = st.recursive(
    _ATOMS,
    lambda sub: st.one_of(
        st.builds(lambda op, f: f"{op}({f})", st.sampled_from(["!", "X ", "F ", "G "]), sub),
        st.builds(
            lambda f, op, g: f"({f}) {op} ({g})",
            sub,
            st.sampled_from(["&", "|", "U", "R", "W", "M", "->", "<->", "xor"]),
            sub,
        ),
    ),
    max_leaves=12,
)


@SLOW
@given(text=_FORMULAS)
def test_translation_under_small_limits(text):
    """Valid formulas under tight limits: an automaton or a limit error, never another."""
    from planner.ltl.budget import TranslationLimits
    from planner.ltl.translate import translate

    limits = TranslationLimits(max_states=60, max_seconds=2.0)
    _only_own_errors(lambda: translate(text, limits=limits), PlannerError)


@FAST
@given(data=hostile(scenario().encode()))
def test_scenario_reader(tmp_path, data):
    from planner.scenario import load_scenario

    _only_own_errors(lambda: load_scenario(_write(tmp_path, "s.toml", data)), PlannerError)


@FAST
@given(text=st.text(alphabet="[]{}\"'#=a1,\n .", max_size=400))
def test_toml_scanners_never_raise(text):
    from planner._util.toml_lines import key_lines, nesting_depth

    depth, line = nesting_depth(text)
    assert depth >= 0 and 1 <= line <= text.count("\n") + 1
    key_lines(text)


def _q_table_bytes() -> bytes:
    from planner.qlearning import RobustQLearner

    buf_path = Path(__import__("tempfile").mkdtemp()) / "q.npz"
    learner = RobustQLearner(4, 3, 2, state_cell=np.array([0, 1, 0, 1]))
    learner.save(buf_path, metadata={"provenance": {"scenario_sha256": "x"}})
    return buf_path.read_bytes()


@FAST
@given(data=hostile(_q_table_bytes()))
def test_q_table_reader(tmp_path, data):
    from planner.qlearning import RobustQLearner

    _only_own_errors(lambda: RobustQLearner.load(_write(tmp_path, "q.npz", data)), PlannerError)


# --------------------------------------------------------------------------- hopper_sim


def _checkpoint_bytes() -> bytes:
    from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT

    return DEFAULT_CHECKPOINT.read_bytes()


@SLOW
@given(data=hostile(_checkpoint_bytes()))
def test_checkpoint_reader(tmp_path, data):
    from hopper_sim.controller.checkpoint import load_checkpoint

    _only_own_errors(lambda: load_checkpoint(_write(tmp_path, "c.pt", data)), ControllerError)


def _dataset_bytes() -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(
        buf,
        inputs=np.zeros((3, 4)),
        outputs=np.zeros((3, 5)),
        ok=np.ones(3, bool),
        status=np.zeros(3, np.int64),
        metadata_json=np.array(json.dumps({"version": 1})),
    )
    return buf.getvalue()


@FAST
@given(data=hostile(_dataset_bytes()))
def test_dataset_reader(tmp_path, data):
    from hopper_sim.controller.dataset import load_dataset

    _only_own_errors(lambda: load_dataset(_write(tmp_path, "d.npz", data)), ControllerError)


def _csv_bytes() -> bytes:
    from hopper_sim.experiments.sweep import SweepRow
    from hopper_sim.experiments.sweep_files import rows_csv

    row = SweepRow(0.5, 0.005, 0.5, 0, 7, "success", 12, 5.0, 3, 0.9, 1, 0.8, "reached")
    return rows_csv([row, row], {"scenario": "a", "scenario_sha256": "d" * 64}).encode()


@FAST
@given(data=hostile(_csv_bytes()))
def test_sweep_csv_reader(tmp_path, data):
    from hopper_sim.experiments.sweep_files import read_rows_csv

    _only_own_errors(lambda: read_rows_csv(_write(tmp_path, "r.csv", data)), SweepFileError)


@pytest.fixture(scope="module")
def recording_bytes(tmp_path_factory):
    from hopper_sim.viz.recording import RerunRecorder
    from planner.scenario import load_scenario
    from tests.hopper_sim.synthetic_runs import run_events

    path = tmp_path_factory.mktemp("rrd") / "r.rrd"
    sc = load_scenario("a")
    with RerunRecorder(path) as rec:
        for event in run_events(sc, 0, 3):
            getattr(rec, _HANDLERS[type(event).__name__])(event)
    return path.read_bytes()


_HANDLERS = {
    "RunStart": "on_run_start",
    "SynthesisEvent": "on_synthesis",
    "HopEvent": "on_hop",
    "RunEnd": "on_run_end",
}


@SLOW
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["random", "cut", "flip"]))
def test_recording_reader(tmp_path, recording_bytes, seed, kind):
    from hopper_sim.viz.recording import read_runs
    from hopper_sim.viz.recording_reader import summarize_recording

    rng = np.random.default_rng(seed)
    data = bytearray(recording_bytes)
    if kind == "random":
        data = bytearray(rng.integers(0, 256, size=int(rng.integers(0, 4096)), dtype=np.uint8))
    elif kind == "cut":
        data = data[: int(rng.integers(0, len(data)))]
    else:
        for _ in range(int(rng.integers(1, 5))):
            data[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
    path = _write(tmp_path, "r.rrd", bytes(data))
    _only_own_errors(lambda: summarize_recording(path), RecordingError)
    _only_own_errors(lambda: read_runs(path), RecordingError)


@FAST
@given(data=st.one_of(st.binary(max_size=600), st.just(b"[" * 50 + b"]" * 50)))
def test_hop_jsonl_reader(data, monkeypatch, capsys):
    """Random bytes on ``hopnav hop --jsonl``: an exit code and one line, no traceback."""
    import sys

    from hopnav.cli import main

    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data), encoding="utf-8"))
    code = main(["hop", "--jsonl"])
    err = capsys.readouterr().err
    assert code in (0, 2) and "Traceback" not in err and len(err.strip().splitlines()) <= 1
