"""Interval soundness audit: do the learned transition intervals contain what MuJoCo does?

Procedure (issue "learning", acceptance), sampling hops the way the navigation loop makes them:

1. One navigation run of the scenario collects departure positions, landing errors (relative
   to the target of the *executed* action, as the runner records them), the executed actions
   and the interstitial velocities the hopper had at its departures (:func:`collect_run_data`);
   further runs (other seeds) add their departure velocities to the pool the audit draws from
   (:func:`pool_velocities`).
2. One re-synthesis on the first run's data (:func:`planner.learning.resynthesise`, the
   runner's settings) fits the landing-error model and gives the transition intervals exactly
   as the loop computes them, and the sub-models the loop would plan with.
3. Start states: a uniformly random point of the pair's cell and a velocity drawn uniformly
   from the pooled departure velocities. At each start state the controller decides as it
   does in the loop (:meth:`hopper_sim.navigation.environment.HopperGridEnv.step`): the audited
   action is
   requested, and its backup switch may execute instead the cheapest action of the *loop's
   allowed set* of that cell (:func:`loop_allowed_actions`: in the product state in which a
   run entering the cell is, the goal plan's actions where the worst-case satisfaction
   probability exceeds ``P_sat`` (the goal-reaching phase), else the nonviolating sub-model's
   actions (exploration), else all enabled actions (the fallback phase)), to which the
   requested action is added (the controller needs the request among its choices). The hop
   is simulated in MuJoCo with the world's terrain field, fresh landing noise and the stance
   thrust, and counts for the pair of the action it **executed** (if that pair is audited and
   not yet full) — so a hop requested for one pair may fill another, as in the loop.
4. Drawing goes on in rounds until every audited pair has ``samples`` executed, successful
   hops, or until the pair's own requests reach ``attempts * samples`` (the attempt cap).
   Pairs left short are reported (:attr:`SampledAudit.executed`): the controller rarely or
   never executes that action from the sampled states, because its cost there is above the
   backup threshold and another allowed action is cheaper.
5. For every (cell, action, successor) triple of the *full* pairs, the empirical frequency of
   landing in the successor passes when it lies in ``[lower - m, upper + m]``, ``m`` the 99 %
   binomial margin (:func:`planner.audit.audit_counts`, unchanged). Successors the intervals
   leave out have ``[0, 0]``. Pairs with some but fewer than ``samples`` hops are audited
   separately with the margin of their own count (:attr:`SampledAudit.partial`). Failed hops
   (the hopper fell) are counted separately, not as landings.

The binomial margin lets a successor that the intervals exclude (``[0, 0]``) be observed with
a frequency up to ``m`` (0.091 at 200 samples); :func:`excluded_landings` lists such landings
so that they are reported rather than hidden by the margin.

What the audit claims when it passes: for the audited pairs, the intervals of ``(cell, a)``
contain (up to the binomial margin) the successor distribution of hops that depart from a
uniform point of the cell with a velocity drawn from several runs' departures and that
**execute** ``a`` under the loop's controller and allowed set. That is the distribution the
abstraction's intervals stand for in the loop, where the policy's request can be replaced by
the backup. It says nothing about hops the controller would not execute (forced reversals
against the incoming velocity), nor about a cell whose departure velocities in a run differ
from the pooled ones (the velocity at a departure is drawn independently of the cell).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from hopper_sim.controller.simulator import nominal_energy
from hopper_sim.navigation.environment import HopperGridEnv
from hopper_sim.navigation.events import HopEvent, Observer
from hopper_sim.navigation.runner import NavigationRunner
from hopper_sim.physics.batch import BatchHopResult, simulate_hops
from hopper_sim.physics.noise import sample_model_noise
from planner._util.torch_threads import torch_threads
from planner.audit import AuditResult
from planner.audit import audit_counts as audit
from planner.gp.landing import LandingErrorGP
from planner.imdp.grid import ACTIONS, GridWorld
from planner.intervals import TransitionIntervals
from planner.learning import Resynthesis, resynthesise


@dataclass(frozen=True)
class RunData:
    """Departure positions (N, 2) [m], landing errors (N, 2) [m], executed actions (N,) and
    the interstitial velocities (M, 3) [m/s] the hopper had at its departures."""

    positions: np.ndarray
    errors: np.ndarray
    actions: np.ndarray
    velocities: np.ndarray


class _Collector(Observer):
    def __init__(self, env: HopperGridEnv) -> None:
        self.env = env
        self.pos: list[np.ndarray] = []
        self.err: list[np.ndarray] = []
        self.act: list[int] = []
        self.vel: list[np.ndarray] = [env.controller.steady.velocity.copy()]

    def on_hop(self, event: HopEvent) -> None:
        self.pos.append(np.array(event.start_pos))
        self.err.append(np.array(event.landing) - np.array(event.target))
        self.act.append(ACTIONS.index(event.executed_action))
        self.vel.append(self.env.vel.copy())


def collect_run_data(runner: NavigationRunner, seed: int) -> RunData:
    """Run one navigation run and return its data (the runner's observer is replaced)."""
    collector = _Collector(runner.env)
    previous, runner.observer = runner.observer, collector
    try:
        runner.run(seed)
    finally:
        runner.observer = previous
    # the velocity after the last hop is no departure velocity
    vel = np.array(collector.vel).reshape(-1, 3)[: len(collector.pos)]
    return RunData(
        np.array(collector.pos).reshape(-1, 2),
        np.array(collector.err).reshape(-1, 2),
        np.array(collector.act, dtype=np.int64),
        vel if len(vel) else np.array(collector.vel).reshape(-1, 3),
    )


def pool_velocities(runner: NavigationRunner, data: RunData, seeds: list[int]) -> RunData:
    """``data`` with the departure velocities of the runs ``seeds`` added to its own."""
    more = [collect_run_data(runner, int(s)).velocities for s in seeds]
    return replace(data, velocities=np.vstack([data.velocities, *more]))


def loop_allowed_actions(res: Resynthesis, grid: GridWorld, p_sat: float) -> np.ndarray:
    """``(n_cells, n_actions)`` mask: the actions the loop lets the controller choose from in
    each cell, for the synthesis ``res``, in the product state
    :meth:`~planner.imdp.product.ProductIMDP.entry_state` of the cell (for ``!Haz U Goal`` the
    state of every unfinished run there): the goal plan's actions where the worst-case
    satisfaction probability exceeds ``p_sat`` (goal reaching), else the nonviolating
    sub-model's (exploration), else every enabled action (the policy's fallback phase)."""
    cells = np.arange(grid.n_cells)
    ps = np.array([res.product.entry_state(int(c)) for c in cells], dtype=np.int64)
    enabled = grid.enabled[: grid.n_cells]
    nv = np.asarray(res.nonviolating.actions, dtype=bool)[ps] & enabled
    goal = np.asarray(res.goal.allowed, dtype=bool)[ps] & enabled
    use_goal = (res.satisfaction.values[ps] > p_sat) & goal.any(axis=1)
    explore = np.where(nv.any(axis=1, keepdims=True), nv, enabled)
    return np.where(use_goal[:, None], goal, explore)


@dataclass(frozen=True)
class SampledAudit:
    """The audit of the full pairs (``result``; ``None`` if none filled up), the audit of the
    pairs with some but fewer than ``samples`` executed hops (``partial``, each with the margin
    of its own count; ``None`` if there are none), per audited pair the successful executed
    hops (``executed``, ``(P,)``), its own requests (``requests``) and how many of those the
    controller executed as requested rather than switching to a backup (``as_requested``), the
    successor counts
    ``(P, n_states)``, the failed hops (not counted as landings), and the hops simulated and
    controller decisions made in all; ``intervals``: the audited transition intervals."""

    result: AuditResult | None
    partial: AuditResult | None
    executed: np.ndarray
    requests: np.ndarray
    as_requested: np.ndarray
    counts: np.ndarray
    failures: int
    hops: int
    decisions: int
    samples: int
    intervals: TransitionIntervals

    @property
    def full(self) -> np.ndarray:
        """``(P,)`` mask of the pairs that reached ``samples`` executed hops."""
        return self.executed >= self.samples


def _first_k(group: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Mask keeping, in order, at most ``limit[g]`` entries of each group ``g`` (``group``
    entries < 0 are never kept)."""
    keep = np.zeros(group.size, dtype=bool)
    idx = np.flatnonzero(group >= 0)
    if idx.size == 0:
        return keep
    g = group[idx]
    order = np.argsort(g, kind="stable")
    gs = g[order]
    start = np.flatnonzero(np.r_[True, gs[1:] != gs[:-1]])
    rank = np.arange(gs.size) - np.repeat(start, np.diff(np.r_[start, gs.size]))
    keep[idx[order[rank < limit[gs]]]] = True
    return keep


def _pair_index(grid: GridWorld, pairs: np.ndarray) -> np.ndarray:
    """``(n_cells, n_actions)``: the position of each audited ``(cell, action)`` in
    ``pairs``, -1 for the others.

    Raises:
        ValueError: a pair's action is not enabled in its cell, or a pair is repeated.
    """
    if pairs.size and not grid.enabled[pairs[:, 0], pairs[:, 1]].all():
        bad = pairs[~grid.enabled[pairs[:, 0], pairs[:, 1]]][0]
        raise ValueError(f"action {ACTIONS[bad[1]]} is not enabled in cell {bad[0]}")
    n_pairs = len(pairs)
    pair_index = np.full((grid.n_cells, len(ACTIONS)), -1, dtype=np.int64)
    pair_index[pairs[:, 0], pairs[:, 1]] = np.arange(n_pairs)
    if len(np.unique(pair_index[pair_index >= 0])) != n_pairs or (
        n_pairs and (pair_index[pairs[:, 0], pairs[:, 1]] != np.arange(n_pairs)).any()
    ):
        raise ValueError("each (cell, action) pair may be audited only once")
    return pair_index


def _resynthesise(runner: NavigationRunner, data: RunData) -> Resynthesis:
    """The re-synthesis the loop makes on ``data``, with the runner's settings."""
    with torch_threads(runner.settings.torch_threads):
        return resynthesise(
            LandingErrorGP(runner.gp_settings),
            runner.grid,
            runner.automaton,
            data.positions,
            data.errors,
            actions=data.actions,
            reward=runner.env.reward_table,
            initial_cell=runner.scenario.start_cell,
            settings=runner.synthesis_settings,
        )


def _decide(
    runner: NavigationRunner,
    allowed: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    cells: np.ndarray,
    acts: np.ndarray,
    progress: Callable[[int], None] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(executed action, alpha, beta)`` of the controller at each start state
    ``(pos[k], vel[k])`` of ``cells[k]`` asked for ``acts[k]``, choosing among the loop's
    allowed actions of the cell and the request."""
    env, grid = runner.env, runner.grid
    ex = np.empty(cells.size, dtype=np.int64)
    alpha = np.empty(cells.size)
    beta = np.empty(cells.size)
    # the controller solves one departure state at a time (its batch is over targets)
    with torch_threads(runner.settings.torch_threads):
        for k in range(cells.size):
            choice = allowed[cells[k]].copy()
            choice[acts[k]] = True
            ids = np.flatnonzero(choice)
            d = env.controller.decide(
                pos[k], vel[k], ids, grid.target_centres[cells[k], ids], int(acts[k])
            )
            ex[k], alpha[k], beta[k] = d.executed, d.alpha, d.beta
            if progress is not None:
                progress(1)
    return ex, alpha, beta


def _simulate(
    env: HopperGridEnv,
    rng: np.random.Generator,
    pos: np.ndarray,
    vel: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    energy: float,
) -> BatchHopResult:
    """The hops from ``(pos, vel)`` at the touchdown angles ``(alpha, beta)`` in MuJoCo, with
    the world's terrain, fresh landing noise and the stance thrust regulated to ``energy``."""
    nu = sample_model_noise(env.model, rng, len(pos))
    return simulate_hops(
        env.model,
        vel,
        alpha,
        beta,
        pos=pos,
        terrain=env.terrain,
        noise=nu,
        thrust=True,
        nominal_energy=energy,
    )


def audit_intervals(
    runner: NavigationRunner,
    data: RunData,
    pairs: np.ndarray,
    *,
    samples: int = 200,
    rng: np.random.Generator,
    attempts: int = 4,
    confidence: float = 0.99,
    progress: Callable[[int], None] | None = None,
) -> SampledAudit:
    """Audit the intervals learned from ``data`` on ``pairs`` ((P, 2) distinct cell, action
    ids), sampling as the loop does (module docstring); ``attempts``: the cap on each pair's
    own requests, in multiples of ``samples``; ``progress`` gets the number of controller
    decisions made."""
    env, grid = runner.env, runner.grid
    pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
    if samples < 1 or attempts < 1:
        raise ValueError(f"samples and attempts must be >= 1, got {samples}, {attempts}")
    pair_index = _pair_index(grid, pairs)
    n_pairs = len(pairs)
    res = _resynthesise(runner, data)
    allowed = loop_allowed_actions(res, grid, runner.scenario.p_sat)
    energy = nominal_energy(env.model, env.controller.steady.speed)

    executed = np.zeros(n_pairs, dtype=np.int64)
    requests = np.zeros(n_pairs, dtype=np.int64)
    as_requested = np.zeros(n_pairs, dtype=np.int64)
    counts = np.zeros((n_pairs, grid.n_states), dtype=np.int64)
    failures = hops = decisions = 0
    cap = attempts * samples
    while True:
        n_req = np.where(executed < samples, np.minimum(samples - executed, cap - requests), 0)
        if not (n_req > 0).any():
            break
        req_pair = np.repeat(np.arange(n_pairs), n_req)
        requests += n_req
        cells, acts = pairs[req_pair, 0], pairs[req_pair, 1]
        i, j = grid.cell_ij(cells)
        pos = (np.stack([i, j], axis=1) + rng.random((cells.size, 2))) * grid.cell
        vel = data.velocities[rng.integers(len(data.velocities), size=cells.size)]
        ex, alpha, beta = _decide(runner, allowed, pos, vel, cells, acts, progress)
        decisions += cells.size
        as_requested += np.bincount(req_pair[ex == acts], minlength=n_pairs)
        ex_pair = pair_index[cells, ex]
        keep = _first_k(ex_pair, samples - executed)
        if not keep.any():
            continue
        out = _simulate(env, rng, pos[keep], vel[keep], alpha[keep], beta[keep], energy)
        hops += int(keep.sum())
        failures += int((~out.ok).sum())
        pid = ex_pair[keep][out.ok]
        np.add.at(counts, (pid, grid.locate(out.next_pos[out.ok])), 1)
        executed += np.bincount(pid, minlength=n_pairs)

    def sub_audit(mask: np.ndarray) -> AuditResult | None:
        if not mask.any():
            return None
        return audit(
            res.intervals, pairs[mask, 0], pairs[mask, 1], counts[mask], confidence=confidence
        )

    full = executed >= samples
    return SampledAudit(
        result=sub_audit(full),
        partial=sub_audit(~full & (executed > 0)),
        executed=executed,
        requests=requests,
        as_requested=as_requested,
        counts=counts,
        failures=failures,
        hops=hops,
        decisions=decisions,
        samples=samples,
        intervals=res.intervals,
    )


def excluded_landings(audit_: SampledAudit, pairs: np.ndarray) -> np.ndarray:
    """``(K, 5)`` rows ``(cell, action, successor, count, executed)``: the landings of
    ``pairs`` (the audited pairs, in order) in successors whose interval upper bound is 0 (no
    interval row, or an upper bound of 0), with the pair's executed hops, most frequent
    (``count / executed``) first."""
    ti = audit_.intervals
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    upper = np.zeros(audit_.counts.shape)
    n_actions = int(max(ti.action.max(initial=0), pairs[:, 1].max(initial=0))) + 1
    code = pairs[:, 0] * n_actions + pairs[:, 1]
    order = np.argsort(code)
    row_code = ti.state * n_actions + ti.action
    pos = np.minimum(np.searchsorted(code[order], row_code), max(len(code) - 1, 0))
    hit = (len(code) > 0) & (code[order][pos] == row_code)
    upper[order[pos[hit]], ti.successor[hit]] = ti.upper[hit]
    r, c = np.nonzero((audit_.counts > 0) & (upper <= 0.0))
    n = audit_.executed[r]
    out = np.stack([pairs[r, 0], pairs[r, 1], c, audit_.counts[r, c], n], axis=1)
    return out[np.argsort(-audit_.counts[r, c] / np.maximum(n, 1), kind="stable")]
