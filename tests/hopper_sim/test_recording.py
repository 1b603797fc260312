from pathlib import Path

import pytest

from hopper_sim.recording import RecordingError, RerunRecorder, format_summary, summarize_recording
from planner.scenario import load_scenario
from tests.hopper_sim.synthetic_runs import feed, run_events

EXPECTED_RUN_ENTITIES = [
    "hop/com_arc",
    "hop/foot",
    "hop/leg",
    "hop/target",
    "hop/landing",
    "trajectory",
    "com",
    "hops",
    "status",
    "plots/p_worst",
    "plots/total_reward",
    "plots/phase",
    "plots/rl_action",
    "plots/backup",
    "plots/p_worst_initial",
    "gp/mean_x",
    "gp/mean_y",
    "gp/std_x",
    "gp/std_y",
    "gp/mean_field",
    "timings/gp_fit",
    "outcome",
    "summary",
]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    scenario = load_scenario("a")
    path = tmp_path_factory.mktemp("rec") / "two_runs.rrd"
    with RerunRecorder(path, recording_id="test") as rec:
        feed(rec, run_events(scenario, 0, 6, "success"))
        feed(rec, run_events(scenario, 1, 3, "timeout"))
    return path, scenario


def test_recording_holds_world_and_run_entities(recorded):
    path, scenario = recorded
    s = summarize_recording(path)
    assert s["application_id"] == "hopnav" and s["recording_id"] == "test"
    ents = set(s["entities"])
    for e in ["world/info", "world/grid", "world/cells/initial", "world/rewards", "world/start"]:
        assert e in ents
    for label in scenario.regions:
        assert f"world/cells/{label}" in ents
    for k in (0, 1):
        missing = [e for e in EXPECTED_RUN_ENTITIES if f"run_{k}/{e}" not in ents]
        assert missing == []
    assert {"hop", "sim_time"} <= set(s["timelines"])


def test_recording_is_consistent_with_the_runs(recorded):
    path, scenario = recorded
    runs = summarize_recording(path)["runs"]
    assert [r["run_index"] for r in runs] == [0, 1]
    r0, r1 = runs
    assert (r0["hops"], r0["outcome"], r0["steps"]) == (6, "success", 6)
    assert (r1["hops"], r1["outcome"], r1["steps"]) == (3, "timeout", 3)
    events = run_events(scenario, 0, 6)
    assert r0["reward"] == pytest.approx(events[-1].reward)
    assert r0["final_total_reward"] == pytest.approx(events[-1].reward)
    assert r0["phases"] == {"exploration": 3, "goal_reaching": 3}
    assert r0["sources"] == {"LTL": 4, "RL": 2}
    assert r0["backup_hops"] == 1 and r0["backups"] == 1
    assert r0["seed"] == 100 and r1["seed"] == 101 and r0["scenario"] == "a"
    assert r0["switch_step"] == 3 and r0["p_switch"] == pytest.approx(0.7)
    text = format_summary(summarize_recording(path))
    assert "run 0: 6 hops, outcome success" in text and "run 1: 3 hops, outcome timeout" in text


def test_recorder_writes_atomically_and_discards_on_error(tmp_path: Path):
    path = tmp_path / "r.rrd"
    with pytest.raises(RuntimeError), RerunRecorder(path) as rec:
        feed(rec, run_events(load_scenario("a"), 0, 1))
        assert not path.exists()
        raise RuntimeError("runner crashed")
    assert list(tmp_path.iterdir()) == []


def test_unfinished_run_has_no_outcome(tmp_path: Path):
    path = tmp_path / "r.rrd"
    with RerunRecorder(path) as rec:
        feed(rec, run_events(load_scenario("a"), 0, 2)[:-1])
    (run,) = summarize_recording(path)["runs"]
    assert run["hops"] == 2 and run["outcome"] is None


def test_bad_files_raise_recording_error(tmp_path: Path, recorded):
    with pytest.raises(RecordingError, match="not found"):
        summarize_recording(tmp_path / "missing.rrd")
    garbage = tmp_path / "garbage.rrd"
    garbage.write_bytes(b"not a recording" * 10)
    with pytest.raises(RecordingError, match="not a readable rerun recording"):
        summarize_recording(garbage)
    data = recorded[0].read_bytes()
    truncated = tmp_path / "truncated.rrd"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError):
        summarize_recording(truncated)
    with pytest.raises(RecordingError, match="folder"):
        RerunRecorder(tmp_path / "no" / "such.rrd")


def _column_rows(path: Path, entity: str, column: str) -> list:
    from rerun.chunk import RrdReader

    rows = []
    for chunk in RrdReader(path).stream().to_chunks():
        if str(chunk.entity_path) == f"/{entity}":
            batch = chunk.to_record_batch()
            hops = batch.column("hop").to_pylist()
            rows += zip(hops, batch.column(column).to_pylist(), strict=True)
    return [v for _, v in sorted(rows, key=lambda r: r[0])]


@pytest.mark.parametrize("flush_every", [1, 2, 100])
def test_buffered_hops_are_written_in_order(tmp_path: Path, flush_every: int):
    path = tmp_path / "r.rrd"
    scenario = load_scenario("a")
    events = run_events(scenario, 0, 5)
    with RerunRecorder(path, flush_every=flush_every) as rec:
        feed(rec, events)
    (run,) = summarize_recording(path)["runs"]
    assert run["hops"] == 5 and run["outcome"] == "success"
    strips = _column_rows(path, "run_0/trajectory", "LineStrips3D:strips")
    assert [len(s[0]) for s in strips] == [2, 3, 4, 5, 6]  # start + landings so far
    assert strips[-1][0][-1][:2] == pytest.approx(events[-2].landing.tolist())
    steps = _column_rows(path, "run_0/hops", "step")
    assert [s[0] for s in steps] == [0, 1, 2, 3, 4]
    rewards = _column_rows(path, "run_0/plots/total_reward", "Scalars:scalars")
    hops = events[2:-1]
    assert [r[0] for r in rewards] == pytest.approx([h.total_reward for h in hops])
