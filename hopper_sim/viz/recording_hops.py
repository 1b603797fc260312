"""Hops of a rerun recording as columns (``run_K/hop/...``, ``route``, ``hops``, ``status``,
``plots/...``, ``com``; see :mod:`hopper_sim.viz.recording` for the entity paths and timelines).

A batch of buffered hops of one run is written with one ``send_columns`` call per entity:
per-hop rows at the hop's end, the foot, leg and target at its touchdown, the (thinned) CoM
samples at their own times. ``sim_time`` of a hop's own times is offset by the hop's start.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import rerun as rr

from hopper_sim.navigation.events import HopEvent
from hopper_sim.viz.styles import PHASE_CODES, PHASE_COLORS, PHASE_NAMES
from planner.modes import Source

_MIN_DURATION = 1e-6
_HOP_FIELDS = {f.name for f in dataclasses.fields(HopEvent)}


def hop_duration(event: HopEvent) -> float:
    """Simulated duration of a hop, s: its last CoM sample time (departure to the next
    interstitial state), else its touchdown time; at least 1 us."""
    if event.com_time is not None and len(event.com_time):
        t = float(event.com_time[-1])
    else:
        t = float(event.touchdown_time)
    return t if math.isfinite(t) and t > _MIN_DURATION else _MIN_DURATION


def is_scalar(value: Any) -> bool:
    """Whether rerun logs ``value`` as one scalar component (bool, int, float or str)."""
    return isinstance(value, bool | int | float | str | np.integer | np.floating)


def is_number(value: Any) -> bool:
    """Whether ``value`` is a number (not a bool), plotted as a time series."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def send_hops(
    rec: rr.RecordingStream, base: str, pending: list[tuple[HopEvent, float]], com_samples: int
) -> None:
    """Write the hops ``pending`` (each with its start on ``sim_time``) of the run at entity
    path ``base`` with one ``send_columns`` per entity; at most ``com_samples`` CoM samples
    per hop."""
    hops = [h for h, _ in pending]
    starts = np.array([t for _, t in pending])
    durations = np.array([hop_duration(h) for h in hops])
    steps = np.array([h.step for h in hops], dtype=np.int64)
    at_end = [
        rr.TimeColumn("hop", sequence=steps + 1),
        rr.TimeColumn("sim_time", duration=starts + durations),
    ]
    at_touchdown = [
        rr.TimeColumn("hop", sequence=steps + 1),
        rr.TimeColumn(
            "sim_time",
            duration=starts + np.minimum([h.touchdown_time for h in hops], durations),
        ),
    ]
    samples = [_thinned(h, com_samples) for h in hops]
    _send_geometry(rec, base, hops, [s[0] for s in samples], at_end, at_touchdown)
    _send_table(rec, base, hops, steps, durations, at_end)
    _send_plots(rec, base, hops, at_end)
    _send_com(rec, base, hops, samples, starts)


def _send_geometry(
    rec: rr.RecordingStream,
    base: str,
    hops: list[HopEvent],
    arcs: list[np.ndarray],
    at_end: list,
    at_touchdown: list,
) -> None:
    """``hop/com_arc``, ``hop/foot``, ``hop/leg``, ``hop/target``, ``hop/landing`` and
    ``route`` (start -> landing, coloured by phase)."""
    send, n = rec.send_columns, len(hops)

    def rows(value) -> np.ndarray:
        return np.tile(np.asarray(value), (n, 1))

    send(
        f"{base}/hop/com_arc",
        at_end,
        rr.LineStrips3D.columns(strips=arcs, colors=rows((60, 60, 60)), radii=np.full(n, 0.01)),
    )
    feet = np.array([h.foot for h in hops])
    send(
        f"{base}/hop/foot",
        at_touchdown,
        rr.Points3D.columns(positions=feet, colors=rows((0, 0, 0)), radii=np.full(n, 0.05)),
    )
    legs = [np.stack([h.foot, _com_at_touchdown(h)]) for h in hops]
    send(
        f"{base}/hop/leg",
        at_touchdown,
        rr.LineStrips3D.columns(strips=legs, colors=rows((0, 0, 0)), radii=np.full(n, 0.02)),
    )
    targets = np.column_stack([[h.target for h in hops], np.full(n, 0.02)])
    send(
        f"{base}/hop/target",
        at_touchdown,
        rr.Points3D.columns(
            positions=targets, colors=rows((120, 120, 120)), radii=np.full(n, 0.08)
        ),
    )
    landings = np.column_stack([[h.landing for h in hops], np.full(n, 0.03)])
    phase_colors = np.array([PHASE_COLORS.get(h.phase, (128, 128, 128)) for h in hops])
    send(
        f"{base}/hop/landing",
        at_end,
        rr.Points3D.columns(positions=landings, colors=phase_colors, radii=np.full(n, 0.06)),
    )
    departures = np.column_stack([[h.start_pos for h in hops], np.full(n, 0.03)])
    send(
        f"{base}/route",
        at_end,
        rr.LineStrips3D.columns(
            strips=np.stack([departures, landings], axis=1),
            colors=phase_colors,
            radii=np.full(n, 0.025),
        ),
    )


