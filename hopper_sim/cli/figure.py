"""``hopnav figure``: the paper's Figure 4 panel, or the Table I plot, as PNG, SVG or PDF.

Three sources, one at a time:

- ``--scenarios a,b,c,d`` (the default): runs each scenario (shipped name or TOML path) with
  its own settings (``--runs``, ``--seed``, ``--max-steps`` override them) and draws the last
  run of each (``--run K`` another, 1-based), as the paper shows the tenth run of (c) and
  (d); ``--save-rrd DIR`` also keeps a recording per scenario (``DIR/<name>.rrd``).
- ``--rrd A.rrd B.rrd ...``: draws from recordings of ``hopnav run`` instead, without
  simulating (the last run of each, or ``--run K``).
- ``--table-i sweep_runs.csv``: the Table I plot (reward and steps with confidence intervals
  against C and eps, the paper's values overlaid) from the rows of a ``hopnav sweep``.

One map is drawn with its legend beside it; several form a grid of two columns with one
legend below (``a,b,c,d`` gives the 2 x 2 panel). Each ``--out`` file (repeatable) gets the
same figure, its format chosen by the extension (``.png`` at 200 dpi, ``.svg``, ``.pdf``);
destinations are checked before anything runs. Each file carries the provenance of
:mod:`hopper_sim.experiments.provenance` (per drawn scenario, joined with commas). Errors follow
:mod:`hopnav.errors`: exit code 2 for bad input, 1 for a run that failed.

Example: ``hopnav figure --scenarios a,b,c,d --out fig4.pdf --out fig4.png``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from hopnav.arguments import figure_file, output_folder
from hopnav.errors import RunFailed, UsageError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "figure",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument(
        "--scenarios", help="comma-separated shipped names or TOML paths to run [a,b,c,d]"
    )
    src.add_argument("--rrd", nargs="+", metavar="FILE", help="recordings to draw instead")
    src.add_argument("--table-i", metavar="CSV", help="a sweep's sweep_runs.csv: Table I plot")
    p.add_argument(
        "--out",
        action="append",
        required=True,
        metavar="FILE",
        help="figure to write (.png, .svg or .pdf; repeat for several formats)",
    )
    p.add_argument("--run", type=int, help="run to draw, 1-based [the last]")
    p.add_argument("--runs", type=int, help="runs per scenario [the scenario's]")
    p.add_argument("--seed", type=int, help="seed of the first run [the scenario's]")
    p.add_argument("--max-steps", type=int, help="hop cap per run [the scenario's]")
    p.add_argument("--save-rrd", metavar="DIR", help="also write DIR/<scenario>.rrd per scenario")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    outs = [figure_file(p, "--out") for p in args.out]
    for name, value, low in (
        ("--run", args.run, 1),
        ("--runs", args.runs, 1),
        ("--max-steps", args.max_steps, 1),
        ("--seed", args.seed, 0),
    ):
        if value is not None and value < low:
            raise UsageError(f"{name} must be at least {low}, got {value}")
    if args.save_rrd:
        output_folder(args.save_rrd, "--save-rrd")
    from hopper_sim.viz.figures import FigureError

    try:
        written = _table_i(args, outs) if args.table_i else _figure4(args, outs)
    except FigureError as err:
        raise UsageError(str(err)) from None
    for path in written:
        print(path)
    return 0


def _save(fig, outs: list[Path], metadata: dict[str, Any]) -> list[Path]:
    """Write ``fig`` to every path of ``outs`` (their folders created)."""
    from hopper_sim.viz.figure_files import save_figure

    for out in outs:
        out.parent.mkdir(parents=True, exist_ok=True)
    return [save_figure(fig, out, metadata=metadata) for out in outs]


def _provenance(records: list[dict[str, Any]], **extra: str) -> dict[str, Any]:
    """The provenance of a figure drawn from the results of ``records`` (one
    :func:`~hopper_sim.experiments.provenance.provenance` per panel): the per-scenario fields
    joined with
    commas, the code's and the checkpoint's shared, and ``extra``."""
    from hopper_sim.experiments.provenance import as_text, provenance

    texts = [as_text(r) for r in records] or [as_text(provenance(None))]
    joined = {k: ",".join(r[k] for r in texts) for k in ("scenario", "scenario_sha256")}
    return {**texts[0], **joined, **extra}


def _table_i(args: argparse.Namespace, outs: list[Path]) -> list[Path]:
    from hopper_sim.experiments.sweep import summarize
    from hopper_sim.experiments.sweep_files import SweepFileError, read_rows_csv
    from hopper_sim.viz.sweep_plot import build_table_plot

    try:
        rows = read_rows_csv(args.table_i)
    except SweepFileError as err:
        raise UsageError(str(err)) from None
    if not rows:
        raise UsageError(f"{args.table_i} holds no runs")
    fig = build_table_plot(summarize(rows))
    return _save(fig, outs, _provenance([], source=str(args.table_i)))


def _figure4(args: argparse.Namespace, outs: list[Path]) -> list[Path]:
    from hopper_sim.viz.figures import Panel, build_figure, run_title

    panels = _from_recordings(args) if args.rrd else _from_scenarios(args)
    drawn = [
        Panel(sc, route, run_title(sc, run_number=k, n_runs=n, end=end, hops=route.n_hops))
        for sc, route, end, k, n, _ in panels
    ]
    fig = build_figure(drawn)
    extra = {"source": ",".join(args.rrd)} if args.rrd else {}
    return _save(fig, outs, _provenance([prov for *_, prov in panels], **extra))


def _pick(n_runs: int, wanted: int | None, where: str) -> int:
    """The 1-based run to draw of ``n_runs``."""
    k = n_runs if wanted is None else wanted
    if not 1 <= k <= n_runs:
        raise UsageError(f"--run {k}: {where} has runs 1..{n_runs}")
    return k


def _from_recordings(args: argparse.Namespace) -> list[tuple]:
    from hopper_sim.experiments.provenance import provenance
    from hopper_sim.viz.recording import RecordingError, read_runs

    panels = []
    for path in args.rrd:
        try:
            sc, runs = read_runs(path)
        except RecordingError as err:
            raise UsageError(str(err)) from None
        by_number = {r.run: r for r in runs}
        if not runs:
            raise UsageError(f"{path} holds no runs")
        if args.run is not None and args.run not in by_number:
            raise UsageError(f"--run {args.run}: {path} has runs {', '.join(map(str, by_number))}")
        rec = by_number[args.run] if args.run is not None else runs[-1]
        # the digest of the scenario as recorded (with the run's overrides); the code that
        # made the recording is named in the recording's own world/provenance
        prov = provenance(sc)
        panels.append((sc, rec.route, rec.end, rec.run, len(runs), prov))
    return panels


def _from_scenarios(args: argparse.Namespace) -> list[tuple]:
    from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT
    from hopper_sim.experiments.provenance import provenance
    from planner.errors import PlannerError
    from planner.scenario import load_scenario

    names = [s.strip() for s in (args.scenarios or "a,b,c,d").split(",") if s.strip()]
    if not names:
        raise UsageError("--scenarios names no scenario")
    scenarios = []
    for name in names:  # all checked before the first run
        try:
            sc = load_scenario(name)
        except PlannerError as err:
            raise UsageError(str(err)) from None
        prov = provenance(sc, DEFAULT_CHECKPOINT)  # as loaded, before --max-steps
        if args.max_steps is not None:
            sc = sc.with_runner(max_steps=args.max_steps)
        n = sc.runner.runs if args.runs is None else args.runs
        k = _pick(n, args.run, f"scenario {sc.name} ({n} runs)")
        scenarios.append((name, sc, n, k, prov))
    save = Path(args.save_rrd) if args.save_rrd else None
    if save is not None:
        save.mkdir(parents=True, exist_ok=True)

    from hopper_sim.navigation.events import Observer, Observers
    from hopper_sim.navigation.runner import NavigationRunner
    from hopper_sim.viz.figures import Route
    from hopper_sim.viz.recording import RecordingError, RerunRecorder

    class Keep(Observer):
        """Keeps the hops and the end of the run to draw."""

        def __init__(self, index: int) -> None:
            self.index, self.hops, self.end = index, [], None

        def on_hop(self, event) -> None:
            if event.run_index == self.index:
                self.hops.append(event)

        def on_run_end(self, event) -> None:
            if event.run_index == self.index:
                self.end = event

    panels = []
    for name, sc, n, k, prov in scenarios:
        keep = Keep(k - 1)
        observers: list = [keep]
        recorder = None
        if save is not None:
            stem = Path(name).stem if name.endswith(".toml") else sc.name
            try:
                recorder = RerunRecorder(save / f"{stem}.rrd", provenance=prov)
            except RecordingError as err:
                raise UsageError(str(err)) from None
            observers.append(recorder)
        if not args.quiet:
            print(f"hopnav figure: running scenario {sc.name} ({n} runs)...", file=sys.stderr)
        try:
            NavigationRunner(sc, observer=Observers(observers)).run_many(n, args.seed)
        except BaseException as err:
            if recorder is not None:
                recorder.discard()
            if isinstance(err, Exception):
                raise RunFailed(f"scenario {sc.name}: the run failed: {err}") from err
            raise
        if recorder is not None:
            recorder.close()
        end = keep.end
        if not args.quiet and end is not None:
            print(
                f"hopnav figure: scenario {sc.name}, run {k}: {end.outcome}, {end.steps} hops, "
                f"reward {end.reward:g}",
                file=sys.stderr,
            )
        route = Route.from_hops(keep.hops, sc.start, end.switch_step if end else None)
        panels.append((sc, route, end, k, n, prov))
    return panels
