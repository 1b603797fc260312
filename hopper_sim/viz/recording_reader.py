"""Reading hopnav recordings back with rerun's own reader (``rerun.chunk.RrdReader``).

:func:`summarize_recording` says what a recording holds (entities, timelines, whether a
blueprint is present, per run the hops and outcome); :func:`read_runs` returns the scenario and
each run's route, hop times and summary, enough to redraw the figure
(``hopnav figure --rrd``). Runs are numbered from 1, as in the entity paths ``run_K``.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hopper_sim.navigation.events import RunEnd
from hopper_sim.viz.recording import RecordingError
from hopper_sim.viz.rrd_frames import check_rrd

if TYPE_CHECKING:
    from hopper_sim.viz.figures import Route
    from planner.scenario import Scenario

_RUN_RE = re.compile(r"^/?run_(\d+)/(.+)$")


def _first(value: Any) -> Any:
    """AnyValues columns hold one list per row: unwrap a single value; an empty list is a
    ``None`` that was logged after the field had a type (rerun writes it as an empty batch)."""
    if isinstance(value, list):
        if not value:
            return None
        return value[0] if len(value) == 1 else value
    return value


def _read(path: Path) -> tuple[list, Any, bool]:
    """``(chunks of the first recording, its store, whether a blueprint is present)``."""
    from rerun.chunk import RrdReader

    if not path.is_file():
        raise RecordingError(f"no recording at {path}: file not found")
    end = check_rrd(path)  # rerun's decoder aborts the process on some corrupt payloads
    try:
        with warnings.catch_warnings(), tempfile.TemporaryDirectory() as tmp:
            warnings.simplefilter("ignore")  # rerun warns about footer-less (legacy) files
            source = path
            if end < path.stat().st_size:
                # rerun would find the chunks through the footer manifest, which
                # check_rrd cannot vouch for: it gets the checked messages alone
                source = Path(tmp) / "checked.rrd"
                _copy_prefix(path, source, end)
            reader = RrdReader(source)
            stores = reader.recordings()
            if not stores:
                raise RecordingError(f"{path} holds no rerun recording")
            chunks = reader.stream(store=stores[0]).to_chunks()
            has_blueprint = bool(reader.blueprints())
    except RecordingError:
        raise
    except (RuntimeError, ValueError, OSError) as err:
        raise RecordingError(f"{path} is not a readable rerun recording: {err}") from err
    return chunks, stores[0], has_blueprint


@contextmanager
def _content_errors(path: Path) -> Iterator[None]:
    """A recording that rerun decodes but whose content is not what hopnav wrote (a column
    missing or of another type: a corrupt or foreign file) raises :class:`RecordingError`
    naming the file, not the ``KeyError`` or ``TypeError`` of the code reading it."""
    try:
        yield
    except RecordingError:
        raise
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as err:
        raise RecordingError(
            f"{path}: not a recording as hopnav writes it ({type(err).__name__}: {err})"
        ) from err


def _copy_prefix(path: Path, to: Path, size: int) -> None:
    """The first ``size`` bytes of ``path`` into ``to``, a megabyte at a time."""
    with path.open("rb") as src, to.open("wb") as dst:
        while size > 0:
            block = src.read(min(size, 1 << 20))
            if not block:
                break
            dst.write(block)
            size -= len(block)


def _data_rows(chunk) -> tuple[list[dict[str, Any]], Any]:
    """The rows of a chunk as dicts of its data columns, and its record batch."""
    batch = chunk.to_record_batch()
    names = [
        n
        for n in batch.schema.names
        if (batch.schema.field(n).metadata or {}).get(b"rerun:kind") == b"data"
    ]
    columns = {n: batch.column(n).to_pylist() for n in names}
    return [{n: _first(columns[n][i]) for n in names} for i in range(batch.num_rows)], batch


def summarize_recording(path: str | os.PathLike[str]) -> dict[str, Any]:
    """What a recording holds, read back with ``rerun.chunk.RrdReader``.

    Returns:
        ``{"path", "application_id", "recording_id", "blueprint" (whether the file holds a
        blueprint), "provenance" (the values of ``world/provenance`` as text, ``{}`` if
        absent), "entities": [sorted entity paths], "timelines": [sorted names],
        "runs": [per run, by number: {"run" (1-based), "seed", "scenario", "hops" (rows of
        run_K/hops), "outcome" (None if the run did not end), "reason", "steps", "reward",
        "switch_step", "p_switch", "backups", "seconds", "sim_seconds",
        "final_total_reward" (total_reward of the last hop row), "phases" (hops per phase),
        "sources" (hops per source), "backup_hops"}]}``.

    Raises:
        RecordingError: the file is missing, not an ``.rrd``, truncated or holds no recording.
    """
    path = Path(path)
    chunks, store, has_blueprint = _read(path)
    with _content_errors(path):
        return _summarize(path, chunks, store, has_blueprint)


def _summarize(path: Path, chunks: list, store: Any, has_blueprint: bool) -> dict[str, Any]:
    """:func:`summarize_recording` on the decoded chunks."""
    entities: set[str] = set()
    timelines: set[str] = set()
    runs: dict[int, dict[str, Any]] = {}
    hop_rows: dict[int, list[dict[str, Any]]] = {}
    provenance: dict[str, Any] = {}
    keys = ("seed", "scenario", "outcome", "reason", "steps", "reward", "switch_step")
    keys += ("p_switch", "backups", "seconds", "sim_seconds")

    def run(k: int) -> dict[str, Any]:
        return runs.setdefault(k, {"run": k, "hops": 0, **dict.fromkeys(keys)})

    for chunk in chunks:
        entity = str(chunk.entity_path)
        if entity.startswith("/__"):
            continue  # rerun's own properties
        entities.add(entity.lstrip("/"))
        timelines.update(t for t in chunk.timeline_names if t != "log_time")
        if entity.lstrip("/") == "world/provenance" and chunk.num_rows:
            provenance.update(_data_rows(chunk)[0][-1])
        match = _RUN_RE.match(entity)
        if not match:
            continue
        k, rest = int(match.group(1)), match.group(2)
        if rest not in ("hops", "summary", "info"):
            continue
        rows, _ = _data_rows(chunk)
        if rest == "hops":
            hop_rows.setdefault(k, []).extend(rows)
            run(k)
        else:
            for row in rows:
                run(k).update({n: v for n, v in row.items() if n != "run"})

    for k, rows in hop_rows.items():
        rows.sort(key=lambda r: r.get("step", 0))
        r = run(k)
        r["hops"] = len(rows)
        r["final_total_reward"] = rows[-1].get("total_reward") if rows else None
        r["phases"] = _count(rows, "phase")
        r["sources"] = _count(rows, "source")
        r["backup_hops"] = sum(bool(row.get("backup")) for row in rows)

    return {
        "path": str(path),
        "application_id": store.application_id,
        "recording_id": store.recording_id,
        "blueprint": has_blueprint,
        "provenance": provenance,
        "entities": sorted(entities),
        "timelines": sorted(timelines),
        "runs": [runs[k] for k in sorted(runs)],
    }


def _count(rows: list[dict[str, Any]], key: str) -> dict[str, int]:
    values, counts = np.unique([str(row.get(key)) for row in rows], return_counts=True)
    return {str(v): int(c) for v, c in zip(values, counts, strict=True)}


def format_summary(summary: dict[str, Any]) -> str:
    """A plain-text rendering of :func:`summarize_recording`'s result."""
    lines = [
        f"recording {summary['path']} (application {summary['application_id']}, "
        f"id {summary['recording_id']}, {'with' if summary.get('blueprint') else 'no'} "
        "blueprint)",
        "provenance: "
        + (", ".join(f"{k} {v}" for k, v in summary.get("provenance", {}).items()) or "-"),
        f"timelines: {', '.join(summary['timelines']) or '-'}",
        f"entities ({len(summary['entities'])}):",
        *(f"  {e}" for e in summary["entities"]),
        f"runs: {len(summary['runs'])} (numbered from 1)",
    ]
    for r in summary["runs"]:
        outcome = r["outcome"] or "unfinished"
        reward = "-" if r["reward"] is None else f"{r['reward']:g}"
        switch = "-" if r["switch_step"] is None else str(r["switch_step"] + 1)
        sim = "-" if r.get("sim_seconds") is None else f"{r['sim_seconds']:.2f} s"
        lines.append(
            f"  run {r['run']}: {r['hops']} hops, outcome {outcome}, reward {reward}, "
            f"switch at hop {switch}, backups "
            f"{r['backups'] if r['backups'] is not None else '-'}, simulated {sim}"
        )
    return "\n".join(lines)


