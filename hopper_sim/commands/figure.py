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
destinations are checked before anything runs. Exit code 2 for bad input, 1 for a run that
failed.

Example: ``hopnav figure --scenarios a,b,c,d --out fig4.pdf --out fig4.png``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "figure",
        help="draw Figure 4 (runs scenarios or reads recordings) or the Table I plot",
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


class _Fail(Exception):
    """A one-line error with its exit code."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code


def run(args: argparse.Namespace) -> int:
    from hopper_sim.figures import FigureError, check_destination

    try:
        outs = [check_destination(p) for p in _prepare(args.out)]
        for name, value, low in (("--run", args.run, 1), ("--runs", args.runs, 1)):
            if value is not None and value < low:
                raise _Fail(f"{name} must be at least {low}, got {value}")
        if args.max_steps is not None and args.max_steps < 1:
            raise _Fail(f"--max-steps must be at least 1, got {args.max_steps}")
        if args.table_i:
            written = _table_i(args, outs)
        else:
            written = _figure4(args, outs)
    except FigureError as err:
        print(f"hopnav figure: {err}", file=sys.stderr)
        return 2
    except _Fail as err:
        print(f"hopnav figure: {err}", file=sys.stderr)
        return err.code
    for path in written:
        print(path)
    return 0


def _prepare(paths: list[str]) -> list[Path]:
    """The output paths, their folders created."""
    from hopper_sim.figures import figure_format

    out = []
    for p in paths:
        path = Path(p)
        figure_format(path)  # unknown extension: fail before creating anything
        path.parent.mkdir(parents=True, exist_ok=True)
        out.append(path)
    return out


def _table_i(args: argparse.Namespace, outs: list[Path]) -> list[Path]:
    from hopper_sim.figures import save_figure
    from hopper_sim.sweep import summarize
    from hopper_sim.sweep_files import SweepFileError, read_rows_csv
    from hopper_sim.sweep_plot import build_table_plot

    try:
        rows = read_rows_csv(args.table_i)
    except SweepFileError as err:
        raise _Fail(str(err)) from err
    if not rows:
        raise _Fail(f"{args.table_i} holds no runs")
    fig = build_table_plot(summarize(rows))
    return [save_figure(fig, out) for out in outs]


def _figure4(args: argparse.Namespace, outs: list[Path]) -> list[Path]:
    from hopper_sim.figures import Panel, build_figure, run_title, save_figure

    panels = _from_recordings(args) if args.rrd else _from_scenarios(args)
    drawn = [
        Panel(sc, route, run_title(sc, run_number=k, n_runs=n, end=end, hops=route.n_hops))
        for sc, route, end, k, n in panels
    ]
    fig = build_figure(drawn)
    return [save_figure(fig, out) for out in outs]


def _pick(n_runs: int, wanted: int | None, where: str) -> int:
    """The 1-based run to draw of ``n_runs``."""
    k = n_runs if wanted is None else wanted
    if not 1 <= k <= n_runs:
        raise _Fail(f"--run {k}: {where} has runs 1..{n_runs}")
    return k


def _from_recordings(args: argparse.Namespace) -> list[tuple]:
    from hopper_sim.recording import RecordingError, read_runs

    panels = []
    for path in args.rrd:
        try:
            sc, runs = read_runs(path)
        except RecordingError as err:
            raise _Fail(str(err)) from err
        by_number = {r.run: r for r in runs}
        if not runs:
            raise _Fail(f"{path} holds no runs")
        if args.run is not None and args.run not in by_number:
            raise _Fail(f"--run {args.run}: {path} has runs {', '.join(map(str, by_number))}")
        rec = by_number[args.run] if args.run is not None else runs[-1]
        panels.append((sc, rec.route, rec.end, rec.run, len(runs)))
    return panels


def _from_scenarios(args: argparse.Namespace) -> list[tuple]:
    from planner.errors import PlannerError
    from planner.scenario import load_scenario

    names = [s.strip() for s in (args.scenarios or "a,b,c,d").split(",") if s.strip()]
    if not names:
        raise _Fail("--scenarios names no scenario")
    scenarios = []
    for name in names:  # all checked before the first run
        try:
            sc = load_scenario(name)
        except PlannerError as err:
            raise _Fail(str(err)) from err
        if args.max_steps is not None:
            sc = sc.with_runner(max_steps=args.max_steps)
        n = sc.runner.runs if args.runs is None else args.runs
        scenarios.append((name, sc, n, _pick(n, args.run, f"scenario {sc.name} ({n} runs)")))
    save = Path(args.save_rrd) if args.save_rrd else None
    if save is not None:
        save.mkdir(parents=True, exist_ok=True)

    from hopper_sim.events import Observer, Observers
    from hopper_sim.figures import Route
    from hopper_sim.recording import RecordingError, RerunRecorder
    from hopper_sim.runner import NavigationRunner

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
    for name, sc, n, k in scenarios:
        keep = Keep(k - 1)
        observers: list = [keep]
        recorder = None
        if save is not None:
            stem = Path(name).stem if name.endswith(".toml") else sc.name
            try:
                recorder = RerunRecorder(save / f"{stem}.rrd")
            except RecordingError as err:
                raise _Fail(str(err)) from err
            observers.append(recorder)
        if not args.quiet:
            print(f"hopnav figure: running scenario {sc.name} ({n} runs)...", file=sys.stderr)
        try:
            NavigationRunner(sc, observer=Observers(observers)).run_many(n, args.seed)
        except Exception as err:
            if recorder is not None:
                recorder.discard()
            raise _Fail(f"scenario {sc.name}: the run failed: {err}", code=1) from err
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
        panels.append((sc, route, end, k, n))
    return panels
