"""``hopnav run``: the main job, a case study end to end.

Runs a scenario (shipped ``a``-``d`` or a TOML path) for ``--runs`` consecutive runs (default:
the scenario's; an unknown reward's Q-values and learned rewards carry over between runs while
the GP data is reset), writes one rerun recording of the invocation and a figure of the last
finished run (PNG, SVG or PDF by the extension of ``--png``; default: under ``runs/``),
shows a progress bar per run and prints a summary table (or, with ``--json``, one JSON object
per run).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from hopnav.arguments import (
    add_set_argument,
    figure_file,
    input_file,
    non_negative_int,
    output_file,
    positive_int,
    run_config,
)
from hopnav.errors import RunFailed, UsageError, is_interrupt
from hopnav.interrupts import deliver_again, interrupt_here
from hopnav.kernels import prepare_kernels
from planner.modes import Candidates, TourMode


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("run", description=__doc__)
    p.add_argument("--scenario", default="a", help="shipped name (a, b, c, d) or TOML path")
    p.add_argument(
        "--runs", type=positive_int, help="number of consecutive runs (default: scenario's)"
    )
    p.add_argument(
        "--seed", type=non_negative_int, help="seed of the first run (default: scenario's)"
    )
    p.add_argument("--max-steps", type=positive_int, help="hop cap per run (default: scenario's)")
    p.add_argument(
        "--explore-to",
        choices=tuple(Candidates),
        help="end components exploration steers to (planner.candidates) [nonviolating]",
    )
    p.add_argument(
        "--tour",
        choices=tuple(TourMode),
        help="exploration inside the chosen component (planner.tour) [reward]",
    )
    add_set_argument(p)
    p.add_argument("--rrd", help="rerun recording to write (default: runs/<scenario>.rrd)")
    p.add_argument(
        "--png", help="figure of the last run, .png/.svg/.pdf (default: runs/<scenario>.png)"
    )
    p.add_argument("--no-rrd", action="store_true", help="write no recording")
    p.add_argument("--no-png", action="store_true", help="write no figure")
    p.add_argument(
        "--q-table",
        help="load the Q-learner from this file if it exists (it must be of the same "
        "scenario), save it after",
    )
    p.add_argument(
        "--checkpoint",
        help="controller checkpoint (default: the shipped one; see hopnav train-controller)",
    )
    p.add_argument("--json", action="store_true", help="print a JSON list, one object per run")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


class _Progress:
    """Observer drawing one tqdm bar per run (to stderr)."""

    def __init__(self, total: int, n_runs: int, disable: bool) -> None:
        self.total, self.n_runs, self.disable = total, n_runs, disable
        self.bar = None
        self._opening = False  # inside tqdm(): a Ctrl-C there leaves a drawn, unowned bar

    def on_run_start(self, event) -> None:
        from tqdm import tqdm

        self._opening = True
        self.bar = tqdm(
            total=self.total,
            desc=f"run {event.run_index + 1}/{self.n_runs}",
            unit="hop",
            disable=self.disable,
            file=sys.stderr,
            leave=True,
        )
        self._opening = False

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
        """Close the bar of a run that did not end (interrupted or failed), so that the
        error line that follows starts a line of its own."""
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        elif self._opening and not self.disable:
            sys.stderr.write("\n")
        self._opening = False


def summary_table(ends) -> str:
    """Plain-text table of a list of :class:`~hopper_sim.navigation.events.RunEnd`."""
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


class _Finished:
    """Observer keeping the :class:`~hopper_sim.navigation.events.RunEnd` of every finished run."""

    def __init__(self) -> None:
        self.ends: list = []
        self.current: int | None = None

    def on_run_start(self, event) -> None:
        self.current = event.run_index

    def on_hop(self, event) -> None:
        pass

    def on_synthesis(self, event) -> None:
        pass

    def on_run_end(self, event) -> None:
        self.ends.append(event)
        self.current = None


class _WholeEvents:
    """Hands each event to every observer before an interrupt lands.

    While :meth:`interrupts_between_events` is active, SIGINT and SIGTERM raise
    ``KeyboardInterrupt`` at once, except while an event is being handed out: then it is
    raised when every observer has the event. Otherwise the count of finished runs, the
    recording and the figure could disagree by the run whose end the signal split. An
    interrupt that Python drops because it landed in a finaliser is raised again after.
    """

    def __init__(self, fan) -> None:
        self.fan = fan
        self._busy = False
        self._pending: int | None = None
        self._raised: int | None = None
        self._previous_hook = sys.unraisablehook

    def _signal(self, signum: int, frame) -> None:
        if self._busy:
            self._pending = signum
        elif interrupt_here(signum, frame):  # else delivered again later
            self._raised = signum
            raise KeyboardInterrupt(f"signal {signum}")

    def _dropped(self, unraisable) -> None:
        """``sys.unraisablehook``: an interrupt raised inside a finaliser or a weakref
        callback (numba's llvmlite objects are finalised while kernels compile) is printed
        and dropped by Python; deliver it again instead, once the finaliser has returned."""
        if isinstance(unraisable.exc_value, KeyboardInterrupt) and self._raised is not None:
            # from another thread: raised here, in the hook, it would be dropped again
            deliver_again(self._raised)
        else:
            self._previous_hook(unraisable)

    @contextmanager
    def interrupts_between_events(self) -> Iterator[None]:
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            yield
            return
        kinds = (signal.SIGINT, signal.SIGTERM)
        previous = [signal.signal(k, self._signal) for k in kinds]
        self._previous_hook, sys.unraisablehook = sys.unraisablehook, self._dropped
        try:
            yield
        finally:
            for k, handler in zip(kinds, previous, strict=True):
                signal.signal(k, handler)
            sys.unraisablehook = self._previous_hook

    def _deliver(self, handler, event) -> None:
        self._busy = True
        try:
            handler(event)
        finally:
            self._busy = False
        if self._pending is not None:
            signum, self._pending = self._pending, None
            raise KeyboardInterrupt(f"signal {signum}")

    def on_run_start(self, event) -> None:
        self._deliver(self.fan.on_run_start, event)

    def on_hop(self, event) -> None:
        self._deliver(self.fan.on_hop, event)

    def on_synthesis(self, event) -> None:
        self._deliver(self.fan.on_synthesis, event)

    def on_run_end(self, event) -> None:
        self._deliver(self.fan.on_run_end, event)


def _load_learner(path: str, expected: dict):
    """The Q-learner saved in ``path``, refused unless it was learnt on the same scenario."""
    from hopper_sim.experiments.provenance import ProvenanceError, require_same_scenario
    from planner.errors import PlannerError
    from planner.qlearning import RobustQLearner

    try:
        learner = RobustQLearner.load(path)
        require_same_scenario(learner.metadata.get("provenance"), expected, f"--q-table {path}")
    except (PlannerError, ProvenanceError) as err:
        raise UsageError(str(err)) from None
    return learner


def _controller(ckpt_path: Path):
    """(model, controller) for the checkpoint ``ckpt_path``, checked against the MJCF."""
    from hopper_sim.controller import LegAngleController, load_checkpoint
    from hopper_sim.controller.errors import ControllerError
    from hopper_sim.physics.model import HopperModel

    model = HopperModel.load()
    try:
        ckpt = load_checkpoint(ckpt_path, expected_param_hash=model.param_hash())
        controller = LegAngleController.from_checkpoint(ckpt)
    except ControllerError as err:
        raise UsageError(f"--checkpoint: {err}") from None
    return model, controller


def _records(ends, files: dict, prov: dict) -> list[dict]:
    return [
        {
            "outcome": e.outcome,
            "reason": e.reason,
            "steps": e.steps,
            "reward": e.reward,
            "switch_step": e.switch_step,
            "p_switch": e.p_switch,
            "left_plan_step": e.left_plan_step,
            "collections": e.collections,
            "mission": None if e.mission is None else dataclasses.asdict(e.mission),
            "resyntheses": [dataclasses.asdict(r) for r in e.resyntheses],
            "backups": e.backups,
            "seconds": e.seconds,
            "timings": e.timings,
            **files,
            "provenance": prov,
        }
        for e in ends
    ]


def _report(args, sc, ends, files: dict, prov: dict) -> None:
    if args.json:
        print(json.dumps(_records(ends, files, prov), indent=2))
        return
    print(f"scenario {sc.name}: {sc.formula}, P_sat = {sc.p_sat}")
    if ends:
        print(summary_table(ends))
    for key, path in files.items():
        if path is not None:
            print(f"{key}: {path}")


def _settings(args: argparse.Namespace, sc):
    """The run's configuration tree: the scenario's, the flags, then ``--set``."""
    flags = {
        "run.max_steps": ("--max-steps", args.max_steps),
        "run.runs": ("--runs", args.runs),
        "run.seed": ("--seed", args.seed),
        "planner.candidates": ("--explore-to", args.explore_to),
        "planner.tour": ("--tour", args.tour),
    }
    return run_config(sc, args.set, flags)


def _outputs(args: argparse.Namespace, sc) -> tuple[Path | None, Path | None]:
    """The recording and figure paths of ``args`` (``None``: not written), with ``--q-table``
    checked: refused for a known-reward scenario, its folder writable."""
    stem = Path(args.scenario).stem if args.scenario.endswith(".toml") else sc.name
    rrd = None if args.no_rrd else output_file(args.rrd or f"runs/{stem}.rrd", "--rrd", (".rrd",))
    png = None if args.no_png else figure_file(args.png or f"runs/{stem}.png", "--png")
    if args.q_table:
        if sc.reward_known:
            raise UsageError(
                f"--q-table {args.q_table}: scenario {sc.name} has a known reward, so nothing "
                "is learnt to load or save (--q-table is for unknown-reward scenarios)"
            )
        output_file(args.q_table, "--q-table")
    return rrd, png


def _runner(args: argparse.Namespace, sc, settings, ckpt_path: Path, learner):
    """The navigation runner of scenario ``sc`` (with the tree applied) on the controller of
    ``ckpt_path``, configured by the tree ``settings``."""
    from hopper_sim.navigation.environment import HopperGridEnv
    from hopper_sim.navigation.runner import NavigationRunner

    model, controller = _controller(ckpt_path)
    env = HopperGridEnv(sc, model=model, controller=controller, settings=settings.env)
    try:
        return NavigationRunner(sc, env=env, settings=settings, learner=learner)
    except ValueError as err:  # e.g. a Q-table of another product size, a formula too hard
        where = f"--q-table {args.q_table}" if learner is not None else f"scenario {sc.name}"
        raise UsageError(f"{where}: {' '.join(str(err).split())}") from None


def run(args: argparse.Namespace) -> int:
    from planner.errors import PlannerError
    from planner.scenario import load_scenario

    try:
        sc = load_scenario(args.scenario)
    except PlannerError as err:
        raise UsageError(str(err)) from None
    settings = _settings(args, sc)
    rrd, png = _outputs(args, sc)
    from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT
    from hopper_sim.experiments.provenance import provenance

    ckpt_path = input_file(args.checkpoint or DEFAULT_CHECKPOINT, "--checkpoint")
    prov = provenance(sc, ckpt_path)  # of the scenario as loaded, before the overrides below
    learner = None
    if args.q_table and Path(args.q_table).exists():
        learner = _load_learner(args.q_table, prov)

    from hopper_sim.navigation.events import Observers
    from hopper_sim.viz.figures import FigureWriter
    from hopper_sim.viz.recording import RerunRecorder

    sc = settings.apply_to(sc)
    n_runs = sc.runner.runs
    runner = _runner(args, sc, settings, ckpt_path, learner)

    prepare_kernels("hopnav run", quiet=args.quiet or args.json)
    for path in (rrd, png):
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
    finished = _Finished()
    progress = _Progress(sc.runner.max_steps, n_runs, args.quiet or args.json)
    observers = [finished, progress]
    recorder = RerunRecorder(rrd, provenance=prov) if rrd is not None else None
    if recorder is not None:
        observers.append(recorder)
    writer = None
    if png is not None:
        writer = FigureWriter(png, n_runs=n_runs, metadata=prov)
        observers.append(writer)
    fan = Observers(observers)
    whole = _WholeEvents(fan)
    runner.observer = whole
    files = {"rrd": None if rrd is None else str(rrd), "png": None if png is None else str(png)}
    seed = sc.runner.seed
    failure: str | None = None
    try:
        with whole.interrupts_between_events():
            runner.run_many(n_runs, seed)
    except KeyboardInterrupt:
        failure = "interrupted"
    except Exception as err:  # a failed run: keep what finished, then report it
        if is_interrupt(err):  # Ctrl-C inside a compiled kernel
            failure = "interrupted"
        else:
            failure = f"failed ({type(err).__name__}: {' '.join(str(err).split())})"
    if failure is None:
        fan.close()
    else:
        progress.close()
        _keep_finished(finished, recorder, writer, files)
    if args.q_table and runner.learner is not None:
        runner.learner.save(args.q_table, metadata={"provenance": prov})
    _report(args, sc, finished.ends, files, prov)
    if failure is not None:
        raise RunFailed(_failure_message(failure, finished, n_runs, files))
    return 0


def _failure_message(failure: str, finished: _Finished, n_runs: int, files: dict) -> str:
    """The one-line error of an interrupted or failed invocation: which run, what is kept."""
    k = (finished.current if finished.current is not None else len(finished.ends)) + 1
    kept = [p for p in files.values() if p is not None]
    where = f" in {', '.join(kept)}" if kept and finished.ends else ""
    return f"run {k} of {n_runs} {failure}; kept the {len(finished.ends)} finished run(s){where}"


def _keep_finished(finished: _Finished, recorder, writer, files: dict) -> None:
    """After an interrupt or a failure: the recording keeps the finished runs (and the hops
    of the one in progress) if any run finished, else it is discarded; the figure of the last
    finished run is written (a fixed ``--png`` path is written on close). A second Ctrl-C does
    not cut this short."""
    import signal

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        if recorder is not None:
            if finished.ends:
                recorder.close()
            else:
                recorder.discard()
                files["rrd"] = None
        if writer is not None and finished.ends:
            writer.close()
        if not finished.ends:
            files["png"] = None
    finally:
        signal.signal(signal.SIGINT, previous)
