"""The rerun viewer layout (blueprint) of hopnav recordings, and the legend panel's text.

:func:`blueprint` builds the layout :class:`~hopper_sim.viz.recording.RerunRecorder` sends with
every recording, so that opening the file shows it: one tab per run (numbered from 1) with the
3D world large on the left (the cells as a white floor with translucent coloured boxes, one
label per connected region instead of per-cell text, the route and CoM arcs up to the time
cursor, the current leg, foot and target, the GP mean field), the legend and the outcome text
below it, and on the right the time series of P-check (the worst-case satisfaction
probability of the current state, and of the initial state at each synthesis), reward, phase,
RL use and backups stacked above the GP mean/std maps. The time panel opens on ``sim_time``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from hopper_sim.viz.styles import PHASE_COLORS, PHASE_NAMES, color_name, legend_entries

if TYPE_CHECKING:
    from planner.scenario import Scenario


def legend_markdown(sc: Scenario) -> str:
    """The legend panel: every region class with its letter, colour and reward; the route
    colours."""
    rows = [
        "| letter | class | colour |",
        "|---|---|---|",
        *(f"| {letter} | {text} | {color_name(c)} |" for letter, text, c in legend_entries(sc)),
    ]
    route = ", ".join(f"{color_name(PHASE_COLORS[p])} = {PHASE_NAMES[p]}" for p in PHASE_COLORS)
    return (
        f"# Regions of scenario {sc.name}\n\n"
        + "\n".join(rows)
        + f"\n\nRoute segments: {route}. Dark grey arcs: the CoM of each hop; the leg is shown "
        "at touchdown; white sphere: the start.\n"
    )


def blueprint(runs: list[int], *, timeline: str = "sim_time"):
    """The viewer layout: one tab per run (``runs``: 1-based run numbers).

    Each tab: the 3D world large on the left (world, the run's route and CoM arcs up to the
    time cursor, leg, foot, target, landing, CoM, GP mean field), the legend and the outcome
    below it; on the right the time series of P-check, reward, phase, RL use and backups
    stacked, and the GP maps (mean and std per axis) below. The time panel opens on
    ``timeline``.
    """
    import rerun.blueprint as rrb

    tabs = [_tab(k) for k in runs] or [rrb.Spatial3DView(origin="/world", name="world")]
    return rrb.Blueprint(
        rrb.Tabs(*tabs) if len(tabs) > 1 else tabs[0],
        rrb.TimePanel(timeline=timeline, state="expanded"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        collapse_panels=False,
    )


def _tab(k: int) -> Any:
    """The tab of run ``k``: world, legend and outcome on the left, plots on the right."""
    import rerun.blueprint as rrb

    below = rrb.Horizontal(
        rrb.TextDocumentView(origin="/world/legend", name="legend"),
        rrb.TextDocumentView(origin=f"/run_{k}/outcome", name="outcome"),
        column_shares=[3, 2],
    )
    return rrb.Horizontal(
        rrb.Vertical(_world_view(k), below, row_shares=[4, 1]),
        _plots(k),
        column_shares=[3, 2],
        name=f"run {k}",
    )


def _world_view(k: int) -> Any:
    """The 3D world of run ``k``; its route and CoM arcs shown up to the time cursor."""
    import rerun.blueprint as rrb

    until_cursor = rrb.VisibleTimeRanges(
        [
            rrb.VisibleTimeRange(
                name,
                start=rrb.TimeRangeBoundary.infinite(),
                end=rrb.TimeRangeBoundary.cursor_relative(),
            )
            for name in ("sim_time", "hop")
        ]
    )
    return rrb.Spatial3DView(
        origin="/",
        contents=[
            "+ /world/**",
            f"+ /run_{k}/hop/**",
            f"+ /run_{k}/route",
            f"+ /run_{k}/com",
            f"+ /run_{k}/gp/mean_field",
        ],
        name=f"world, run {k}",
        overrides={
            f"/run_{k}/route": until_cursor,
            f"/run_{k}/hop/com_arc": until_cursor,
        },
    )


def _plots(k: int) -> Any:
    """The time series of run ``k`` stacked above its GP maps."""
    import rerun.blueprint as rrb

    gp = rrb.Tabs(
        *(
            rrb.Spatial2DView(origin=f"/run_{k}/gp/image/{m}", name=f"GP {m}")
            for m in ("mean_x", "mean_y", "std_x", "std_y")
        ),
        name="GP maps",
    )
    return rrb.Vertical(
        _series(
            k,
            ["p_worst", "p_worst_current", "p_worst_initial"],
            "P-check (worst-case satisfaction)",
            (0, 1),
        ),
        _series(k, ["total_reward", "reward"], "reward"),
        _series(k, ["phase"], "phase (0 explore, 1 goal, 2 fallback)", (-0.1, 2.1)),
        _series(k, ["rl_action"], "RL action", (-0.1, 1.1)),
        _series(k, ["backup"], "backup", (-0.1, 1.1)),
        gp,
        row_shares=[2, 2, 1, 1, 1, 3],
    )


def _series(k: int, paths: list[str], title: str, axis=None) -> Any:
    """A time-series view of the plots ``paths`` of run ``k`` (y range ``axis`` if given)."""
    import rerun.blueprint as rrb

    return rrb.TimeSeriesView(
        origin=f"/run_{k}/plots",
        contents=[f"/run_{k}/plots/{p}" for p in paths],
        name=title,
        axis_y=None if axis is None else rrb.ScalarAxis(range=axis),
        plot_legend=rrb.PlotLegend(visible=len(paths) > 1),
    )
