"""rerun recordings of navigation runs, with a blueprint, and readers that summarise them.

:class:`RerunRecorder` is an :class:`~hopper_sim.navigation.events.Observer` that writes one rerun
recording (``.rrd``, rerun-sdk 0.41, headless file sink) per invocation. It writes into a
private temporary folder beside the target (:func:`planner._util.atomic.new_temporary_folder`: no
planted link is followed) and moves the file into place on :meth:`RerunRecorder.close`, so
a crashed invocation never leaves a half-written recording. Hops are buffered per run and
written with ``send_columns`` (one call per entity for up to ``flush_every`` hops), at each
synthesis, at the run's end and on close. Every hop adds a bounded amount of data (its CoM
samples are thinned to at most ``com_samples``), so a recording grows linearly with the
hops. :func:`summarize_recording` and :func:`read_runs` read a recording back with rerun's own
reader (``rerun.chunk.RrdReader``). The static world is written by
:mod:`hopper_sim.viz.recording_world`, the hop columns by :mod:`hopper_sim.viz.recording_hops`.

Runs are numbered from 1 (``K = RunStart.run_index + 1``), as in the summary table of
``hopnav run``, in ``hopnav replay``, in figure titles and in the entity paths below.

Timelines:

- ``hop`` (sequence): hops completed in the run. Hop ``k`` (``HopEvent.step = k``, 0-based)
  is logged at ``hop = k + 1``; a synthesis after ``m`` hops at ``hop = m`` (the initial one
  at 0); the run's outcome at ``hop = steps``.
- ``sim_time`` (duration): simulated seconds since the run started, cumulative over hops. A
  hop's own times (``touchdown_time``, ``com_time``: seconds since its departure state) are
  offset by the hop's start, the sum of the durations of the hops before it; a hop's duration
  is its last CoM sample time (the next interstitial state; without samples, its touchdown
  time, and at least 1 us), so ``sim_time`` strictly increases over a run's hops and the end
  of hop ``k`` lies at the sum of the durations of hops ``0..k``. Each run starts again at 0.
  Per-hop rows are logged at the hop's end, the foot, leg and target at its touchdown, the
  CoM samples at their own times.

Wall-clock time is not a timeline (the same events give the same recording); the wall-clock
seconds of each synthesis stage are plotted under ``run_K/timings``. All positions are world
metres, z up.

Entity paths::

    world/scenario               AnyValues     the scenario as JSON (redraws the figure)  (static)
    world/info                   TextDocument  scenario name, formula, settings           (static)
    world/provenance             AnyValues     scenario digest, checkpoint hash, version,
                                               commit (experiments.provenance)            (static)
    world/legend                 TextDocument  region classes: letter, colour, reward;
                                               route colours                              (static)
    world/ground, world/grid     Boxes3D, LineStrips3D  white floor and cell borders      (static)
    world/cells/initial          Boxes3D       initial region cells, translucent          (static)
    world/cells/<label>          Boxes3D       cells of each label                        (static)
    world/regions                Points3D      one label per connected region ("A +20")   (static)
    world/start                  Points3D      start position                             (static)
    run_K/info                   AnyValues     run, seed, scenario                        (static)
    run_K/hop/com_arc            LineStrips3D  the hop's CoM arc, at its end
    run_K/hop/foot, hop/leg      Points3D, LineStrips3D  foot and leg at touchdown
    run_K/hop/target             Points3D      target cell centre, at touchdown
    run_K/hop/landing            Points3D      landing (next interstitial CoM, z = 0)
    run_K/route                  LineStrips3D  the hop's segment start -> landing, coloured by
                                               phase (the blueprint shows all up to the cursor)
    run_K/com                    Points3D      the CoM along sim_time
    run_K/hops                   AnyValues     step, phase, source, backup, requested_action,
                                               executed_action, cell, product_state, p_worst,
                                               reward, total_reward, duration (+ any new
                                               scalar field of HopEvent), one row per hop
    run_K/status                 TextLog       one line per hop
    run_K/plots/p_worst          Scalars       worst-case satisfaction probability (P-check) of
                                               the current product state, after each hop
    run_K/plots/p_worst_initial  Scalars       of the initial state, at each synthesis
    run_K/plots/p_worst_current  Scalars       of the current state, at each synthesis (the
                                               number the switch compares with P_sat)
    run_K/plots/total_reward     Scalars       reward collected so far
    run_K/plots/reward           Scalars       reward of the hop
    run_K/plots/phase            Scalars       0 exploration, 1 goal reaching, 2 fallback
    run_K/plots/rl_action        Scalars       1 if the RL policy chose the action
    run_K/plots/backup           Scalars       1 if the backup switch replaced the action
    run_K/synthesis/num_data     Scalars       hops the GPs were fitted on, at each synthesis
    run_K/synthesis/mec_states   Scalars       states of the end component exploration steers
                                               to (0: none), at each synthesis
    run_K/synthesis/mec_probability, synthesis/mec_average_reward
                                 Scalars       its worst-case reach probability from the
                                               current state and its average reward still to
                                               be collected (absent when there is none)
    run_K/synthesis/<field>      Scalars       any new numeric field of SynthesisEvent
    run_K/gp/fit/<name>          Scalars       the fit report's numeric values (one series
                                               per component, e.g. per axis), at each synthesis
    run_K/gp/mean, gp/std        Tensor        GP posterior mean / std of the landing error,
                                               (Gx, Gy, 2) m, at each synthesis
    run_K/gp/image/<m>_<axis>    Image         the same as colour maps (mean: purple-orange in
                                               [-cell, +cell], std: viridis in [0, cell],
                                               saturated beyond; x right, y up)
    run_K/gp/mean_field          Arrows3D      GP mean error as arrows at the grid points
    run_K/timings/<stage>        Scalars       wall-clock seconds per synthesis stage
    run_K/outcome                TextDocument  outcome at the end of the run, with P-check at
                                               the current state after each synthesis
    run_K/summary                AnyValues     outcome, reason, steps, reward, switch_step,
                                               p_switch, left_plan_step, backups, collections,
                                               seconds,
                                               timing_<stage> (+ any new scalar field)

The blueprint (:func:`blueprint`) is sent on close: one tab per run with the 3D world large on
the left (the route and CoM arcs so far, the current leg and foot, the legend and the outcome
below), the time series of P-check, reward, phase, RL use and backups stacked on the right
above the GP maps; the time panel opens on ``sim_time``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import weakref
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr

from hopper_sim.errors import HopperSimError
from hopper_sim.experiments.provenance import as_text
from hopper_sim.navigation.events import HopEvent, Observer, RunEnd, RunStart, SynthesisEvent
from hopper_sim.viz.recording_hops import hop_duration, is_number, is_scalar, send_hops
from hopper_sim.viz.recording_world import log_world
from hopper_sim.viz.recording_world import scenario_record as scenario_record  # re-exported
from hopper_sim.viz.rerun_blueprint import blueprint
from planner._util.atomic import new_temporary_folder

if TYPE_CHECKING:
    from hopper_sim.navigation.events import ResynthesisRecord
    from planner.scenario import Scenario

APPLICATION_ID = "hopnav"

_SYNTHESIS_FIELDS = {f.name for f in dataclasses.fields(SynthesisEvent)}
_END_FIELDS = {f.name for f in dataclasses.fields(RunEnd)}


class RecordingError(HopperSimError, ValueError):
    """A recording cannot be written or read (missing, corrupt or truncated file...)."""


def run_path(run_index: int) -> str:
    """Entity path of the run with 0-based ``run_index``: ``run_<run_index + 1>``."""
    return f"run_{run_index + 1}"


class RerunRecorder(Observer):
    """Observer writing every event of an invocation to one ``.rrd`` file with a blueprint.

    Args:
        path: the ``.rrd`` file to write (its folder must exist).
        application_id: rerun application id.
        recording_id: rerun recording id (default: a fresh one).
        flush_every: hops buffered per run before they are written as columns (they are
            also written at each synthesis, at the run's end and on close).
        com_samples: at most this many CoM samples per hop are recorded (evenly thinned in
            time, first and last kept), for the arc and the animated CoM.
        provenance: what produced the recording
        (:func:`hopper_sim.experiments.provenance.provenance`),
            logged as ``world/provenance`` (values as text; ``None`` values left out).

    Use as a context manager, or call :meth:`close` after the last run: the file appears at
    ``path`` only then. Leaving the context by an exception discards the recording.

    Raises:
        RecordingError: the folder of ``path`` does not exist or a setting is out of range.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        application_id: str = APPLICATION_ID,
        recording_id: str | None = None,
        flush_every: int = 100,
        com_samples: int = 48,
        provenance: dict[str, Any] | None = None,
    ) -> None:
        if flush_every < 1:
            raise RecordingError(f"flush_every must be at least 1, got {flush_every}")
        if com_samples < 2:
            raise RecordingError(f"com_samples must be at least 2, got {com_samples}")
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise RecordingError(f"cannot write {self.path}: folder {self.path.parent} missing")
        # rerun opens the sink by name: a private folder beside the target holds it, so no
        # planted file or link can be written through (planner._util.atomic)
        self._tmp_folder = new_temporary_folder(self.path)
        self._tmp = self._tmp_folder / self.path.name
        # removed on close/discard, else when the recorder is collected or Python exits
        self._remove_tmp = weakref.finalize(self, shutil.rmtree, self._tmp_folder, True)
        self._rec = rr.RecordingStream(application_id, recording_id=recording_id)
        self._rec.set_log_time_enabled(False)
        self._rec.set_log_tick_enabled(False)
        self._rec.set_sinks(rr.FileSink(str(self._tmp)))
        self._world_logged: str | None = None
        self.flush_every = int(flush_every)
        self.com_samples = int(com_samples)
        self._pending: dict[int, list[tuple[HopEvent, float]]] = {}
        self._clock: dict[int, float] = {}
        self._hops_done: dict[int, int] = {}
        self._runs: list[int] = []
        self._cell = 1.0
        self._closed = False
        if provenance:
            values = {k: v for k, v in as_text(provenance).items() if v}
            self._rec.log("world/provenance", rr.AnyValues(**values), static=True)

    # -- context manager -------------------------------------------------------------
    def __enter__(self) -> RerunRecorder:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.discard()

    def close(self) -> None:
        """Write what is buffered and the blueprint, finish the file and move it to
        :attr:`path` (idempotent)."""
        if self._closed:
            return
        for k in list(self._pending):
            self._flush_hops(k)
        rr.send_blueprint(
            blueprint([k + 1 for k in sorted(self._runs)]),
            make_active=True,
            make_default=True,
            recording=self._rec,
        )
        self._closed = True
        self._rec.flush()
        self._rec.disconnect()
        try:
            os.replace(self._tmp, self.path)
        finally:
            self._remove_tmp()

    def discard(self) -> None:
        """Stop recording and delete the temporary file; nothing appears at :attr:`path`."""
        if self._closed:
            return
        self._closed = True
        self._rec.disconnect()
        self._remove_tmp()

    def _time(self, hop: int, sim_time: float) -> None:
        self._rec.set_time("hop", sequence=int(hop))
        self._rec.set_time("sim_time", duration=float(sim_time))

    # -- the world -------------------------------------------------------------------
    def _log_world(self, sc: Scenario) -> None:
        self._cell = float(sc.world.cell)
        log_world(self._rec, sc)

    # -- observer handlers -----------------------------------------------------------
    def on_run_start(self, event: RunStart) -> None:
        """Log the world (once per scenario) and the run's static info."""
        if self._world_logged != event.scenario.name:
            self._log_world(event.scenario)
            self._world_logged = event.scenario.name
        k = event.run_index
        self._flush_hops(k)
        self._clock[k] = 0.0
        self._hops_done[k] = 0
        if k not in self._runs:
            self._runs.append(k)
        self._rec.log(
            f"{run_path(k)}/info",
            rr.AnyValues(run=k + 1, seed=int(event.seed), scenario=event.scenario.name),
            static=True,
        )

    def on_hop(self, event: HopEvent) -> None:
        """Buffer the hop at its start time; hops are written in columns at each synthesis,
        run end, close or every ``flush_every`` hops."""
        k = event.run_index
        start = self._clock.get(k, 0.0)
        self._clock[k] = start + hop_duration(event)
        self._hops_done[k] = self._hops_done.get(k, 0) + 1
        if k not in self._runs:
            self._runs.append(k)
        self._pending.setdefault(k, []).append((event, start))
        if len(self._pending[k]) >= self.flush_every:
            self._flush_hops(k)

    def _flush_hops(self, k: int) -> None:
        """Write the buffered hops of run ``k`` with one ``send_columns`` per entity."""
        pending = self._pending.pop(k, [])
        if pending:
            send_hops(self._rec, run_path(k), pending, self.com_samples)

    def on_synthesis(self, event: SynthesisEvent) -> None:
        """Log the GP maps, the initial state's worst-case probability and stage timings."""
        k, rec = event.run_index, self._rec
        base = run_path(k)
        self._flush_hops(k)
        self._time(event.step, self._clock.get(k, 0.0))
        rec.log(f"{base}/gp/mean", rr.Tensor(event.gp_mean, dim_names=("x", "y", "axis")))
        rec.log(f"{base}/gp/std", rr.Tensor(event.gp_std, dim_names=("x", "y", "axis")))
        for d, axis in enumerate("xy"):
            rec.log(
                f"{base}/gp/image/mean_{axis}",
                rr.Image(_color_map(event.gp_mean[..., d], "PuOr", -self._cell, self._cell)),
            )
            rec.log(
                f"{base}/gp/image/std_{axis}",
                rr.Image(_color_map(event.gp_std[..., d], "viridis", 0.0, self._cell)),
            )
        gx, gy = np.meshgrid(event.grid_x, event.grid_y, indexing="ij")
        origins = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, 0.03)])
        vectors = np.column_stack([event.gp_mean.reshape(-1, 2), np.zeros(gx.size)])
        rec.log(
            f"{base}/gp/mean_field",
            rr.Arrows3D(origins=origins, vectors=vectors, colors=[(30, 90, 200)], radii=[0.01]),
        )
        rec.log(f"{base}/plots/p_worst_initial", rr.Scalars(float(event.p_worst_initial)))
        if event.record is not None:
            self._log_record(base, event.record)
        for stage, seconds in event.timings.items():
            rec.log(f"{base}/timings/{stage}", rr.Scalars(float(seconds)))
        extra: dict[str, Any] = {}
        for name in sorted({f.name for f in dataclasses.fields(event)} - _SYNTHESIS_FIELDS):
            value = getattr(event, name)
            if is_number(value):
                rec.log(f"{base}/synthesis/{name}", rr.Scalars(float(value)))
            elif isinstance(value, dict) and all(is_number(v) for v in value.values()):
                for key, v in value.items():
                    rec.log(f"{base}/synthesis/{name}/{key}", rr.Scalars(float(v)))
            elif value is not None:
                extra[name] = value if is_scalar(value) else json.dumps(_jsonable(value))
        if extra:
            rec.log(f"{base}/synthesis", rr.AnyValues(**extra))

    def _log_record(self, base: str, record: ResynthesisRecord) -> None:
        """The synthesis's report: ``P̌`` of the current state (beside the initial one's),
        the fit's numeric values and the chosen end component, each a time series."""
        rec = self._rec
        rec.log(f"{base}/plots/p_worst_current", rr.Scalars(float(record.p_worst_current)))
        for name in ("num_data", "mec_states", "mec_probability", "mec_average_reward"):
            value = getattr(record, name)
            if value is not None:
                rec.log(f"{base}/synthesis/{name}", rr.Scalars(float(value)))
        for name, values in record.gp.items():
            rec.log(f"{base}/gp/fit/{name}", rr.Scalars(np.asarray(values, dtype=float)))

    def on_run_end(self, event: RunEnd) -> None:
        """Log the outcome text and the run's summary record."""
        k, rec = event.run_index, self._rec
        base = run_path(k)
        self._flush_hops(k)
        self._time(event.steps, self._clock.get(k, 0.0))
        switch = (
            f"switched to goal reaching at hop {event.switch_step + 1} "
            f"(P-check {event.p_switch:.3f})"
            if event.switch_step is not None and event.p_switch is not None
            else "never switched to goal reaching"
        )
        reason = getattr(event, "reason", "")
        left = getattr(event, "left_plan_step", None)
        left_text = "" if left is None else f"; left the switch's plan at hop {left + 1}"
        records = getattr(event, "resyntheses", ())
        trace = (
            "\nP-check at the current state after each synthesis (hop: P): "
            + ", ".join(f"{r.step}: {r.p_worst_current:.3f}" for r in records)
            + ".\n"
            if records
            else ""
        )
        rec.log(
            f"{base}/outcome",
            rr.TextDocument(
                f"# Run {k + 1}: {event.outcome}\n\n"
                f"{reason or event.outcome} after {event.steps} hops "
                f"({self._clock.get(k, 0.0):.2f} s simulated, {event.seconds:.1f} s wall); "
                f"reward {event.reward:g}; {switch}{left_text}; {event.backups} backups.\n"
                f"{trace}",
                media_type="text/markdown",
            ),
        )
        timings = {f"timing_{name}": float(v) for name, v in event.timings.items()}
        extra = {
            name: getattr(event, name)
            for name in sorted({f.name for f in dataclasses.fields(event)} - _END_FIELDS)
            if is_scalar(getattr(event, name))
        }
        rec.log(
            f"{base}/summary",
            rr.AnyValues(
                outcome=event.outcome,
                reason=str(reason),
                steps=int(event.steps),
                reward=float(event.reward),
                switch_step=None if event.switch_step is None else int(event.switch_step),
                p_switch=None if event.p_switch is None else float(event.p_switch),
                left_plan_step=None if left is None else int(left),
                backups=int(event.backups),
                collections=int(getattr(event, "collections", 0)),
                **_mission_values(getattr(event, "mission", None)),
                seconds=float(event.seconds),
                sim_seconds=float(self._clock.get(k, 0.0)),
                **timings,
                **extra,
            ),
        )


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value if value is None or is_scalar(value) else str(value)


