"""rerun recordings of navigation runs, and a reader that summarises them.

:class:`RerunRecorder` is an :class:`~hopper_sim.events.Observer` that writes one rerun
recording (``.rrd``, rerun-sdk 0.41, headless file sink) per invocation. It writes to a
temporary file beside the target and moves it into place on :meth:`RerunRecorder.close`, so
a crashed invocation never leaves a half-written recording. Hops are buffered per run and
written with ``send_columns`` (one call per entity for up to ``flush_every`` hops), at each
synthesis, at the run's end and on close. :func:`summarize_recording` reads a
recording back with rerun's own reader (``rerun.chunk.RrdReader``).

Timelines: ``hop`` (the hop number within a run: hop ``k`` is logged at ``hop = k``, a
re-synthesis after ``k`` hops at ``hop = k``) and ``sim_time`` (seconds of simulated time since
the run started). Wall-clock log times are not recorded, so the same events give the same
recording. All positions are world metres, z up.

Entity paths (``K`` is the run index)::

    world/info                   TextDocument  scenario name, formula, settings   (static)
    world/grid                   LineStrips3D  cell borders                       (static)
    world/cells/initial          Boxes3D       initial region (blue)              (static)
    world/cells/<label>          Boxes3D       cells of each label, coloured      (static)
    world/rewards                Points3D      cells with a reward, labelled "+20" (static;
                                               the true rewards, also when unknown to
                                               the planner)
    world/start                  Points3D      start position                     (static)
    run_K/info                   AnyValues     run_index, seed, scenario          (static)
    run_K/hop/com_arc            LineStrips3D  this hop's CoM arc (T points)
    run_K/hop/foot               Points3D      foot at touchdown
    run_K/hop/leg                LineStrips3D  leg at touchdown (foot to CoM)
    run_K/hop/target             Points3D      target cell centre of the hop
    run_K/hop/landing            Points3D      landing (next interstitial CoM, z = 0)
    run_K/trajectory             LineStrips3D  all landings so far, joined
    run_K/com                    Points3D      the CoM along sim_time (when com_time given)
    run_K/hops                   AnyValues     step, phase, source, backup, requested_action,
                                               executed_action, cell, product_state, p_worst,
                                               reward, total_reward (one row per hop)
    run_K/status                 TextLog       one line per hop (phase, source, backup)
    run_K/plots/p_worst          Scalars       worst-case satisfaction probability
    run_K/plots/total_reward     Scalars       reward collected so far
    run_K/plots/phase            Scalars       0 exploration, 1 goal reaching
    run_K/plots/rl_action        Scalars       1 if the RL policy chose the action
    run_K/plots/backup           Scalars       1 if the backup switch replaced the action
    run_K/plots/p_worst_initial  Scalars       at each synthesis
    run_K/gp/mean_x, mean_y      Tensor        GP posterior mean of the landing error, (Gx, Gy)
    run_K/gp/std_x, std_y        Tensor        GP posterior std of the landing error, (Gx, Gy)
    run_K/gp/mean_field          Arrows3D      GP mean error as arrows at the grid points
    run_K/timings/<stage>        Scalars       seconds per synthesis stage
    run_K/outcome                TextDocument  outcome line at the end of the run
    run_K/summary                AnyValues     outcome, steps, reward, switch_step, p_switch,
                                               backups, seconds, timing_<stage>
"""

from __future__ import annotations

import contextlib
import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from hopper_sim.events import HopEvent, Observer, RunEnd, RunStart, SynthesisEvent
from hopper_sim.styles import INITIAL_COLOR, LANDING_COLOR, TRAJECTORY_COLOR, label_colors

APPLICATION_ID = "hopnav"
_FLOOR_Z = 0.0
_RUN_RE = re.compile(r"^/?run_(\d+)/(.+)$")


class RecordingError(ValueError):
    """A recording cannot be written or read (missing, corrupt or truncated file...)."""


def _run(k: int) -> str:
    return f"run_{k}"


def _status_line(h: HopEvent) -> str:
    backup = f" (backup for {h.requested_action})" if h.backup else ""
    return (
        f"hop {h.step}: {h.phase}, {h.source} action {h.executed_action}{backup}, "
        f"p_worst {h.p_worst:.3f}, reward {h.reward:+g} (total {h.total_reward:+g})"
    )


