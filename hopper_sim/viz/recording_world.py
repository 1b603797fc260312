"""The static ``world/...`` entities of a rerun recording (see :mod:`hopper_sim.viz.recording`).

The scenario as JSON (enough to redraw the figure), its description and legend, the white
floor with the cell borders, the cells of each region as translucent boxes, one letter per
connected region and the start position. All positions are world metres, z up; everything
here is logged ``static``.
"""

from __future__ import annotations

import dataclasses
import json
from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr

from hopper_sim.viz.rerun_blueprint import legend_markdown
from hopper_sim.viz.styles import (
    GRID_COLOR,
    INITIAL_COLOR,
    INITIAL_LETTER,
    draw_order,
    format_reward,
    label_colors,
    region_components,
    region_letters,
)

if TYPE_CHECKING:
    from planner.scenario import Scenario

_FLOOR_Z = 0.0
_CELL_ALPHA = 170


def scenario_record(sc: Scenario) -> dict[str, Any]:
    """``sc`` as the dict :func:`planner.scenario.scenario_from_dict` reads (the TOML schema)."""

    def region(r) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if r.rects:
            out["rects"] = [list(map(float, x)) for x in r.rects]
        if r.cells:
            out["cells"] = [list(map(int, x)) for x in r.cells]
        return out

    return {
        "name": sc.name,
        "description": sc.description,
        "formula": sc.formula,
        "hazard": sc.hazard,
        "goal": sc.goal,
        "p_sat": float(sc.p_sat),
        "reward_known": bool(sc.reward_known),
        "world": {"size": [float(sc.world.width), float(sc.world.height)], "cell": sc.world.cell},
        "initial": {**region(sc.initial), "start": [float(v) for v in sc.start]},
        "regions": {label: region(r) for label, r in sc.regions.items()},
        "rewards": {k: float(v) for k, v in sc.rewards.items()},
        "runner": dataclasses.asdict(sc.runner),
    }


def log_world(rec: rr.RecordingStream, sc: Scenario) -> None:
    """Log the static world of scenario ``sc`` to ``rec``: its record and texts, the floor
    and grid, the region cells, the region letters and the start."""
    _log_texts(rec, sc)
    _log_floor(rec, sc)
    centers = sc.world.geometry.centres().reshape(sc.world.nx, sc.world.ny, 2)
    colors = label_colors(sc.labels, sc.goal, sc.hazard)
    _log_cells(rec, sc, centers, colors)
    _log_region_letters(rec, sc, centers, colors)
    rec.log(
        "world/start",
        rr.Points3D([[*sc.start, 0.05]], colors=[(255, 255, 255)], radii=[0.15]),
        static=True,
    )


def _log_texts(rec: rr.RecordingStream, sc: Scenario) -> None:
    """``world/scenario`` (JSON), ``world/info`` and ``world/legend`` (Markdown)."""
    w = sc.world
    rec.log(
        "world/scenario",
        rr.AnyValues(scenario_json=json.dumps(scenario_record(sc), sort_keys=True)),
        static=True,
    )
    info = (
        f"# Scenario {sc.name}\n\n{sc.description}\n\n"
        f"- world: {w.width} x {w.height} m, cells of {w.cell} m ({w.nx} x {w.ny})\n"
        f"- formula: `{sc.formula}`; hazard label `{sc.hazard}`, goal label `{sc.goal}`\n"
        f"- P_sat = {sc.p_sat}; reward known: {sc.reward_known}\n"
        f"- rewards: {dict(sc.rewards)}\n- runner: {sc.runner}\n"
    )
    rec.log("world/info", rr.TextDocument(info, media_type="text/markdown"), static=True)
    rec.log(
        "world/legend",
        rr.TextDocument(legend_markdown(sc), media_type="text/markdown"),
        static=True,
    )


def _log_floor(rec: rr.RecordingStream, sc: Scenario) -> None:
    """``world/ground`` (a white slab) and ``world/grid`` (the cell borders just above it)."""
    w = sc.world
    rec.log(
        "world/ground",
        rr.Boxes3D(
            centers=[[0.5 * w.width, 0.5 * w.height, _FLOOR_Z - 0.02]],
            half_sizes=[[0.5 * w.width, 0.5 * w.height, 0.01]],
            colors=[(250, 250, 250)],
            fill_mode="solid",
        ),
        static=True,
    )
    xs = np.arange(w.nx + 1) * w.cell
    ys = np.arange(w.ny + 1) * w.cell
    strips = [[[x, 0.0, _FLOOR_Z + 0.006], [x, w.height, _FLOOR_Z + 0.006]] for x in xs]
    strips += [[[0.0, y, _FLOOR_Z + 0.006], [w.width, y, _FLOOR_Z + 0.006]] for y in ys]
    rec.log("world/grid", rr.LineStrips3D(strips, colors=[GRID_COLOR], radii=[0.004]), static=True)


def _log_cells(
    rec: rr.RecordingStream, sc: Scenario, centers: np.ndarray, colors: dict[str, Any]
) -> None:
    """``world/cells/initial`` and ``world/cells/<label>``: translucent boxes on the floor."""
    half = [0.5 * sc.world.cell, 0.5 * sc.world.cell, 0.005]

    def boxes(mask: np.ndarray, color) -> rr.Boxes3D:
        c = centers[mask]
        return rr.Boxes3D(
            centers=np.column_stack([c, np.full(len(c), _FLOOR_Z)]),
            half_sizes=np.tile(half, (len(c), 1)),
            colors=[(*color, _CELL_ALPHA)],
            fill_mode="solid",
        )

    rec.log("world/cells/initial", boxes(sc.initial_mask, INITIAL_COLOR), static=True)
    for label in sc.regions:
        rec.log(f"world/cells/{label}", boxes(sc.region_mask(label), colors[label]), static=True)


def _log_region_letters(
    rec: rr.RecordingStream, sc: Scenario, centers: np.ndarray, colors: dict[str, Any]
) -> None:
    """``world/regions``: one label ("A +20") per connected region, hazards drawn last."""
    letters = region_letters(sc.labels)
    spots, texts, tints = [], [], []
    for label in ["initial", *draw_order(sc.labels, sc.goal, sc.hazard)]:
        if label == "initial":
            mask, text, color = sc.initial_mask, f"{INITIAL_LETTER} initial", INITIAL_COLOR
        else:
            mask = sc.region_mask(label)
            reward = float(sc.rewards.get(label, 0.0))
            text = f"{letters[label]} {label} {format_reward(reward)}"
            color = colors[label]
        for i, j in region_components(mask):
            spots.append([*centers[i, j], 0.06])
            texts.append(text)
            tints.append(color)
    if spots:
        rec.log(
            "world/regions",
            rr.Points3D(spots, labels=texts, colors=tints, radii=[0.05], show_labels=True),
            static=True,
        )
