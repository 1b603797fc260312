"""The navigation loop: plan on the learned interval abstraction, hop in MuJoCo, learn, repeat.

One run (the paper's "Synthesis Approach", docs/design.md "Rewards and policies"):

1. The landing-error GPs start empty (their prior alone sets wide intervals); the grid IMDP,
   the MT-PIMDP with the automaton of the scenario's formula and the reward, and the policies
   are synthesised (:func:`planner.learning.resynthesise`).
2. Every hop, the :class:`~planner.policy.SwitchingPolicy` picks an action in the current
   product state (exploration: towards the chosen MEC and through it, see
   :mod:`planner.tour`; or goal reaching; LTL or RL, only among the allowed actions of the
   nonviolating or satisfying sub-model); the environment
   (:class:`~hopper_sim.navigation.environment.HopperGridEnv`) turns it into touchdown angles (with
   the
   controller's backup switch among the same allowed actions) and hops in MuJoCo with the
   terrain field, noise and thrust; the departure position and the landing error
   ``landing - target`` (relative to the executed action's target) and the executed action
   are recorded for the landing-error model; the automaton reads the label of the cell
   landed in; the reward is paid as the scenario's ``collect`` says. Where cells pay once, a
   first landing in a cell with a (known or believed) nonzero reward re-solves the reward plan
   with that cell at 0 (:func:`planner.learning.replan_reward`, timed as ``replan``).
3. After every ``batch_size`` hops the landing-error model (its prior derived from the
   scene, :func:`hopper_sim.controller.error_prior.error_prior`) is refitted on all data of the run
   and the
   abstraction and policies re-synthesised. After the switch to goal reaching the data are
   still recorded and the model re-synthesised, but the goal-reaching plan of the switch is
   kept (:class:`~planner.policy.SwitchingPolicy`, ``keep_goal_plan``): the reported
   ``p_switch`` is the worst-case satisfaction probability of that plan on the IMDP of the
   switch, and the run is held to it. Only if the robot lands in a product state outside that
   plan's satisfying sub-model does it leave the plan (back to exploration with the latest
   synthesis, which may switch again); :attr:`~hopper_sim.navigation.events.RunEnd.left_plan_step`
   reports when.
4. The automaton decides the outcome (:func:`hopper_sim.navigation.episode.hop_outcome` on the
product
   state entered, :class:`planner.verdict.MissionMonitor` at the step cap; one rule for
   every class of formula): the run ends in success as soon as every hazard-free continuation
   satisfies the formula (for ``!Haz U Goal``: the goal; for ``F(a & F goal) & G !haz``: the
   goal after ``a``), in violation as soon as none does, on a hazard cell, off the map, or
   when a hop fails (the hopper fell). At ``max_steps`` hops a run whose formula is still
   open (recurrence such as ``GF a``, persistence, safety on a non-hazard label) ends
   ``"satisfying"`` if its last window repeated forever satisfies the formula (the report
   gives the Rabin ``G`` visits in that window and whether the run is in an accepting end
   component), else in a timeout.

With an unknown reward (``reward_known = false``) a :class:`~planner.qlearning.RobustQLearner`
learns the reward from visits and updates its Q-values online; it persists across the runs of
:meth:`NavigationRunner.run_many` (and can be saved and loaded), while the GP data is reset at
every run, as in the paper.

The loop (:meth:`NavigationRunner._run`) is a few lines, as dm_control's ``Environment.step``:
decide, hop, land; the hooks ``_begin``, ``_land`` (with ``_learn`` and ``_replan``) and
``_finish`` do the work on the run's :class:`~hopper_sim.navigation.episode.Episode`. The runner
never
prints or plots: it calls an observer (:mod:`hopper_sim.navigation.events`), with events built by
their
own constructors.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from hopper_sim.controller.error_prior import error_prior
from hopper_sim.navigation.config import NavigationConfig
from hopper_sim.navigation.environment import HopperGridEnv
from hopper_sim.navigation.episode import Episode, RunClock, hop_outcome
from hopper_sim.navigation.events import (
    HopEvent,
    Observer,
    ResynthesisRecord,
    RunEnd,
    RunStart,
    SynthesisEvent,
)
from planner._util.torch_threads import torch_threads
from planner.gp.landing import LandingErrorGP
from planner.imdp.analysis import accepting_states
from planner.imdp.grid import ACTIONS
from planner.imdp.product import base_states, check_product_size
from planner.intervals import TruncatedGaussianNoise
from planner.learning import Resynthesis, replan_reward, resynthesise
from planner.ltl.translate import translate
from planner.modes import Outcome
from planner.policy import Decision, SwitchingPolicy
from planner.qlearning import RobustQLearner
from planner.scenario import Scenario
from planner.verdict import AutomatonVerdicts, MissionMonitor, describe


class NavigationRunner:
    """Runs navigation episodes of a scenario (see the module docstring).

    Args:
        scenario: the world and tasks.
        env: the environment (default: built from ``scenario`` and ``settings.env``; a given
            one must have ``settings.env``, and its settings are the default's ``env``).
        settings: the run's configuration tree, complete (default:
            ``NavigationConfig.from_scenario(scenario)``, the shipped defaults with the
            scenario's ``[runner]`` table and ``p_sat``). Its ``run`` section and
            ``planner.switching.p_sat`` replace the scenario's ``[runner]`` table and ``p_sat``
            (:attr:`scenario` is the scenario as run), so build it from the scenario and
            ``override`` it to keep them.
        observer: receives every event (default: none).
        learner: an existing Q-learner to continue (unknown reward; default: a fresh one);
            it continues with ``settings.planner.q_learning``.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        env: HopperGridEnv | None = None,
        settings: NavigationConfig | None = None,
        observer: Observer | None = None,
        learner: RobustQLearner | None = None,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        if settings is None:
            base = None if env is None else NavigationConfig(env=env.settings)
            settings = NavigationConfig.from_scenario(scenario, base)
        elif env is not None and env.settings != settings.env:
            raise ValueError(
                f"the environment's settings {env.settings} differ from settings.env {settings.env}"
            )
        self.settings = settings
        # the scenario as run: its [runner] table and p_sat are the tree's
        self.scenario = scenario = self.settings.apply_to(scenario)
        self.env = env or HopperGridEnv(scenario, settings=self.settings.env)
        self.observer = observer or Observer()
        self.clock = clock
        self.grid = self.env.grid
        self.automaton = translate(scenario.formula)
        self.verdicts = AutomatonVerdicts(self.automaton, excluded=scenario.hazard)
        pp = self.env.model.perturbation
        noise = TruncatedGaussianNoise(pp.noise_sigma, pp.noise_bound)
        self.synthesis_settings = replace(self.settings.planner, noise=noise)
        self.switching = self.synthesis_settings.switching
        q_settings = self.synthesis_settings.q_learning
        nq = self.automaton.n_states
        n_product = self.grid.n_states * nq
        # before any hop: each enabled (cell, action) has a successor in every product
        check_product_size(self.grid.n_states, int(np.count_nonzero(self.grid.enabled)), nq)
        if scenario.reward_known:
            self.learner = None
        elif learner is not None:
            if learner.n_states != n_product:
                raise ValueError(
                    f"the Q-learner has {learner.n_states} states, this scenario's product "
                    f"{n_product}"
                )
            learner.settings = q_settings  # it continues with this run's settings
            self.learner = learner
        else:
            self.learner = RobustQLearner(
                n_product,
                len(ACTIONS),
                self.grid.n_states,
                state_cell=base_states(self.grid.n_states, nq),
                settings=q_settings,
            )
        prior = self.settings.gp_prior or error_prior(
            self.env.model,
            self.env.controller,
            terrain=self.env.settings.terrain,
            cell=scenario.world.cell,
        )
        self.gp_settings = replace(prior, **self.settings.gp)
        res = self.settings.map_resolution
        w = scenario.world
        self.map_x = (np.arange(w.nx * res) + 0.5) * (w.cell / res)
        self.map_y = (np.arange(w.ny * res) + 0.5) * (w.cell / res)

    # ------------------------------------------------------------------ synthesis
    @property
    def pays_once(self) -> bool:
        """Whether a cell pays its reward only on the first landing of a run."""
        return self.scenario.collect == "once"

    def _collected(self) -> np.ndarray | None:
        return self.env.collected.copy() if self.pays_once else None

    def _synthesise(
        self,
        gp: LandingErrorGP,
        positions: list[np.ndarray],
        errors: list[np.ndarray],
        actions: list[int],
        current: int | None,
        previous: Resynthesis | None = None,
    ) -> Resynthesis:
        pos = np.asarray(positions, dtype=float).reshape(-1, 2)
        err = np.asarray(errors, dtype=float).reshape(-1, 2)
        known = self.learner is None
        return resynthesise(
            gp,
            self.grid,
            self.automaton,
            pos,
            err,
            actions=np.asarray(actions, dtype=np.int64),
            reward=self.env.reward_table if known else None,
            learner=self.learner,
            initial_cell=self.scenario.start_cell,
            current_state=current,
            collected=self._collected() if known else None,
            settings=self.synthesis_settings,
            previous=previous,
            clock=self.clock,
        )

    def _replan_reward(self, res: Resynthesis) -> tuple:
        known = self.learner is None
        return replan_reward(
            res,
            reward=self.env.reward_table if known else None,
            learner=self.learner,
            collected=self._collected() if known else None,
            settings=self.synthesis_settings,
        )

    def _install(self, ep: Episode, res: Resynthesis, step: int) -> None:
        """Hand a (re-)synthesis after ``step`` hops to the policy and the observer."""
        ep.res = res
        ep.clock.add_synthesis(res.timings)
        ep.policy.resynthesise(
            res.exploration,
            res.goal,
            res.satisfaction.values,
            res.fallback,
            rl=res.rl,
            tour=res.tour,
        )
        record = ResynthesisRecord.of_synthesis(step, res, ep.pstate)
        ep.records.append(record)
        event = SynthesisEvent.of_model(
            ep.run_index, step, ep.gp, self.map_x, self.map_y, res.timings, record
        )
        self.observer.on_synthesis(event)

    # ------------------------------------------------------------------ runs
    def run(self, seed: int, run_index: int = 0) -> RunEnd:
        """One complete run; ``seed`` fixes the landing noise and every policy draw."""
        with torch_threads(self.settings.torch_threads):
            return self._run(seed, run_index)

    def _run(self, seed: int, run_index: int) -> RunEnd:
        """The loop: decide, hop, land; the hooks below do the work."""
        ep = self._begin(seed, run_index)
        while ep.outcome is None and ep.steps < self.scenario.runner.max_steps:
            decision = ep.policy.decide(ep.pstate, ep.rng)
            allowed = np.asarray(decision.allowed, dtype=int)
            with ep.clock.timed("hops"):
                obs, reward, terminated, _, info = self.env.step(decision.action, allowed=allowed)
            ep.outcome = self._land(ep, decision, obs, reward, terminated, info)
        return self._finish(ep)

    def _begin(self, seed: int, run_index: int) -> Episode:
        """Reset the world, the data and the learner's collections; the initial synthesis."""
        clock = RunClock(self.clock)
        # the third word seeded the old GP's k-means; kept so that a seed's draws stay the same
        env_seed, policy_seed, _ = np.random.SeedSequence(seed).generate_state(3)
        rng = np.random.default_rng(policy_seed)
        self.observer.on_run_start(RunStart(run_index, self.scenario, int(seed)))
        obs, _ = self.env.reset(seed=int(env_seed))
        if self.learner is not None:
            self.learner.collected[:] = False
        gp = LandingErrorGP(self.gp_settings)
        res = self._synthesise(gp, [], [], [], None)
        product = res.product
        pstate = product.entry_state(obs["cell"])
        policy = SwitchingPolicy(self.switching, res.rl)
        monitor = MissionMonitor(self.verdicts, self.scenario.runner.window)
        ep = Episode(run_index, rng, gp, clock, res, policy, pstate, monitor)
        self._install(ep, res, 0)
        monitor.start(product.automaton_state_of(pstate))
        ep.outcome = hop_outcome(product, self.verdicts, pstate, start=True)
        return ep

    def _land(
        self,
        ep: Episode,
        decision: Decision,
        obs: dict,
        reward: float,
        terminated: bool,
        info: dict,
    ) -> tuple[Outcome, str] | None:
        """After a hop: record its data, learn, report it, follow the automaton; the
        outcome if the run ends here, else re-plan as due."""
        si = info["step"]
        ep.steps += 1
        ep.backups += int(si.decision.backup_used)
        if not si.hop.ok:
            return Outcome.VIOLATION, f"hop failed: {si.hop.status}"
        ep.positions.append(si.start_pos)
        ep.errors.append(si.error)
        ep.actions.append(int(si.decision.executed))
        landed = int(obs["cell"])
        first = bool(info.get("first_landing", False))
        product = ep.res.product
        nxt = product.step(ep.pstate, landed)
        # the plan values a cell by what it still pays: a first landing in a cell with a
        # (known or believed) nonzero reward changes the reward plan where cells pay once
        believed = (
            self.env.reward_table[landed]
            if self.learner is None
            else self.learner.cell_reward()[landed]
        )
        ep.collections += int(first and self.env.reward_table[landed] != 0.0)
        self._learn(ep, int(si.decision.executed), landed, nxt, reward, first)
        ep.total += reward
        p_worst = float(ep.res.satisfaction.values[nxt])
        event = HopEvent.of_hop(
            ep.run_index,
            ep.steps - 1,
            decision,
            si,
            obs["pos"],
            landed,
            product_state=nxt,
            p_worst=p_worst,
            reward=reward,
            total_reward=ep.total,
        )
        self.observer.on_hop(event)
        ep.pstate = nxt
        ep.monitor.step(product.letter_of(nxt), product.automaton_state_of(nxt))
        outcome = hop_outcome(product, self.verdicts, nxt, terminated=terminated, out=self.grid.out)
        if outcome is None:
            self._replan(ep, paid_cell=first and believed != 0.0)
        return outcome

    def _learn(
        self, ep: Episode, action: int, landed: int, nxt: int, reward: float, first: bool
    ) -> None:
        """An unknown reward's learner: the landing's collection and its Q-update."""
        if self.learner is None:
            return
        if self.pays_once:
            self.learner.collected[landed] = True
        self.learner.update(
            ep.res.product.model,
            ep.pstate,
            action,
            nxt,
            reward,
            allowed=ep.res.q_allowed,
            learn_reward=first or not self.pays_once,
        )

    def _replan(self, ep: Episode, paid_cell: bool) -> None:
        """After a full batch the re-synthesis; else, after a first landing in a cell with a
        nonzero reward where cells pay once, the reward plan."""
        if ep.steps % self.scenario.runner.batch_size == 0:
            res = self._synthesise(ep.gp, ep.positions, ep.errors, ep.actions, ep.pstate, ep.res)
            self._install(ep, res, ep.steps)
        elif self.pays_once and paid_cell:
            with ep.clock.timed("replan"):
                q_sol, rl, tour = self._replan_reward(ep.res)
                ep.res = replace(ep.res, q=q_sol, rl=rl, tour=tour)
                ep.policy.replan_reward(rl, tour)

    def _finish(self, ep: Episode) -> RunEnd:
        """Judge the run (at the step cap: its last window) and report its end."""
        in_accepting = bool(accepting_states(ep.res.product)[ep.pstate])
        mission = ep.monitor.report(in_accepting)
        outcome, reason = ep.outcome or describe(mission)
        policy = ep.policy
        end = RunEnd(
            run_index=ep.run_index,
            outcome=outcome,
            steps=ep.steps,
            reward=ep.total,
            switch_step=policy.switch_step,
            p_switch=policy.switch_probability,
            backups=ep.backups,
            seconds=ep.clock.elapsed(),
            timings=ep.clock.report(),
            reason=reason,
            left_plan_step=policy.left_plan_step,
            resyntheses=tuple(ep.records),
            collections=ep.collections,
            mission=mission,
        )
        self.observer.on_run_end(end)
        return end

    def run_many(self, runs: int | None = None, seed: int | None = None) -> list[RunEnd]:
        """``runs`` consecutive runs (default: the scenario's) with seeds ``seed + k``
        (default seed: the scenario's); an unknown reward's Q-learner carries over."""
        rp = self.scenario.runner
        n = rp.runs if runs is None else int(runs)
        base = rp.seed if seed is None else int(seed)
        return [self.run(base + k, run_index=k) for k in range(n)]


def run_single(
    scenario: Scenario, seed: int, run_index: int = 0, overrides: dict | None = None
) -> RunEnd:
    """One run of ``scenario`` with its settings (``overrides``: changes by key, as text,
    :meth:`~hopper_sim.navigation.config.NavigationConfig.override`) and no observer
    (picklable, also as a :func:`functools.partial`, for worker processes)."""
    settings = NavigationConfig.from_scenario(scenario)
    if overrides:
        settings = settings.override(overrides, text=True, source="--set")
    return NavigationRunner(scenario, settings=settings).run(seed, run_index=run_index)