class RerunRecorder(Observer):
    """Observer writing every event of an invocation to one ``.rrd`` file.

    Args:
        path: the ``.rrd`` file to write (its folder must exist).
        application_id: rerun application id.
        recording_id: rerun recording id (default: a fresh one).
        flush_every: hops buffered per run before they are written as columns (they are
            also written at each synthesis, at the run's end and on close); logging in
            columns costs far less per hop than one ``log`` call per entity and hop.

    Use as a context manager, or call :meth:`close` after the last run: the file appears at
    ``path`` only then. Leaving the context by an exception discards the recording.

    Raises:
        RecordingError: the folder of ``path`` does not exist.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        application_id: str = APPLICATION_ID,
        recording_id: str | None = None,
        flush_every: int = 100,
    ) -> None:
        if flush_every < 1:
            raise RecordingError(f"flush_every must be at least 1, got {flush_every}")
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise RecordingError(f"cannot write {self.path}: folder {self.path.parent} missing")
        self._tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        self._rec = rr.RecordingStream(application_id, recording_id=recording_id)
        self._rec.set_log_time_enabled(False)
        self._rec.set_log_tick_enabled(False)
        self._rec.set_sinks(rr.FileSink(str(self._tmp)))
        self._world_logged: str | None = None
        self.flush_every = int(flush_every)
        self._pending: dict[int, list[HopEvent]] = {}
        self._landings: dict[int, list[np.ndarray]] = {}
        self._sim_time: dict[int, float] = {}
        self._closed = False

    # -- context manager -------------------------------------------------------------
    def __enter__(self) -> RerunRecorder:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.discard()

    def close(self) -> None:
        """Finish the file and move it to :attr:`path` (idempotent)."""
        if self._closed:
            return
        for k in list(self._pending):
            self._flush_hops(k)
        self._closed = True
        self._rec.flush()
        self._rec.disconnect()
        os.replace(self._tmp, self.path)

    def discard(self) -> None:
        """Stop recording and delete the temporary file; nothing appears at :attr:`path`."""
        if self._closed:
            return
        self._closed = True
        self._rec.disconnect()
        with contextlib.suppress(FileNotFoundError):
            self._tmp.unlink()

    def _time(self, hop: int, sim_time: float) -> None:
        self._rec.set_time("hop", sequence=int(hop))
        self._rec.set_time("sim_time", duration=float(sim_time))

    # -- the world -------------------------------------------------------------------
    def _log_world(self, event: RunStart) -> None:
        sc = event.scenario
        w = sc.world
        rec = self._rec
        info = (
            f"# Scenario {sc.name}\n\n{sc.description}\n\n"
            f"- world: {w.width} x {w.height} m, cells of {w.cell} m ({w.nx} x {w.ny})\n"
            f"- formula: `{sc.formula}`; hazard label `{sc.hazard}`, goal label `{sc.goal}`\n"
            f"- P_sat = {sc.p_sat}; reward known: {sc.reward_known}\n"
            f"- rewards: {dict(sc.rewards)}\n- runner: {sc.runner}\n"
        )
        rec.log("world/info", rr.TextDocument(info, media_type="text/markdown"), static=True)
        xs = np.arange(w.nx + 1) * w.cell
        ys = np.arange(w.ny + 1) * w.cell
        strips = [[[x, 0.0, _FLOOR_Z], [x, w.height, _FLOOR_Z]] for x in xs]
        strips += [[[0.0, y, _FLOOR_Z], [w.width, y, _FLOOR_Z]] for y in ys]
        rec.log(
            "world/grid",
            rr.LineStrips3D(strips, colors=[(160, 160, 160)], radii=[0.005]),
            static=True,
        )
        centers = w.cell_centers().reshape(w.nx, w.ny, 2)
        half = [0.5 * w.cell, 0.5 * w.cell, 0.005]

        def boxes(mask: np.ndarray, color, name: str) -> rr.Boxes3D:
            c = centers[mask]
            return rr.Boxes3D(
                centers=np.column_stack([c, np.full(len(c), _FLOOR_Z)]),
                half_sizes=[half] * len(c),
                colors=[(*color, 160)],
                fill_mode="solid",
                labels=[name] * len(c) if len(c) < 64 else None,
            )

        rec.log("world/cells/initial", boxes(sc.initial_mask, INITIAL_COLOR, "init"), static=True)
        colors = label_colors(sc.labels, sc.goal, sc.hazard)
        for label in sc.regions:
            rec.log(
                f"world/cells/{label}",
                boxes(sc.region_mask(label), colors[label], label),
                static=True,
            )
        rewarded = sc.reward_grid != 0
        c = centers[rewarded]
        rec.log(
            "world/rewards",
            rr.Points3D(
                np.column_stack([c, np.full(len(c), 0.05)]),
                labels=[f"{r:+g}" for r in sc.reward_grid[rewarded]],
                radii=[0.04],
            ),
            static=True,
        )
        rec.log(
            "world/start",
            rr.Points3D([[*sc.start, 0.05]], colors=[INITIAL_COLOR], radii=[0.12]),
            static=True,
        )

    # -- observer handlers -----------------------------------------------------------
    def on_run_start(self, event: RunStart) -> None:
        """Log the world (once per scenario) and the run's static info."""
        if self._world_logged != event.scenario.name:
            self._log_world(event)
            self._world_logged = event.scenario.name
        k = event.run_index
        self._flush_hops(k)
        self._landings[k] = [np.array([*event.scenario.start, _FLOOR_Z])]
        self._sim_time[k] = 0.0
        self._rec.log(
            f"{_run(k)}/info",
            rr.AnyValues(run_index=k, seed=int(event.seed), scenario=event.scenario.name),
            static=True,
        )

    def on_hop(self, event: HopEvent) -> None:
        """Buffer the hop; hops are written in columns at each synthesis, run end or close."""
        k = event.run_index
        self._pending.setdefault(k, []).append(event)
        t_end = float(event.com_time[-1]) if event.com_time is not None else event.touchdown_time
        self._sim_time[k] = max(self._sim_time.get(k, 0.0), t_end)
        if len(self._pending[k]) >= self.flush_every:
            self._flush_hops(k)

    def _flush_hops(self, k: int) -> None:
        """Write the buffered hops of run ``k`` with one ``send_columns`` per entity.

        Each hop is one row at ``hop = step`` and ``sim_time = touchdown_time``.
        """
        hops = self._pending.pop(k, [])
        if not hops:
            return
        base, send, n = _run(k), self._rec.send_columns, len(hops)
        steps = np.array([h.step for h in hops], dtype=np.int64)
        index = [
            rr.TimeColumn("hop", sequence=steps),
            rr.TimeColumn("sim_time", duration=np.array([h.touchdown_time for h in hops])),
        ]

        def rows(value) -> np.ndarray:
            return np.tile(np.asarray(value), (n, 1))

        send(
            f"{base}/hop/com_arc",
            index,
            rr.LineStrips3D.columns(
                strips=[h.com_path for h in hops], colors=rows(TRAJECTORY_COLOR)
            ),
        )
        feet = np.array([h.foot for h in hops])
        send(f"{base}/hop/foot", index, rr.Points3D.columns(positions=feet, radii=np.full(n, 0.06)))
        legs = [np.stack([h.foot, self._com_at_touchdown(h)]) for h in hops]
        send(f"{base}/hop/leg", index, rr.LineStrips3D.columns(strips=legs, radii=np.full(n, 0.02)))
        targets = np.column_stack([[h.target for h in hops], np.full(n, 0.02)])
        send(
            f"{base}/hop/target",
            index,
            rr.Points3D.columns(positions=targets, colors=rows((0, 0, 0)), radii=np.full(n, 0.1)),
        )
        landings = np.column_stack([[h.landing for h in hops], np.full(n, _FLOOR_Z)])
        send(
            f"{base}/hop/landing",
            index,
            rr.Points3D.columns(
                positions=landings, colors=rows(LANDING_COLOR), radii=np.full(n, 0.08)
            ),
        )
        done = self._landings.setdefault(k, [])
        first = len(done)
        done.extend(landings)
        path = np.asarray(done)
        send(
            f"{base}/trajectory",
            index,
            rr.LineStrips3D.columns(
                strips=[path[: first + m + 1] for m in range(n)], colors=rows(LANDING_COLOR)
            ),
        )
        send(
            f"{base}/hops",
            index,
            rr.AnyValues.columns(
                step=steps,
                phase=[h.phase for h in hops],
                source=[h.source for h in hops],
                backup=np.array([h.backup for h in hops], dtype=bool),
                requested_action=[h.requested_action for h in hops],
                executed_action=[h.executed_action for h in hops],
                cell=np.array([h.cell for h in hops], dtype=np.int64),
                product_state=np.array([h.product_state for h in hops], dtype=np.int64),
                p_worst=np.array([h.p_worst for h in hops], dtype=float),
                reward=np.array([h.reward for h in hops], dtype=float),
                total_reward=np.array([h.total_reward for h in hops], dtype=float),
            ),
        )
        send(
            f"{base}/status",
            index,
            rr.TextLog.columns(
                text=[_status_line(h) for h in hops],
                level=["WARN" if h.backup else "INFO" for h in hops],
            ),
        )
        plots = {
            "p_worst": [h.p_worst for h in hops],
            "total_reward": [h.total_reward for h in hops],
            "phase": [1.0 if h.phase == "goal_reaching" else 0.0 for h in hops],
            "rl_action": [1.0 if h.source == "RL" else 0.0 for h in hops],
            "backup": [1.0 if h.backup else 0.0 for h in hops],
        }
        for name, values in plots.items():
            send(f"{base}/plots/{name}", index, rr.Scalars.columns(scalars=np.asarray(values)))
        timed = [h for h in hops if h.com_time is not None]
        if timed:
            send(
                f"{base}/com",
                [
                    rr.TimeColumn("sim_time", duration=np.concatenate([h.com_time for h in timed])),
                    rr.TimeColumn(
                        "hop",
                        sequence=np.concatenate([np.full(len(h.com_path), h.step) for h in timed]),
                    ),
                ],
                rr.Points3D.columns(positions=np.concatenate([h.com_path for h in timed])),
            )

    @staticmethod
    def _com_at_touchdown(event: HopEvent) -> np.ndarray:
        """CoM at touchdown: interpolated in ``com_time`` if given, else the path point
        nearest to the foot (the CoM is above the foot at touchdown, at leg length)."""
        path = event.com_path
        if event.com_time is not None and len(path) > 1:
            return np.array(
                [np.interp(event.touchdown_time, event.com_time, path[:, d]) for d in range(3)]
            )
        return path[np.argmin(np.linalg.norm(path - event.foot, axis=1))]

    def on_synthesis(self, event: SynthesisEvent) -> None:
        """Log the GP maps, the initial state's worst-case probability and stage timings."""
        k, rec = event.run_index, self._rec
        base = _run(k)
        self._flush_hops(k)
        self._time(event.step, self._sim_time.get(k, 0.0))
        for d, axis in enumerate("xy"):
            rec.log(
                f"{base}/gp/mean_{axis}", rr.Tensor(event.gp_mean[..., d], dim_names=("x", "y"))
            )
            rec.log(f"{base}/gp/std_{axis}", rr.Tensor(event.gp_std[..., d], dim_names=("x", "y")))
        gx, gy = np.meshgrid(event.grid_x, event.grid_y, indexing="ij")
        origins = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, 0.03)])
        vectors = np.column_stack([event.gp_mean.reshape(-1, 2), np.zeros(gx.size)])
        rec.log(
            f"{base}/gp/mean_field",
            rr.Arrows3D(origins=origins, vectors=vectors, colors=[(30, 90, 200)], radii=[0.01]),
        )
        rec.log(f"{base}/plots/p_worst_initial", rr.Scalars(float(event.p_worst_initial)))
        if event.record is not None:  # the current state's P and the refit's hyperparameters
            r = event.record
            rec.log(f"{base}/plots/p_worst_current", rr.Scalars(float(r.p_worst_current)))
            rec.log(f"{base}/gp/hyperparameters", rr.AnyValues(**r.gp))
        for stage, seconds in event.timings.items():
            rec.log(f"{base}/timings/{stage}", rr.Scalars(float(seconds)))

    def on_run_end(self, event: RunEnd) -> None:
        """Log the outcome line and the run's summary record."""
        k, rec = event.run_index, self._rec
        base = _run(k)
        self._flush_hops(k)
        self._time(event.steps, self._sim_time.get(k, 0.0))
        switch = (
            f"switched at hop {event.switch_step} (p_worst {event.p_switch:.3f})"
            if event.switch_step is not None and event.p_switch is not None
            else "never switched to goal reaching"
        )
        rec.log(
            f"{base}/outcome",
            rr.TextDocument(
                f"run {k}: {event.outcome} ({event.reason or 'no reason given'}) after "
                f"{event.steps} hops, reward {event.reward:g}, "
                f"{switch}, {event.backups} backups, {event.seconds:.1f} s"
            ),
        )
        timings = {f"timing_{name}": float(v) for name, v in event.timings.items()}
        rec.log(
            f"{base}/summary",
            rr.AnyValues(
                outcome=event.outcome,
                steps=int(event.steps),
                reward=float(event.reward),
                switch_step=None if event.switch_step is None else int(event.switch_step),
                p_switch=None if event.p_switch is None else float(event.p_switch),
                backups=int(event.backups),
                seconds=float(event.seconds),
                **timings,
            ),
        )


