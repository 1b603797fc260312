"""``hopnav run``: the main job, a case study end to end.

Runs a scenario (shipped ``a``-``d`` or a TOML path) for ``--runs`` consecutive runs (default:
the scenario's; an unknown reward's Q-values and learned rewards carry over between runs while
the GP data is reset), writes one rerun recording of the invocation and a PNG figure of the
last run (default: under ``runs/``), shows a progress bar per run and prints a summary table
(or, with ``--json``, one JSON object per run).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "run",
        help="run a case study (default: scenario a) with recording, figure and summary",
        description=__doc__,
    )
    p.add_argument("--scenario", default="a", help="shipped name (a, b, c, d) or TOML path")
    p.add_argument("--runs", type=int, help="number of consecutive runs (default: scenario's)")
    p.add_argument("--seed", type=int, help="seed of the first run (default: scenario's)")
    p.add_argument("--max-steps", type=int, help="hop cap per run (default: scenario's)")
    p.add_argument(
        "--explore-to",
        choices=("nonviolating", "accepting"),
        default="nonviolating",
        help="end components exploration steers to (see RunnerSettings.candidates)",
    )
    p.add_argument(
        "--tour",
        choices=("reward", "coverage"),
        default="reward",
        help="exploration inside the chosen component (see RunnerSettings.tour)",
    )
    p.add_argument("--rrd", help="rerun recording to write (default: runs/<scenario>.rrd)")
    p.add_argument("--png", help="figure of the last run (default: runs/<scenario>.png)")
    p.add_argument("--no-rrd", action="store_true", help="write no recording")
    p.add_argument("--no-png", action="store_true", help="write no figure")
    p.add_argument(
        "--q-table", help="load the Q-learner from this file if it exists, save it after"
    )
    p.add_argument("--json", action="store_true", help="print a JSON list, one object per run")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


class _Progress:
    """Observer drawing one tqdm bar per run (to stderr)."""

    def __init__(self, total: int, n_runs: int, disable: bool) -> None:
        self.total, self.n_runs, self.disable = total, n_runs, disable
        self.bar = None

    def on_run_start(self, event) -> None:
        from tqdm import tqdm

        self.bar = tqdm(
            total=self.total,
            desc=f"run {event.run_index + 1}/{self.n_runs}",
            unit="hop",
            disable=self.disable,
            file=sys.stderr,
            leave=True,
        )

    def on_hop(self, event) -> None:
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(
                phase=event.phase[:4], reward=f"{event.total_reward:.1f}", p=f"{event.p_worst:.2f}"
            )

    def on_synthesis(self, event) -> None:
        pass

    def on_run_end(self, event) -> None:
        if self.bar is not None:
            self.bar.set_postfix(outcome=event.outcome, reward=f"{event.reward:.1f}")
            self.bar.close()
            self.bar = None

    def close(self) -> None:
        pass


def summary_table(ends) -> str:
    """Plain-text table of a list of :class:`~hopper_sim.events.RunEnd`."""
    head = (
        "run",
        "outcome",
        "steps",
        "reward",
        "switch",
        "p_switch",
        "P after each synthesis",
        "left plan",
        "backups",
        "gp s",
        "abstr s",
        "synth s",
        "max batch s",
        "total s",
    )
    rows = []
    for e in ends:
        t = e.timings
        rows.append(
            (
                str(e.run_index + 1),
                e.outcome if not e.reason else f"{e.outcome} ({e.reason})",
                str(e.steps),
                f"{e.reward:.1f}",
                "-" if e.switch_step is None else str(e.switch_step),
                "-" if e.p_switch is None else f"{e.p_switch:.3f}",
                " ".join(f"{p:.2f}" for p in e.p_worst_trace) or "-",
                "-" if e.left_plan_step is None else str(e.left_plan_step),
                str(e.backups),
                f"{t.get('gp_fit', 0.0):.2f}",
                f"{t.get('abstraction', 0.0):.2f}",
                f"{t.get('synthesis', 0.0):.2f}",
                f"{t.get('batch_max', 0.0):.2f}",
                f"{e.seconds:.1f}",
            )
        )
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True))]
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from hopper_sim.events import Observers
    from hopper_sim.figures import FigureWriter
    from hopper_sim.recording import RerunRecorder
    from hopper_sim.runner import NavigationRunner, RunnerSettings
    from planner.errors import PlannerError
    from planner.qlearning import RobustQLearner
    from planner.scenario import load_scenario

    try:
        sc = load_scenario(args.scenario)
    except PlannerError as err:
        print(f"hopnav run: {err}", file=sys.stderr)
        return 2
    if args.max_steps is not None:
        if args.max_steps < 1:
            print(
                f"hopnav run: --max-steps must be at least 1, got {args.max_steps}", file=sys.stderr
            )
            return 2
        sc = sc.with_runner(max_steps=args.max_steps)
    n_runs = sc.runner.runs if args.runs is None else args.runs
    if n_runs < 1:
        print(f"hopnav run: --runs must be at least 1, got {n_runs}", file=sys.stderr)
        return 2
    stem = Path(args.scenario).stem if args.scenario.endswith(".toml") else sc.name
    rrd = None if args.no_rrd else Path(args.rrd or f"runs/{stem}.rrd")
    png = None if args.no_png else Path(args.png or f"runs/{stem}.png")
    for path in (rrd, png):
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
    learner = None
    if args.q_table and Path(args.q_table).exists():
        try:
            learner = RobustQLearner.load(args.q_table)
        except PlannerError as err:
            print(f"hopnav run: {err}", file=sys.stderr)
            return 2
    observers = [_Progress(sc.runner.max_steps, n_runs, args.quiet or args.json)]
    recorder = RerunRecorder(rrd) if rrd is not None else None
    if recorder is not None:
        observers.append(recorder)
    if png is not None:
        observers.append(FigureWriter(png))
    fan = Observers(observers)
    try:
        settings = RunnerSettings(candidates=args.explore_to, tour=args.tour)
        runner = NavigationRunner(sc, settings=settings, observer=fan, learner=learner)
        ends = runner.run_many(n_runs, args.seed)
    except BaseException:
        if recorder is not None:
            recorder.discard()
        raise
    fan.close()
    if args.q_table and runner.learner is not None:
        runner.learner.save(args.q_table)
    files = {"rrd": None if rrd is None else str(rrd), "png": None if png is None else str(png)}
    if args.json:
        out = [
            {
                "outcome": e.outcome,
                "reason": e.reason,
                "steps": e.steps,
                "reward": e.reward,
                "switch_step": e.switch_step,
                "p_switch": e.p_switch,
                "left_plan_step": e.left_plan_step,
                "collections": e.collections,
                "resyntheses": [dataclasses.asdict(r) for r in e.resyntheses],
                "backups": e.backups,
                "seconds": e.seconds,
                "timings": e.timings,
                **files,
            }
            for e in ends
        ]
        print(json.dumps(out, indent=2))
    else:
        print(f"scenario {sc.name}: {sc.formula}, P_sat = {sc.p_sat}")
        print(summary_table(ends))
        for key, path in files.items():
            if path is not None:
                print(f"{key}: {path}")
    return 0