def _send_table(
    rec: rr.RecordingStream,
    base: str,
    hops: list[HopEvent],
    steps: np.ndarray,
    durations: np.ndarray,
    at_end: list,
) -> None:
    """``hops`` (one row of values per hop, new scalar fields included) and ``status``."""
    rec.send_columns(
        f"{base}/hops",
        at_end,
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
            duration=durations,
            **_extra_columns(hops),
        ),
    )
    rec.send_columns(
        f"{base}/status",
        at_end,
        rr.TextLog.columns(
            text=[_status_line(h) for h in hops],
            level=["WARN" if h.backup else "INFO" for h in hops],
        ),
    )


def _send_plots(rec: rr.RecordingStream, base: str, hops: list[HopEvent], at_end: list) -> None:
    """``plots/<name>``: P-check, rewards, phase code, RL use and backups per hop."""
    plots = {
        "p_worst": [h.p_worst for h in hops],
        "total_reward": [h.total_reward for h in hops],
        "reward": [h.reward for h in hops],
        "phase": [PHASE_CODES.get(h.phase, np.nan) for h in hops],
        "rl_action": [1.0 if h.source == Source.RL else 0.0 for h in hops],
        "backup": [1.0 if h.backup else 0.0 for h in hops],
    }
    for name, values in plots.items():
        rec.send_columns(
            f"{base}/plots/{name}", at_end, rr.Scalars.columns(scalars=np.asarray(values))
        )


def _send_com(
    rec: rr.RecordingStream,
    base: str,
    hops: list[HopEvent],
    samples: list[tuple[np.ndarray, np.ndarray | None]],
    starts: np.ndarray,
) -> None:
    """``com``: the thinned CoM samples of the hops that have sample times, at their times."""
    timed = [(s, t0) for s, t0 in zip(samples, starts, strict=True) if s[1] is not None]
    if not timed:
        return
    rec.send_columns(
        f"{base}/com",
        [
            rr.TimeColumn("sim_time", duration=np.concatenate([t0 + s[1] for s, t0 in timed])),
            rr.TimeColumn(
                "hop",
                sequence=np.concatenate(
                    [np.full(len(s[0]), h.step + 1) for (s, _), h in zip(timed, hops, strict=False)]
                ),
            ),
        ],
        rr.Points3D.columns(positions=np.concatenate([s[0] for s, _ in timed])),
    )


def _status_line(h: HopEvent) -> str:
    backup = f" (backup for {h.requested_action})" if h.backup else ""
    return (
        f"hop {h.step + 1}: {PHASE_NAMES.get(h.phase, h.phase)}, {h.source} action "
        f"{h.executed_action}{backup}, P-check {h.p_worst:.3f}, reward {h.reward:+g} "
        f"(total {h.total_reward:+g})"
    )


def _thin(n: int, most: int) -> np.ndarray:
    """At most ``most`` indices of ``range(n)``, evenly spread, first and last kept."""
    if n <= most:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, most)).astype(np.int64))


def _thinned(event: HopEvent, most: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The hop's CoM samples (and their times since departure) thinned to ``most``; a hop
    without samples gets its departure and landing."""
    path = event.com_path
    if len(path) < 2:
        z = path[0, 2] if len(path) else 1.0
        return np.array([[*event.start_pos, z], [*event.landing, z]]), None
    idx = _thin(len(path), most)
    times = None if event.com_time is None else np.asarray(event.com_time)[idx]
    return path[idx], times


def _com_at_touchdown(event: HopEvent) -> np.ndarray:
    """CoM at touchdown: interpolated in ``com_time`` if given, else the path point nearest
    to the foot (the CoM is above the foot at touchdown, at leg length)."""
    path = event.com_path
    if not len(path):
        return np.asarray(event.foot) + np.array([0.0, 0.0, 1.0])
    if event.com_time is not None and len(path) > 1:
        return np.array(
            [np.interp(event.touchdown_time, event.com_time, path[:, d]) for d in range(3)]
        )
    return path[np.argmin(np.linalg.norm(path - event.foot, axis=1))]


def _extra_columns(hops: list[HopEvent]) -> dict[str, Any]:
    """Columns for HopEvent fields this recorder does not know: each that holds the same
    scalar type (bool, int, float, str) in every hop; others are left out."""
    out: dict[str, Any] = {}
    names = {f.name for f in dataclasses.fields(hops[0])} - _HOP_FIELDS
    for name in sorted(names):
        values = [getattr(h, name) for h in hops]
        kinds = {type(v) for v in values}
        if len(kinds) != 1 or not is_scalar(values[0]):
            continue
        out[name] = values if isinstance(values[0], str) else np.asarray(values)
    return out
