import dataclasses
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from hopper_sim.navigation.events import (
    HopEvent,
    Observers,
    ResynthesisRecord,
    RunEnd,
    SynthesisEvent,
)
from hopper_sim.viz.recording import RecordingError, RerunRecorder, scenario_record
from hopper_sim.viz.recording_reader import format_summary, read_runs, summarize_recording
from planner.scenario import load_scenario
from tests.hopper_sim.synthetic_runs import feed, run_events

EXPECTED_RUN_ENTITIES = [
    "hop/com_arc",
    "hop/foot",
    "hop/leg",
    "hop/target",
    "hop/landing",
    "route",
    "com",
    "hops",
    "status",
    "plots/p_worst",
    "plots/total_reward",
    "plots/reward",
    "plots/phase",
    "plots/rl_action",
    "plots/backup",
    "plots/p_worst_initial",
    "gp/mean",
    "gp/std",
    "gp/image/mean_x",
    "gp/image/mean_y",
    "gp/image/std_x",
    "gp/image/std_y",
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


def _chunks(path: Path, entity: str, store: str = "recording"):
    reader = RrdReader(path)
    (entry,) = reader.recordings() if store == "recording" else reader.blueprints()
    return [c for c in reader.stream(store=entry).to_chunks() if str(c.entity_path) == entity]


def _column(path: Path, entity: str, column: str, order: str = "hop") -> list:
    """One column of an entity, rows sorted by the ``order`` timeline."""
    rows = []
    for chunk in _chunks(path, f"/{entity}"):
        batch = chunk.to_record_batch()
        key = batch.column(order).cast("int64").to_pylist()
        values = batch.column(column)
        if pa.types.is_duration(values.type):
            values = values.cast("int64")  # nanoseconds
        rows += zip(key, values.to_pylist(), strict=True)
    return [v for _, v in sorted(rows, key=lambda r: r[0])]


def _sim_time(path: Path, entity: str) -> np.ndarray:
    """sim_time of an entity's rows in seconds, in hop order (read as raw nanoseconds)."""
    return np.array(_column(path, entity, "sim_time"), dtype=float) * 1e-9


def test_recording_holds_world_and_run_entities(recorded):
    path, scenario = recorded
    s = summarize_recording(path)
    assert s["application_id"] == "hopnav" and s["recording_id"] == "test"
    ents = set(s["entities"])
    for e in ["world/info", "world/legend", "world/grid", "world/cells/initial", "world/start"]:
        assert e in ents
    assert "world/regions" in ents and "world/scenario" in ents
    for label in scenario.regions:
        assert f"world/cells/{label}" in ents
    for k in (1, 2):  # runs are numbered from 1
        missing = [e for e in EXPECTED_RUN_ENTITIES if f"run_{k}/{e}" not in ents]
        assert missing == []
    assert not any(e.startswith("run_0/") for e in ents)
    assert {"hop", "sim_time"} <= set(s["timelines"])


def test_regions_are_labelled_once_each_not_per_cell(recorded):
    path, scenario = recorded
    (chunk,) = _chunks(path, "/world/regions")
    labels = chunk.to_record_batch().column("Points3D:labels").to_pylist()[0]
    assert "A A +20" in labels and "W weak -0.5" in labels and "I initial" in labels
    assert labels.count("H Haz 0") == 4  # the wall (two pieces) and two blocks
    n_cells = sum(int(scenario.region_mask(lab).sum()) for lab in scenario.regions)
    assert len(labels) < n_cells / 3
    for label in scenario.regions:
        (cells,) = _chunks(path, f"/world/cells/{label}")
        assert "Boxes3D:labels" not in cells.to_record_batch().schema.names


def test_sim_time_is_cumulative_over_hops(recorded):
    path, scenario = recorded
    for k, n in ((0, 6), (1, 3)):
        hops = [e for e in run_events(scenario, k, n) if isinstance(e, HopEvent)]
        durations = np.array([h.com_time[-1] for h in hops])  # each hop's own end time
        t = _sim_time(path, f"run_{k + 1}/hops")
        assert np.all(np.diff(t) > 0)
        np.testing.assert_allclose(t, np.cumsum(durations), atol=1e-9)
        touchdown = _sim_time(path, f"run_{k + 1}/hop/foot")
        starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        np.testing.assert_allclose(touchdown, starts + 0.2, atol=1e-9)
        com = _sim_time(path, f"run_{k + 1}/com")
        assert com.min() == pytest.approx(0.0) and com.max() == pytest.approx(durations.sum())
        assert _column(path, f"run_{k + 1}/hops", "step") == [[s] for s in range(n)]


def test_blueprint_is_in_the_file(recorded):
    path, _ = recorded
    assert summarize_recording(path)["blueprint"] is True
    reader = RrdReader(path)
    (bp,) = reader.blueprints()
    views, timeline = {}, None
    for chunk in reader.stream(store=bp).to_chunks():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "ViewBlueprint:class_identifier" in names:
            kind = batch.column("ViewBlueprint:class_identifier").to_pylist()[0][0]
            name = batch.column("ViewBlueprint:display_name").to_pylist()[0][0]
            views.setdefault(kind, []).append(name)
        if "TimePanelBlueprint:timeline" in names:
            timeline = batch.column("TimePanelBlueprint:timeline").to_pylist()[0][0]
    assert timeline == "sim_time"
    assert sorted(views["3D"]) == ["world, run 1", "world, run 2"]
    assert len(views["TimeSeries"]) == 2 * 5  # P-check, reward, phase, RL, backup per run
    assert len(views["2D"]) == 2 * 4  # the GP maps
    assert sorted(views["TextDocument"]) == ["legend", "legend", "outcome", "outcome"]


def test_recording_is_consistent_with_the_runs(recorded):
    path, scenario = recorded
    runs = summarize_recording(path)["runs"]
    assert [r["run"] for r in runs] == [1, 2]
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
    durations = [h.com_time[-1] for h in events if isinstance(h, HopEvent)]
    assert r0["sim_seconds"] == pytest.approx(sum(durations))
    text = format_summary(summarize_recording(path))
    assert "run 1: 6 hops, outcome success" in text and "run 2: 3 hops, outcome timeout" in text
    assert "with blueprint" in text


def test_runs_read_back_for_figures(recorded):
    path, scenario = recorded
    sc, runs = read_runs(path)
    assert scenario_record(sc) == scenario_record(scenario)
    assert [r.run for r in runs] == [1, 2]
    hops = [e for e in run_events(scenario, 0, 6) if isinstance(e, HopEvent)]
    route = runs[0].route
    assert route.phases == tuple(h.phase for h in hops)
    assert route.backups.tolist() == [h.backup for h in hops]
    assert route.switch_step == 3
    for track, h in zip(route.tracks, hops, strict=True):
        np.testing.assert_allclose(track[[0, -1]], h.com_path[[0, -1], :2], atol=1e-6)
    np.testing.assert_allclose(runs[0].durations, [h.com_time[-1] for h in hops])
    assert runs[0].end.outcome == "success" and runs[1].end.steps == 3


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


class _ForeignChunk:
    """A chunk that rerun decodes but hopnav did not write: a route without its columns."""

    entity_path = "/run_1/route"

    def to_record_batch(self):
        return pa.record_batch({"x": pa.array([1.0])})


def test_decodable_but_foreign_content_raises_recording_error(tmp_path: Path, monkeypatch):
    # found by the reader fuzz test: a bit flip in a column name left read_runs with a
    # KeyError from pyarrow
    import hopper_sim.viz.recording_reader as reader

    monkeypatch.setattr(reader, "_read", lambda path: ([_ForeignChunk()], None, False))
    with pytest.raises(RecordingError, match=r"r\.rrd: not a recording as hopnav writes it"):
        read_runs(tmp_path / "r.rrd")


@pytest.mark.parametrize("flush_every", [1, 2, 100])
def test_buffered_hops_are_written_in_order(tmp_path: Path, flush_every: int):
    path = tmp_path / "r.rrd"
    scenario = load_scenario("a")
    events = run_events(scenario, 0, 5)
    with RerunRecorder(path, flush_every=flush_every) as rec:
        feed(rec, events)
    (run,) = summarize_recording(path)["runs"]
    assert run["hops"] == 5 and run["outcome"] == "success"
    segments = _column(path, "run_1/route", "LineStrips3D:strips")
    hops = events[2:-1]
    assert len(segments) == 5 and all(len(s[0]) == 2 for s in segments)  # one segment per hop
    for seg, h in zip(segments, hops, strict=True):
        np.testing.assert_allclose(np.array(seg[0])[:, :2], [h.start_pos, h.landing], atol=1e-6)
    steps = _column(path, "run_1/hops", "step")
    assert [s[0] for s in steps] == [0, 1, 2, 3, 4]
    rewards = _column(path, "run_1/plots/total_reward", "Scalars:scalars")
    assert [r[0] for r in rewards] == pytest.approx([h.total_reward for h in hops])
    assert np.all(np.diff(_sim_time(path, "run_1/hops")) > 0)


def _size(tmp_path: Path, name: str, scenario, runs: int, hops: int) -> int:
    path = tmp_path / f"{name}.rrd"
    with RerunRecorder(path, recording_id="size") as rec:
        for k in range(runs):
            feed(rec, run_events(scenario, k, hops, samples=240))
    return path.stat().st_size


def test_recording_grows_linearly(tmp_path: Path):
    c = load_scenario("c")
    one = _size(tmp_path, "one", c, 1, 60)
    ten = _size(tmp_path, "ten", c, 10, 60)
    assert ten <= 12 * one, (one, ten)
    empty, half, full = (_size(tmp_path, f"h{n}", c, 1, n) for n in (0, 100, 200))
    # quadratic growth (the whole path re-logged per hop) would make the second 100 hops
    # cost three times the first
    assert full - half <= 1.25 * (half - empty), (empty, half, full)


@dataclasses.dataclass(frozen=True)
class _HopPlus(HopEvent):
    margin: float = 0.25
    note: str = "ok"


@dataclasses.dataclass(frozen=True)
class _SynthesisPlus(SynthesisEvent):
    p_worst_current: float = 0.5
    hyper: dict = dataclasses.field(default_factory=lambda: {"lengthscale": 1.5, "noise": 0.01})
    kernel: str = "rbf"


@dataclasses.dataclass(frozen=True)
class _EndPlus(RunEnd):
    end_reason: str = "goal reached"


def _plus(event):
    kind = {HopEvent: _HopPlus, SynthesisEvent: _SynthesisPlus, RunEnd: _EndPlus}.get(type(event))
    if kind is None:
        return event
    return kind(**{f.name: getattr(event, f.name) for f in dataclasses.fields(event)})


def test_recorder_keeps_new_event_fields(tmp_path: Path):
    path = tmp_path / "plus.rrd"
    with RerunRecorder(path) as rec:
        feed(rec, [_plus(e) for e in run_events(load_scenario("a"), 0, 3)])
    ents = set(summarize_recording(path)["entities"])
    assert {"run_1/synthesis/p_worst_current", "run_1/synthesis/hyper/lengthscale"} <= ents
    assert _column(path, "run_1/hops", "margin") == [[0.25]] * 3
    assert _column(path, "run_1/hops", "note") == [["ok"]] * 3
    (run,) = summarize_recording(path)["runs"]
    assert run["outcome"] == "success"
    (chunk,) = _chunks(path, "/run_1/summary")
    assert chunk.to_record_batch().column("end_reason").to_pylist() == [["goal reached"]]


def test_synthesis_reports_are_time_series_and_in_the_outcome(tmp_path: Path):
    """Each synthesis's record (current P-check, fit values, chosen component) is logged."""
    records = (
        ResynthesisRecord(
            0, 0.0, 0.0, 0, {"lengthscale": (1.5, 2.5), "noise": (0.01,)}, 12, 1.0, 3.5
        ),
        ResynthesisRecord(2, 0.875, 0.5, 2, {"lengthscale": (1.25, 2.0), "noise": (0.02,)}),
    )
    events = run_events(load_scenario("a"), 0, 3)
    synth = next(e for e in events if isinstance(e, SynthesisEvent))
    later = dataclasses.replace(synth, step=2, record=records[1])
    events = [dataclasses.replace(e, record=records[0]) if e is synth else e for e in events]
    events.insert(len(events) - 1, later)
    events[-1] = dataclasses.replace(events[-1], resyntheses=records, collections=2)
    path = tmp_path / "records.rrd"
    with RerunRecorder(path) as rec:
        feed(rec, events)
    assert _column(path, "run_1/plots/p_worst_current", "Scalars:scalars") == [[0.0], [0.875]]
    assert _column(path, "run_1/gp/fit/lengthscale", "Scalars:scalars") == [[1.5, 2.5], [1.25, 2.0]]
    assert _column(path, "run_1/synthesis/num_data", "Scalars:scalars") == [[0.0], [2.0]]
    assert _column(path, "run_1/synthesis/mec_states", "Scalars:scalars") == [[12.0], [0.0]]
    assert _column(path, "run_1/synthesis/mec_probability", "Scalars:scalars") == [[1.0]]
    (text,) = _column(path, "run_1/outcome", "TextDocument:text")
    assert "0: 0.000, 2: 0.875" in text[0]
    (chunk,) = _chunks(path, "/run_1/summary")
    assert chunk.to_record_batch().column("collections").to_pylist() == [[2]]


def test_gp_maps_are_images_with_y_up(recorded):
    from hopper_sim.viz.recording import _color_map

    values = np.array([[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]])  # (Gx=3, Gy=2): rises with y
    image = _color_map(values, "viridis", 0.0, 1.0)
    assert image.shape == (2, 3, 3) and image.dtype == np.uint8
    assert image[0].mean() > image[1].mean()  # the top row is y = max (viridis is bright)
    path, _ = recorded
    (chunk,) = _chunks(path, "/run_1/gp/image/std_x")
    assert "Image:buffer" in chunk.to_record_batch().schema.names


def test_real_runs_have_cumulative_sim_time(tmp_path: Path):
    """Two short runs of case (c) through the runner: sim_time adds the hops' durations."""
    from hopper_sim.navigation.runner import NavigationRunner

    class Keep:
        def __init__(self):
            self.durations = {}

        def on_run_start(self, e): ...
        def on_synthesis(self, e): ...
        def on_run_end(self, e): ...
        def close(self): ...

        def on_hop(self, e):
            self.durations.setdefault(e.run_index, []).append(e.com_time[-1])

    keep = Keep()
    path = tmp_path / "c.rrd"
    scenario = load_scenario("c").with_runner(max_steps=4)
    with RerunRecorder(path) as rec:
        NavigationRunner(scenario, observer=Observers([rec, keep])).run_many(2, 3)
    for k, durations in keep.durations.items():
        t = _sim_time(path, f"run_{k + 1}/hops")
        assert len(t) == len(durations) and np.all(np.diff(t) > 0)
        np.testing.assert_allclose(t, np.cumsum(durations), atol=1e-9)
        assert 0.3 < np.mean(durations) < 2.0  # hops last about a second, not a touchdown time


def test_none_fields_read_back_as_none_after_a_typed_value(tmp_path: Path):
    """rerun writes a None as an empty batch once the field has had a type in the process."""
    scenario = load_scenario("a")
    path = tmp_path / "none.rrd"
    with RerunRecorder(path) as rec:
        feed(rec, run_events(scenario, 0, 2))  # switch_step = 1
        events = run_events(scenario, 1, 2)
        events[-1] = dataclasses.replace(events[-1], switch_step=None, p_switch=None)
        feed(rec, events)
    first, second = summarize_recording(path)["runs"]
    assert first["switch_step"] == 1 and second["switch_step"] is None
    assert second["p_switch"] is None
    assert "run 2: 2 hops, outcome success, reward" in format_summary(summarize_recording(path))
