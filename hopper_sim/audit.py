"""Interval soundness audit: do the learned transition intervals contain what MuJoCo does?

Procedure (issue "learning", acceptance):

1. One navigation run of the scenario collects departure positions, landing errors and the
   interstitial velocities the hopper met (:func:`collect_run_data`).
2. The landing-error GPs are fitted on that data and the transition intervals of the grid
   abstraction are computed exactly as the runner computes them
   (:func:`planner.intervals.cell_error_bounds`, :func:`planner.intervals.transition_intervals`).
3. For each audited (cell, action) pair, ``samples`` hops start from uniformly random points
   of the cell with velocities drawn from the run's interstitial velocities; the controller
   computes the touchdown angles for the pair's target with the backup switch off (only that
   action is allowed), and the hops are simulated in one batch in MuJoCo with the world's
   terrain field, fresh landing noise and the stance thrust.
4. For every (cell, action, successor) triple, the empirical frequency of landing in the
   successor passes when it lies in ``[lower - m, upper + m]``, ``m`` the 99 % binomial margin
   (:func:`planner.audit.audit_intervals`). Successors the intervals leave out have
   ``[0, 0]``. Failed hops are counted separately, not as landings.

The audit checks the abstraction *as used*: the GP models the error as a function of the
departure position only, while the hop also depends on the incoming velocity; a mismatch
there shows up as failed triples.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hopper_sim.batch import simulate_hops
from hopper_sim.controller.simulator import nominal_energy
from hopper_sim.environment import HopperGridEnv
from hopper_sim.events import HopEvent, Observer
from hopper_sim.noise import sample_model_noise
from hopper_sim.runner import NavigationRunner, RunnerSettings
from planner.audit import AuditResult
from planner.audit import audit_intervals as audit
from planner.gp.landing import LandingErrorGP
from planner.imdp.grid import ACTIONS
from planner.intervals import TruncatedGaussianNoise, cell_error_bounds, transition_intervals
from planner.torch_threads import torch_threads


@dataclass(frozen=True)
class RunData:
    """Departure positions (N, 2) [m], landing errors (N, 2) [m] and the interstitial
    velocities (M, 3) [m/s] the hopper had at its departures."""

    positions: np.ndarray
    errors: np.ndarray
    velocities: np.ndarray


class _Collector(Observer):
    def __init__(self, env: HopperGridEnv) -> None:
        self.env = env
        self.pos: list[np.ndarray] = []
        self.err: list[np.ndarray] = []
        self.vel: list[np.ndarray] = [env.controller.steady.velocity.copy()]

    def on_hop(self, event: HopEvent) -> None:
        self.pos.append(np.array(event.start_pos))
        self.err.append(np.array(event.landing) - np.array(event.target))
        self.vel.append(self.env.vel.copy())


def collect_run_data(runner: NavigationRunner, seed: int) -> RunData:
    """Run one navigation run and return its data (the runner's observer is replaced)."""
    collector = _Collector(runner.env)
    previous, runner.observer = runner.observer, collector
    try:
        runner.run(seed)
    finally:
        runner.observer = previous
    return RunData(
        np.array(collector.pos).reshape(-1, 2),
        np.array(collector.err).reshape(-1, 2),
        np.array(collector.vel).reshape(-1, 3),
    )


@dataclass(frozen=True)
class SampledAudit:
    """The audit of :func:`planner.audit.audit_intervals` on MuJoCo samples, the number of
    failed hops (not counted as landings), the hops simulated, and the successor counts
    ``(P, n_states)`` per audited pair."""

    result: AuditResult
    failures: int
    hops: int
    counts: np.ndarray


def audit_intervals(
    env: HopperGridEnv,
    data: RunData,
    pairs: np.ndarray,
    *,
    samples: int = 200,
    rng: np.random.Generator,
    settings: RunnerSettings | None = None,
    confidence: float = 0.99,
    progress: Callable[[int], None] | None = None,
) -> SampledAudit:
    """Audit the intervals learned from ``data`` on ``pairs`` ((P, 2) cell, action ids)."""
    settings = settings or RunnerSettings()
    grid = env.grid
    pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
    if pairs.size and not grid.enabled[pairs[:, 0], pairs[:, 1]].all():
        bad = pairs[~grid.enabled[pairs[:, 0], pairs[:, 1]]][0]
        raise ValueError(f"action {ACTIONS[bad[1]]} is not enabled in cell {bad[0]}")
    gp = LandingErrorGP(settings.gp, seed=0)
    gp.fit(data.positions, data.errors)
    pp = env.model.perturbation
    bounds = cell_error_bounds(
        gp, grid, samples_per_axis=settings.samples_per_axis, delta=settings.delta
    )
    ti = transition_intervals(bounds, grid, TruncatedGaussianNoise(pp.noise_sigma, pp.noise_bound))

    n_pairs = len(pairs)
    cells = np.repeat(pairs[:, 0], samples)
    acts = np.repeat(pairs[:, 1], samples)
    i, j = grid.cell_ij(cells)
    pos = (np.stack([i, j], axis=1) + rng.random((cells.size, 2))) * grid.cell
    vel = data.velocities[rng.integers(len(data.velocities), size=cells.size)]
    targets = grid.target_centres[cells, acts]
    alpha = np.empty(cells.size)
    beta = np.empty(cells.size)
    # the controller solves one departure state at a time (its batch is over targets)
    with torch_threads(settings.torch_threads):
        for k in range(cells.size):
            d = env.controller.decide(pos[k], vel[k], [acts[k]], targets[k][None], int(acts[k]))
            alpha[k], beta[k] = d.alpha, d.beta
            if progress is not None and (k + 1) % samples == 0:
                progress(samples)
    nu = sample_model_noise(env.model, rng, cells.size)
    res = simulate_hops(
        env.model,
        vel,
        alpha,
        beta,
        pos=pos,
        terrain=env.terrain,
        noise=nu,
        thrust=True,
        nominal_energy=nominal_energy(env.model, env.controller.steady.speed),
    )
    landed = grid.locate(res.next_pos[res.ok])
    pair_id = np.repeat(np.arange(n_pairs), samples)[res.ok]
    counts = np.zeros((n_pairs, grid.n_states), dtype=np.int64)
    np.add.at(counts, (pair_id, landed), 1)
    sampled = counts.sum(axis=1) > 0
    result = audit(ti, pairs[sampled, 0], pairs[sampled, 1], counts[sampled], confidence=confidence)
    return SampledAudit(result, int((~res.ok).sum()), int(cells.size), counts)