# --------------------------------------------------------------------------- runs back


@dataclass(frozen=True)
class RecordedRun:
    """A run read back from a recording (:func:`read_runs`).

    Attributes:
        run: the 1-based run number.
        route: its route, as the figures draw it.
        sim_time: ``(n,)`` sim_time of each hop's row (the hop's end), s.
        durations: ``(n,)`` the hops' durations, s.
        summary: the run's summary record (empty if the run did not end).
    """

    run: int
    route: Route
    sim_time: np.ndarray
    durations: np.ndarray
    summary: dict[str, Any]

    @property
    def end(self) -> RunEnd | None:
        """The run's end as an event (for figure titles), or ``None`` if it did not end."""
        s = self.summary
        if s.get("outcome") is None:
            return None
        return RunEnd(
            run_index=self.run - 1,
            outcome=s["outcome"],
            steps=int(s["steps"]),
            reward=float(s["reward"]),
            switch_step=s.get("switch_step"),
            p_switch=s.get("p_switch"),
            backups=int(s.get("backups") or 0),
            seconds=float(s.get("seconds") or 0.0),
            reason=str(s.get("reason") or ""),
            left_plan_step=s.get("left_plan_step"),
        )


def duration_seconds(column) -> np.ndarray:
    """A rerun duration time column (arrow ``duration[ns]``) in seconds."""
    import pyarrow as pa

    return column.cast(pa.int64()).to_numpy(zero_copy_only=False).astype(float) * 1e-9


