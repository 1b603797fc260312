"""The exploration and goal-reaching policies and the switch between them.

Both phases mix an LTL action and an RL (reward) action, drawn *only* from the allowed actions
of a sub-model, so that no mix of the two trades away safety:

* **Exploration** (before the switch): the allowed actions are those of the *nonviolating*
  sub-model; the LTL action steers towards the chosen MEC and, inside it, follows a
  :class:`~planner.tour.ComponentTour` when one is installed (it keeps moving through the
  component; it needs the run's history, which the policy keeps: the step at which each state
  was last visited); the RL action (from an :class:`RLActor`, e.g. robust Q-values) is taken
  with probability ``P_RL,ee``.
* **Goal reaching** (after the switch): the allowed actions are those of the *satisfying*
  sub-model; the LTL action comes from the goal-reaching strategy; the RL action is taken with
  probability ``P_RL,gr = C exp(-eps m)``, ``m`` the number of steps taken in this phase
  (0 at the first goal-reaching step).

Switch: at a decision in state ``q``, exploration turns into goal reaching as soon as the
worst-case satisfaction probability of ``q`` *exceeds* ``P_sat`` and the satisfying sub-model
allows an action in ``q``. That probability, ``p_switch``, is a statement about the IMDP and
the goal-reaching plan *of that synthesis*; so, by default
(``SwitchingConfig.keep_goal_plan``), the goal-reaching plan of the switch is kept for the
rest of the run: later re-syntheses replace the exploration and fallback plans and the
satisfaction probabilities used for the next switch, but not the plan being followed, so the
run is held to the guarantee it reported. The phase stays goal reaching while the current state
has an allowed action in that plan (the switch's satisfying sub-model). If the robot lands in a
state outside it (possible: the satisfying sub-model keeps every action whose worst-case value
exceeds ``P_sat``, not only the optimal one, and the real system may fall outside the
intervals), the policy *leaves the plan*: it records the step
(:attr:`SwitchingPolicy.left_plan_step`, which a runner must report), returns to exploration
with the latest plans and may switch again under the same rule (with a new plan;
``switch_step`` and ``p_switch`` stay those of the first switch). With
``keep_goal_plan=False`` every re-synthesis replaces the goal plan too (the guarantee then
refers to a model that changes under the run), and the policy returns to exploration where
the latest plan has no action.

What ``p_switch`` promises: following the kept plan's LTL action from the switch state
satisfies the formula with probability at least ``p_switch`` under every adversary of the
switch's IMDP (and so on the real system if its intervals are sound). The goal-reaching policy
also takes RL actions (probability ``C exp(-eps m)``), only among actions whose worst-case value
under that IMDP exceeds ``P_sat``; an RL action can thus lower the guarantee towards ``P_sat``,
and a run that then lands outside the satisfying sub-model is the case reported by
``left_plan_step``. The promise has no time bound: a runner's step cap may still end a run
that follows the plan (a timeout).

Fallback: where the nonviolating sub-model allows no action in the current state (typically at
the start, when the prior's wide intervals let every hop possibly leave the world or reach a
hazard), no action is safe by the abstraction's standard. If a fallback plan is installed
(e.g. all enabled actions, with the action that maximises the worst-case satisfaction
probability as its LTL action), the policy takes its LTL action (its RL action where it has
none) and reports the phase ``"fallback"``; without one it raises :class:`PolicyError`.

An LTL strategy entry of -1 (no LTL preference, e.g. a state the strategy treats as reached)
makes the policy take the RL action, reported with source ``"RL"``.

Ties: the RL actor is given the LTL action as its preference, so where the reward is
indifferent between the best actions (e.g. robust Q-values that are all 0 under wide
intervals) the RL action is the LTL action instead of the lowest-index one; its other ties,
and the tour's, are drawn from the caller's generator.

Randomness: every decision draws one uniform number from the caller's generator for the
LTL/RL choice (always, so the stream does not depend on the probabilities); then the tour (on
a tie) and the RL actor (when it acts: epsilon-greedy, ties) may draw more; the same generator
state gives the same decisions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from planner.errors import PolicyError
from planner.modes import Phase, Source
from planner.tour import ComponentTour


class RLActor(Protocol):
    """Chooses a reward-seeking action among ``allowed`` (``(n_actions,)`` boolean mask);
    ``prefer`` (the LTL action, -1 for none) is the action to take among equally good ones."""

    def act(
        self, state: int, allowed: np.ndarray, rng: np.random.Generator, prefer: int = -1
    ) -> int: ...


@dataclass(frozen=True)
class PhasePlan:
    """What one phase needs from a synthesis.

    Attributes:
        allowed: ``(n_states, n_actions)`` boolean mask of the sub-model's allowed actions.
        ltl_action: ``(n_states,)`` the LTL strategy's action per state (-1: none).
    """

    allowed: np.ndarray
    ltl_action: np.ndarray

    @classmethod
    def masked(cls, allowed: np.ndarray, strategy: np.ndarray) -> PhasePlan:
        """A plan from a strategy that may name actions outside ``allowed``: those entries
        become -1 (no LTL preference), so the RL action is taken there."""
        allowed = np.asarray(allowed, dtype=bool)
        strategy = np.asarray(strategy, dtype=np.int64)
        if allowed.ndim != 2 or strategy.shape != (allowed.shape[0],):
            raise PolicyError(
                f"strategy of shape {strategy.shape} does not fit allowed {allowed.shape}"
            )
        ok = (strategy >= 0) & (strategy < allowed.shape[1])
        idx = np.flatnonzero(ok)
        ok[idx] = allowed[idx, strategy[idx]]
        return cls(allowed, np.where(ok, strategy, -1))

    def __post_init__(self) -> None:
        allowed = np.asarray(self.allowed)
        ltl = np.asarray(self.ltl_action)
        if allowed.ndim != 2 or allowed.dtype != bool:
            raise PolicyError(f"allowed must be a 2-D boolean mask, got {allowed.dtype}")
        if ltl.shape != (allowed.shape[0],) or ltl.dtype.kind not in "iu":
            raise PolicyError(f"ltl_action must be integers of shape ({allowed.shape[0]},)")
        if ((ltl < -1) | (ltl >= allowed.shape[1])).any():
            raise PolicyError(f"ltl_action values must lie in [-1, {allowed.shape[1]})")
        has = ltl >= 0
        bad = np.flatnonzero(has & ~allowed[np.arange(ltl.size), np.where(has, ltl, 0)])
        if bad.size:
            s = int(bad[0])
            raise PolicyError(
                f"state {s}: LTL action {int(ltl[s])} is not among the allowed actions "
                f"{np.flatnonzero(allowed[s]).tolist()}"
            )


@dataclass(frozen=True)
class Decision:
    """One decision: the action, where it came from and what else was allowed.

    Attributes:
        action: the chosen action.
        phase: ``"exploration"``, ``"goal_reaching"`` or ``"fallback"``.
        source: ``"LTL"`` or ``"RL"``.
        allowed: the allowed actions in this state (the backup controller picks among them).
        p_rl: the probability with which the RL action was to be taken.
        phase_step: ``m``, the number of earlier steps in the current phase.
        sat_probability: worst-case satisfaction probability of the state (in goal reaching:
            under the synthesis of the plan in use).
        switched: this decision switched the phase or the plan (to goal reaching, back, or
            out of a plan it left into a new one).
    """

    action: int
    phase: Phase
    source: Source
    allowed: tuple[int, ...]
    p_rl: float
    phase_step: int
    sat_probability: float
    switched: bool


def _check_prob(name: str, value: float) -> None:
    if not 0.0 <= value <= 1.0:
        raise PolicyError(f"{name} must lie in [0, 1], got {value}")


def _mix(
    plan: PhasePlan,
    rl: RLActor,
    state: int,
    p_rl: float,
    rng: np.random.Generator,
    tour: ComponentTour | None = None,
    last_visit: np.ndarray | None = None,
) -> tuple[int, Source, np.ndarray]:
    allowed = np.asarray(plan.allowed[state], dtype=bool)
    if not allowed.any():
        raise PolicyError(f"state {state} has no allowed action in this phase's sub-model")
    u = rng.random()
    ltl = int(plan.ltl_action[state])
    if tour is not None and last_visit is not None and tour.covers(state):
        ltl = tour.action(state, last_visit, rng)
        if ltl >= 0 and not allowed[ltl]:
            raise PolicyError(f"state {state}: the tour chose action {ltl}, not allowed")
    if u < p_rl or ltl < 0:
        action = int(rl.act(state, allowed, rng, prefer=ltl))
        if not allowed[action]:
            raise PolicyError(f"state {state}: the RL actor chose action {action}, not allowed")
        return action, Source.RL, allowed
    return ltl, Source.LTL, allowed


class ExplorationPolicy:
    """LTL action towards the chosen MEC (inside it the ``tour``'s, if given), RL action with
    probability ``p_rl``."""

    def __init__(
        self, plan: PhasePlan, rl: RLActor, p_rl: float, tour: ComponentTour | None = None
    ) -> None:
        _check_prob("P_RL,ee", p_rl)
        self.plan, self.rl, self.p_rl, self.tour = plan, rl, float(p_rl), tour

    def choose(
        self, state: int, rng: np.random.Generator, last_visit: np.ndarray | None = None
    ) -> tuple[int, Source, np.ndarray]:
        """``(action, source, allowed mask)`` in ``state``; ``last_visit`` (per state, -1:
        never) feeds the tour."""
        return _mix(self.plan, self.rl, state, self.p_rl, rng, self.tour, last_visit)


class GoalReachingPolicy:
    """LTL goal-reaching action, RL action with probability ``C exp(-eps m)``."""

    def __init__(self, plan: PhasePlan, rl: RLActor, c: float, eps: float) -> None:
        _check_prob("C", c)
        _check_prob("eps", eps)
        self.plan, self.rl, self.c, self.eps = plan, rl, float(c), float(eps)

    def p_rl(self, m: int) -> float:
        """``P_RL,gr = C exp(-eps m)``."""
        return self.c * float(np.exp(-self.eps * m))

    def choose(
        self, state: int, m: int, rng: np.random.Generator
    ) -> tuple[int, Source, np.ndarray]:
        return _mix(self.plan, self.rl, state, self.p_rl(m), rng)


@dataclass(frozen=True)
class SwitchingConfig:
    """``p_rl_explore`` = P_RL,ee; ``c``, ``eps`` of P_RL,gr = C exp(-eps m); ``p_sat``;
    ``keep_goal_plan``: follow the goal-reaching plan of the switch until the state leaves it
    (default) instead of the latest re-synthesis's (see the module docstring)."""

    p_rl_explore: float = 0.5
    c: float = 0.5
    eps: float = 0.005
    p_sat: float = 0.65
    keep_goal_plan: bool = True

    def __post_init__(self) -> None:
        for name in ("p_rl_explore", "c", "eps", "p_sat"):
            _check_prob(name, float(getattr(self, name)))


class SwitchingPolicy:
    """Exploration until the worst-case satisfaction probability exceeds ``p_sat``, then goal
    reaching (see the module docstring). Call :meth:`resynthesise` after every re-synthesis
    and :meth:`decide` once per hop.
    """

    def __init__(self, settings: SwitchingConfig, rl: RLActor | None = None) -> None:
        self.settings = settings
        self.rl = rl
        self.exploration: ExplorationPolicy | None = None
        self.goal: GoalReachingPolicy | None = None
        self.latest_goal: GoalReachingPolicy | None = None
        self.fallback: ExplorationPolicy | None = None
        self.sat_probability: np.ndarray | None = None
        self.goal_sat_probability: np.ndarray | None = None
        self.last_visit: np.ndarray | None = None
        """``(n_states,)`` step of this run's last decision in each state (-1: none yet)."""
        self.reset()

    def reset(self) -> None:
        """Start a new run: exploration phase, no steps taken, no states visited, the latest
        plans in use."""
        if self.last_visit is not None:
            self.last_visit[:] = -1
        self.phase = Phase.EXPLORATION
        self.phase_step = 0
        self.step = 0
        self.switch_step: int | None = None
        self.switch_probability: float | None = None
        self.left_plan_step: int | None = None
        self.switches = 0
        self.goal = self.latest_goal
        self.goal_sat_probability = self.sat_probability

    @property
    def following_switch_plan(self) -> bool:
        """Whether the goal-reaching plan in use is kept from a switch (not replaced)."""
        return self.phase == Phase.GOAL_REACHING and self.settings.keep_goal_plan

    def resynthesise(
        self,
        exploration: PhasePlan,
        goal: PhasePlan,
        sat_probability: np.ndarray,
        fallback: PhasePlan | None = None,
        rl: RLActor | None = None,
        tour: ComponentTour | None = None,
    ) -> None:
        """Install the plans of a new synthesis (phase and step counters are kept); ``rl``
        replaces the RL actor when given; ``tour`` is the exploration's in-component tour
        (none: the exploration plan's LTL action everywhere). In goal reaching with
        ``keep_goal_plan`` the goal-reaching plan of the switch stays in use (the new one is
        kept for later)."""
        if rl is not None:
            self.rl = rl
        if self.rl is None:
            raise PolicyError("no RL actor: pass rl here or to the constructor")
        sat = np.asarray(sat_probability, dtype=np.float64)
        shape = np.asarray(exploration.allowed).shape
        shapes = [np.asarray(p.allowed).shape for p in (goal, fallback) if p is not None]
        if any(sh != shape for sh in shapes) or sat.shape != (shape[0],):
            raise PolicyError(
                f"plans and sat_probability disagree in shape: {shape}, {shapes}, {sat.shape}"
            )
        # value iteration may overshoot [0, 1] by rounding (sums of interval products)
        if not np.isfinite(sat).all() or (sat < -1e-9).any() or (sat > 1 + 1e-9).any():
            raise PolicyError("sat_probability must lie in [0, 1]")
        sat = np.clip(sat, 0.0, 1.0)
        s = self.settings
        if self.last_visit is None or self.last_visit.shape != (shape[0],):
            self.last_visit = np.full(shape[0], -1, dtype=np.int64)
        self.exploration = ExplorationPolicy(exploration, self.rl, s.p_rl_explore, tour)
        self.latest_goal = GoalReachingPolicy(goal, self.rl, s.c, s.eps)
        self.fallback = None if fallback is None else ExplorationPolicy(fallback, self.rl, 0.0)
        self.sat_probability = sat
        if not self.following_switch_plan:
            self.goal, self.goal_sat_probability = self.latest_goal, sat
        elif self.goal is not None:
            # the kept plan acts with the current RL actor (its allowed actions are the plan's)
            self.goal = GoalReachingPolicy(self.goal.plan, self.rl, s.c, s.eps)

    def replan_reward(self, rl: RLActor, tour: ComponentTour | None = None) -> None:
        """Replace the RL actor of every plan in use (e.g. re-solved after a reward was
        collected), and the exploration's tour when ``tour`` is given; plans, phase and the
        guarantee are unchanged."""
        if self.exploration is None or self.latest_goal is None:
            raise PolicyError("replan_reward called before resynthesise")
        self.rl = rl
        ex = self.exploration
        self.exploration = ExplorationPolicy(ex.plan, rl, ex.p_rl, tour or ex.tour)
        for name in ("goal", "latest_goal"):
            g = getattr(self, name)
            if g is not None:
                setattr(self, name, GoalReachingPolicy(g.plan, rl, g.c, g.eps))
        if self.fallback is not None:
            self.fallback = ExplorationPolicy(self.fallback.plan, rl, 0.0)

    def decide(self, state: int, rng: np.random.Generator) -> Decision:
        """Choose the action in (product) state ``state``."""
        if (
            self.exploration is None
            or self.goal is None
            or self.latest_goal is None
            or self.sat_probability is None
            or self.goal_sat_probability is None
        ):
            raise PolicyError("decide called before resynthesise")
        if not 0 <= state < self.sat_probability.size:
            raise PolicyError(f"state {state} is not in [0, {self.sat_probability.size})")
        switched = False
        left = not np.asarray(self.goal.plan.allowed[state]).any()
        if self.phase == Phase.GOAL_REACHING and left:
            # the state left the goal-reaching plan in use: back to exploration, latest plans
            self.phase, self.phase_step, switched = Phase.EXPLORATION, 0, True
            if self.settings.keep_goal_plan and self.left_plan_step is None:
                self.left_plan_step = self.step
            self.goal, self.goal_sat_probability = self.latest_goal, self.sat_probability
        sat = float(self.sat_probability[state])
        goal_ok = bool(np.asarray(self.latest_goal.plan.allowed[state]).any())
        if self.phase == Phase.EXPLORATION and sat > self.settings.p_sat and goal_ok:
            self.phase, self.phase_step, switched = Phase.GOAL_REACHING, 0, True
            self.goal, self.goal_sat_probability = self.latest_goal, self.sat_probability
            self.switches += 1
            if self.switch_step is None:
                self.switch_step, self.switch_probability = self.step, sat
        if self.phase == Phase.GOAL_REACHING:
            sat = float(self.goal_sat_probability[state])
        explore_ok = bool(np.asarray(self.exploration.plan.allowed[state]).any())
        phase = self.phase
        if self.phase == Phase.GOAL_REACHING:
            p_rl = self.goal.p_rl(self.phase_step)
            action, source, allowed = self.goal.choose(state, self.phase_step, rng)
        elif not explore_ok and self.fallback is not None:
            phase, p_rl = Phase.FALLBACK, 0.0
            action, source, allowed = self.fallback.choose(state, rng)
        else:
            p_rl = self.exploration.p_rl
            action, source, allowed = self.exploration.choose(state, rng, self.last_visit)
        decision = Decision(
            action=action,
            phase=phase,
            source=source,
            allowed=tuple(int(a) for a in np.flatnonzero(allowed)),
            p_rl=p_rl,
            phase_step=self.phase_step,
            sat_probability=sat,
            switched=switched,
        )
        if self.last_visit is not None:
            self.last_visit[state] = self.step
        self.phase_step += 1
        self.step += 1
        return decision