def _color_map(values: np.ndarray, cmap: str, low: float, high: float) -> np.ndarray:
    """``(Gx, Gy)`` values as an RGB image ``(Gy, Gx, 3)`` uint8, x to the right, y up."""
    from matplotlib import colormaps

    scaled = np.clip((np.asarray(values, dtype=float) - low) / (high - low), 0.0, 1.0)
    rgb = colormaps[cmap](np.nan_to_num(scaled, nan=0.5))[..., :3]
    return np.ascontiguousarray((255 * rgb).round().astype(np.uint8).transpose(1, 0, 2)[::-1])


_READERS = ("summarize_recording", "format_summary", "read_runs", "RecordedRun")


def __getattr__(name: str) -> Any:
    """The readers live in :mod:`hopper_sim.viz.recording_reader` (imported on first use)."""
    if name in _READERS:
        from hopper_sim.viz import recording_reader

        return getattr(recording_reader, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _mission_values(mission) -> dict:
    """The run's :class:`planner.verdict.MissionReport` as scalar summary values."""
    if mission is None:
        return {}
    return {
        "verdict": str(mission.verdict),
        "obligation": str(mission.obligation),
        "window": int(mission.window),
        "window_accepted": bool(mission.window_accepted),
        "pair_visits": [int(v) for v in mission.pair_visits],
        **{f"visits_{k}": int(v) for k, v in mission.label_visits.items()},
        "in_accepting_component": mission.in_accepting_component,
    }