def read_runs(path: str | os.PathLike[str]) -> tuple[Scenario, list[RecordedRun]]:
    """The scenario and the runs of a recording written by :class:`RerunRecorder`.

    Raises:
        RecordingError: the file is unreadable, or it holds no scenario (``world/scenario``;
            recordings of older versions lack it).
    """
    path = Path(path)
    chunks, _, _ = _read(path)
    with _content_errors(path):
        return _runs(path, chunks)


def _runs(path: Path, chunks: list) -> tuple[Scenario, list[RecordedRun]]:
    """:func:`read_runs` on the decoded chunks."""
    from hopper_sim.viz.figures import Route
    from planner.errors import ScenarioError
    from planner.scenario import scenario_from_dict

    scenario_json = None
    hops: dict[int, list[tuple[dict[str, Any], float]]] = {}
    arcs: dict[int, dict[int, np.ndarray]] = {}
    segments: dict[int, dict[int, np.ndarray]] = {}
    summaries: dict[int, dict[str, Any]] = {}
    for chunk in chunks:
        entity = str(chunk.entity_path).lstrip("/")
        if entity == "world/scenario":
            rows, _ = _data_rows(chunk)
            scenario_json = rows[-1].get("scenario_json") if rows else None
            continue
        match = _RUN_RE.match(entity)
        if not match:
            continue
        k, rest = int(match.group(1)), match.group(2)
        if rest == "hops":
            rows, batch = _data_rows(chunk)
            times = duration_seconds(batch.column("sim_time"))
            hops.setdefault(k, []).extend(zip(rows, times, strict=True))
        elif rest in ("hop/com_arc", "route"):
            batch = chunk.to_record_batch()
            seq = batch.column("hop").to_pylist()
            strips = batch.column("LineStrips3D:strips").to_pylist()
            into = arcs if rest == "hop/com_arc" else segments
            for h, s in zip(seq, strips, strict=True):
                into.setdefault(k, {})[int(h)] = np.asarray(s[0], dtype=float)[:, :2]
        elif rest == "summary":
            rows, _ = _data_rows(chunk)
            for row in rows:
                summaries.setdefault(k, {}).update(row)
    if scenario_json is None:
        raise RecordingError(f"{path} holds no scenario (world/scenario): it cannot be redrawn")
    try:
        scenario = scenario_from_dict(json.loads(scenario_json))
    except (ScenarioError, ValueError) as err:
        raise RecordingError(f"{path}: the recorded scenario is invalid: {err}") from err
    out = []
    for k in sorted(set(hops) | set(summaries)):
        rows = sorted(hops.get(k, []), key=lambda r: r[0]["step"])
        tracks = []
        for r, _ in rows:
            h = int(r["step"]) + 1
            track = arcs.get(k, {}).get(h)
            if track is None or len(track) < 2:
                track = segments.get(k, {}).get(h)
            if track is None:
                raise RecordingError(f"{path}: run {k}, hop {h} has no CoM arc or route segment")
            tracks.append(track)
        summary = summaries.get(k, {})
        route = Route(
            start=np.asarray(scenario.start, dtype=float),
            tracks=tuple(tracks),
            phases=tuple(str(r["phase"]) for r, _ in rows),
            backups=np.array([bool(r["backup"]) for r, _ in rows], dtype=bool),
            switch_step=summary.get("switch_step"),
        )
        out.append(
            RecordedRun(
                run=k,
                route=route,
                sim_time=np.array([t for _, t in rows]),
                durations=np.array([float(r.get("duration", np.nan)) for r, _ in rows]),
                summary=summary,
            )
        )
    return scenario, out