# --------------------------------------------------------------------------- reading


def _first(value: Any) -> Any:
    """AnyValues columns hold one list per row; unwrap single values."""
    if isinstance(value, list):
        return value[0] if len(value) == 1 else value
    return value


def _read_chunks(path: Path) -> tuple[list, Any]:
    from rerun.chunk import RrdReader

    if not path.is_file():
        raise RecordingError(f"no recording at {path}: file not found")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # rerun warns about footer-less (legacy) files
            reader = RrdReader(path)
            stores = reader.recordings()
            if not stores:
                raise RecordingError(f"{path} holds no rerun recording")
            chunks = reader.stream(store=stores[0]).to_chunks()
    except RecordingError:
        raise
    except (RuntimeError, ValueError, OSError) as err:
        raise RecordingError(f"{path} is not a readable rerun recording: {err}") from err
    return chunks, stores[0]


def summarize_recording(path: str | os.PathLike[str]) -> dict[str, Any]:
    """What a recording holds, read back with ``rerun.chunk.RrdReader``.

    Returns:
        ``{"path", "application_id", "recording_id", "entities": [sorted entity paths],
        "timelines": [sorted names], "runs": [per run, by index: {"run_index", "seed",
        "scenario", "hops" (rows of run_K/hops), "outcome" (None if the run did not end),
        "steps", "reward", "switch_step", "p_switch", "backups", "seconds",
        "final_total_reward" (total_reward of the last hop row), "phases" (hops per phase),
        "sources" (hops per source), "backup_hops"}]}``.

    Raises:
        RecordingError: the file is missing, not an ``.rrd``, truncated or holds no recording.
    """
    path = Path(path)
    chunks, store = _read_chunks(path)
    entities: set[str] = set()
    timelines: set[str] = set()
    runs: dict[int, dict[str, Any]] = {}
    hop_rows: dict[int, list[dict[str, Any]]] = {}

    def run(k: int) -> dict[str, Any]:
        return runs.setdefault(
            k,
            {
                "run_index": k,
                "seed": None,
                "scenario": None,
                "hops": 0,
                "outcome": None,
                "steps": None,
                "reward": None,
                "switch_step": None,
                "p_switch": None,
                "backups": None,
                "seconds": None,
            },
        )

    for chunk in chunks:
        entity = str(chunk.entity_path)
        if entity.startswith("/__"):
            continue  # rerun's own properties
        entities.add(entity.lstrip("/"))
        timelines.update(t for t in chunk.timeline_names if t != "log_time")
        match = _RUN_RE.match(entity)
        if not match:
            continue
        k, rest = int(match.group(1)), match.group(2)
        if rest not in ("hops", "summary", "info"):
            continue
        batch = chunk.to_record_batch()
        names = [
            n
            for n in batch.schema.names
            if (batch.schema.field(n).metadata or {}).get(b"rerun:kind") == b"data"
        ]
        rows = [
            {n: _first(batch.column(n)[i].as_py()) for n in names} for i in range(batch.num_rows)
        ]
        if rest == "hops":
            hop_rows.setdefault(k, []).extend(rows)
            run(k)
        else:
            for row in rows:
                run(k).update({n: v for n, v in row.items() if n != "run_index"})

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
        f"id {summary['recording_id']})",
        f"timelines: {', '.join(summary['timelines']) or '-'}",
        f"entities ({len(summary['entities'])}):",
        *(f"  {e}" for e in summary["entities"]),
        f"runs: {len(summary['runs'])}",
    ]
    for r in summary["runs"]:
        outcome = r["outcome"] or "unfinished"
        reward = "-" if r["reward"] is None else f"{r['reward']:g}"
        switch = "-" if r["switch_step"] is None else str(r["switch_step"])
        lines.append(
            f"  run {r['run_index']}: {r['hops']} hops, outcome {outcome}, reward {reward}, "
            f"switch step {switch}, backups {r['backups'] if r['backups'] is not None else '-'}"
        )
    return "\n".join(lines)
