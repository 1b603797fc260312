"""Cost of the run observers per hop: rerun recording and PNG figure vs a no-op observer.

Feeds the same synthetic run (``--hops`` hops with 60-sample CoM arcs, a synthesis every 50
hops with a 30 x 30 GP grid) to a no-op :class:`Observer`, to :class:`RerunRecorder` writing
every hop at once (``flush_every=1``, the baseline) and buffering hops (the default), and to
:class:`FigureWriter`; prints microseconds per hop and the ratio of the buffered recorder to
the baseline, all measured in this process. Run: ``python benchmarks/observers.py``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hopper_sim.navigation.events import HopEvent, Observer, RunEnd, RunStart, SynthesisEvent
from hopper_sim.viz.figures import FigureWriter
from hopper_sim.viz.recording import RerunRecorder
from planner.scenario import load_scenario


def synthetic_run(n_hops: int, rng: np.random.Generator) -> list:
    sc = load_scenario("a")
    gx = gy = np.linspace(0.25, 14.75, 30)
    events: list = [RunStart(0, sc, seed=0)]
    pos = np.array(sc.start)
    total = 0.0
    for step in range(n_hops):
        if step % 50 == 0:
            events.append(
                SynthesisEvent(
                    0, step, gx, gy, rng.normal(0, 0.1, (30, 30, 2)), np.full((30, 30, 2), 0.2), 0.5
                )
            )
        target = np.clip(pos + rng.choice([-1.0, 1.0], 2), 0.5, 14.5)
        landing = target + rng.normal(0, 0.1, 2)
        s = np.linspace(0, 1, 60)
        com = np.column_stack([pos + s[:, None] * (landing - pos), 1 + 0.2 * np.sin(np.pi * s)])
        total += 1.0
        events.append(
            HopEvent(
                0, step, "exploration", "LTL", False, "E1", "E1", pos, target, landing, com,
                np.array([*(0.5 * (pos + landing)), 0.0]), 0.2,
                int(sc.world.geometry.locate(landing)), 0, 0.5, 1.0, total, 0.45 * s,
            )
        )  # fmt: skip
        pos = landing
    events.append(RunEnd(0, "timeout", n_hops, total, None, None, 0, 1.0))
    return events


def feed(observer, events) -> float:
    handlers = {
        RunStart: observer.on_run_start,
        SynthesisEvent: observer.on_synthesis,
        HopEvent: observer.on_hop,
        RunEnd: observer.on_run_end,
    }
    t0 = time.perf_counter()
    for e in events:
        handlers[type(e)](e)  # hop times count from each hop's departure, as from the runner
    if hasattr(observer, "close"):
        observer.close()
    return time.perf_counter() - t0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hops", type=int, default=500)
    args = parser.parse_args()
    events = synthetic_run(args.hops, np.random.default_rng(0))
    n = args.hops
    with tempfile.TemporaryDirectory() as d:
        warm = synthetic_run(10, np.random.default_rng(1))  # imports and first-call costs
        feed(RerunRecorder(Path(d) / "w.rrd", flush_every=1), warm)
        feed(RerunRecorder(Path(d) / "w.rrd"), warm)
        feed(FigureWriter(Path(d) / "w.png"), warm)
        noop = feed(Observer(), events)
        per_hop = feed(RerunRecorder(Path(d) / "a.rrd", flush_every=1), events)
        batched = feed(RerunRecorder(Path(d) / "b.rrd"), events)
        size = (Path(d) / "b.rrd").stat().st_size
        fig = feed(FigureWriter(Path(d) / "b.png"), events)
    print(f"hops: {n}")
    print(f"no-op observer:                        {noop / n * 1e6:9.1f} us/hop")
    print(f"RerunRecorder, flush_every=1 (baseline): {per_hop / n * 1e6:7.1f} us/hop")
    print(
        f"RerunRecorder, flush_every=100:        {batched / n * 1e6:9.1f} us/hop  "
        f"ratio to baseline {batched / per_hop:.3f}  ({size / 1e6:.2f} MB)"
    )
    print(f"FigureWriter (one PNG at run end):     {fig / n * 1e6:9.1f} us/hop")
    return 0


if __name__ == "__main__":
    sys.exit(main())
