"""Deterministic synthetic runner events for observer tests (no simulation involved)."""

from __future__ import annotations

import numpy as np

from hopper_sim.navigation.events import HopEvent, RunEnd, RunStart, SynthesisEvent
from planner.scenario import Scenario

PERIOD = 0.45  # s per hop, close to the steady SLIP gait (hop k lasts PERIOD + 0.01 k)


def run_events(
    scenario: Scenario, run_index: int, n_hops: int, outcome: str = "success", samples: int = 21
):
    """RunStart, an initial SynthesisEvent, ``n_hops`` eastward E2 hops and a RunEnd.

    As from the runner, a hop's times (``touchdown_time``, ``com_time``) count from its own
    departure; hop ``k`` lasts ``PERIOD + 0.01 k`` s and has ``samples`` CoM samples.
    """
    events: list = [RunStart(run_index, scenario, seed=100 + run_index)]
    w = scenario.world
    gx = np.linspace(0.5, w.width - 0.5, 5)
    gy = np.linspace(0.5, w.height - 0.5, 4)
    x, y = np.meshgrid(gx, gy, indexing="ij")
    events.append(
        SynthesisEvent(
            run_index,
            0,
            gx,
            gy,
            gp_mean=np.stack([0.1 * np.sin(x), 0.1 * np.cos(y)], axis=-1),
            gp_std=np.full((5, 4, 2), 0.3),
            p_worst_initial=0.4,
            timings={"gp_fit": 0.5, "synthesis": 0.25},
        )
    )
    pos = np.array(scenario.start)
    total = 0.0
    for step in range(n_hops):
        target = np.floor(pos / w.cell) * w.cell + 0.5 * w.cell + np.array([2.0 * w.cell, 0.0])
        landing = target + 0.05 * np.array([np.sin(step), np.cos(step)])
        s = np.linspace(0.0, 1.0, samples)
        xy = pos + s[:, None] * (landing - pos)
        z = 1.0 + 0.3 * np.abs(np.sin(np.pi * (2 * s - 0.5)))
        com = np.column_stack([xy, z])
        foot = np.array([*(pos + 0.5 * (landing - pos)), 0.0])
        cell = int(w.geometry.locate(landing))
        reward = float(scenario.reward_grid.ravel()[cell]) if cell < w.n_cells else 0.0
        total += reward
        goal_phase = step >= n_hops // 2
        events.append(
            HopEvent(
                run_index=run_index,
                step=step,
                phase="goal_reaching" if goal_phase else "exploration",
                source="RL" if step % 3 == 1 else "LTL",
                backup=step == 2,
                requested_action="N1" if step == 2 else "E2",
                executed_action="E2",
                start_pos=pos,
                target=target,
                landing=landing,
                com_path=com,
                foot=foot,
                touchdown_time=0.2,
                cell=cell,
                product_state=cell,
                p_worst=min(1.0, 0.4 + 0.1 * step),
                reward=reward,
                total_reward=total,
                com_time=s * (PERIOD + 0.01 * step),
            )
        )
        pos = landing
    events.append(
        RunEnd(
            run_index,
            outcome,
            steps=n_hops,
            reward=total,
            switch_step=n_hops // 2,
            p_switch=0.7,
            backups=1 if n_hops > 2 else 0,
            seconds=1.5,
            timings={"gp_fit": 0.5, "synthesis": 0.25},
        )
    )
    return events


def feed(observer, events) -> None:
    """Deliver ``events`` to ``observer`` through the matching handlers."""
    handlers = {
        RunStart: observer.on_run_start,
        SynthesisEvent: observer.on_synthesis,
        HopEvent: observer.on_hop,
        RunEnd: observer.on_run_end,
    }
    for e in events:
        handlers[next(t for t in handlers if isinstance(e, t))](e)
