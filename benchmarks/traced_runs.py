"""Navigation runs with a trace of the guarantee, in worker processes (for guarantee.py and
guarantee_stability.py).

A traced run is :func:`hopper_sim.navigation.runner.run_single`'s run plus: the worst-case
satisfaction
probability at the start after every re-synthesis (``p_start``) and, for a run that left the
goal-reaching plan of its switch, the hop that did it and what the intervals of the switch
said about that landing: ``"excluded"`` (upper bound 0: the intervals were wrong) or
``"allowed"`` (a landing the adversary may make; ``p_switch`` accounts for it).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field

import numpy as np

from hopper_sim.experiments.sweep_backends import _init_worker
from hopper_sim.navigation.events import HopEvent, Observer, RunEnd, SynthesisEvent
from hopper_sim.navigation.runner import NavigationRunner
from planner.imdp.grid import ACTIONS
from planner.intervals import TransitionIntervals
from planner.learning import Resynthesis
from planner.scenario import Scenario


@dataclass
class RunTrace:
    """One traced run (see the module docstring); ``left`` is ``None`` for a run that kept
    its plan (or never switched)."""

    end: RunEnd
    seed: int
    p_start: list[float] = field(default_factory=list)
    synthesis_steps: list[int] = field(default_factory=list)
    left: dict | None = None


class _Trace(Observer):
    def __init__(self) -> None:
        self.p_start: list[float] = []
        self.steps: list[int] = []
        self.hops: list[tuple[np.ndarray, int, int]] = []

    def on_synthesis(self, event: SynthesisEvent) -> None:
        self.p_start.append(float(event.p_worst_initial))
        self.steps.append(int(event.step))

    def on_hop(self, event: HopEvent) -> None:
        self.hops.append(
            (np.asarray(event.start_pos), ACTIONS.index(event.executed_action), int(event.cell))
        )


class _Runner(NavigationRunner):
    """Keeps the transition intervals of every re-synthesis with the hop count it used."""

    def _synthesise(self, gp, positions, errors, actions, current, previous=None) -> Resynthesis:
        res = super()._synthesise(gp, positions, errors, actions, current, previous)
        self.kept.append((len(positions), res.intervals))
        return res


def _upper(ti: TransitionIntervals, cell: int, action: int, successor: int) -> float:
    sel = (ti.state == cell) & (ti.action == action) & (ti.successor == successor)
    return float(ti.upper[sel].max()) if sel.any() else 0.0


def traced_run(scenario: Scenario, seed: int, run_index: int = 0) -> RunTrace:
    """One run of ``scenario`` with default settings, traced (picklable, module level)."""
    trace = _Trace()
    runner = _Runner(scenario, observer=trace)
    runner.kept = []
    end = runner.run(seed, run_index=run_index)
    out = RunTrace(end, int(seed), trace.p_start, trace.steps)
    if end.left_plan_step is not None and end.switch_step is not None:
        k = int(end.left_plan_step) - 1  # the hop that landed outside the plan
        start, action, landed = trace.hops[k]
        cell = int(runner.grid.locate(start[None])[0])
        ti = [t for n, t in runner.kept if n <= end.switch_step][-1]
        upper = _upper(ti, cell, action, landed)
        out.left = {
            "hop": k,
            "cell": cell,
            "action": ACTIONS[action],
            "landed": landed,
            "upper": upper,
            "kind": "excluded" if upper <= 0.0 else "allowed",
        }
    return out


def run_traced(scenario: Scenario, seeds: list[int], workers: int) -> Iterator[RunTrace]:
    """Traced runs of ``scenario`` with ``seeds`` on ``workers`` spawned processes (one
    compute thread each, as in :mod:`hopper_sim.experiments.sweep`), in completion order."""
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker) as pool:
        pending = {pool.submit(traced_run, scenario, s, k) for k, s in enumerate(seeds)}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut.result()
