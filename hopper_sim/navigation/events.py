"""Events a navigation run emits, and the observer contract that receives them.

The runner never logs, prints or plots: it calls an :class:`Observer` (or several, through
:class:`Observers`) at four points of each run, passing one of the dataclasses below. All
positions are in world metres (origin at the world's lower-left corner, z up), all times in
seconds, all probabilities in [0, 1], cells are flat indices ``i * ny + j`` (``nx * ny`` is
the absorbing ``out`` state). Arrays are numpy ``float64``; an observer must not modify them.

Order of calls for one run: ``on_run_start``, then ``on_synthesis`` for the initial synthesis
(``step = 0``), then ``on_hop`` for every hop, with ``on_synthesis`` after each batch refit,
and finally ``on_run_end``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, fields
from enum import Enum
from typing import TYPE_CHECKING, Protocol, TypeVar, runtime_checkable

import numpy as np

from hopper_sim.errors import HopperSimError
from planner.modes import Outcome, Phase, Source

if TYPE_CHECKING:
    from hopper_sim.navigation.environment import StepInfo
    from planner.gp.landing import LandingErrorGP
    from planner.learning import Resynthesis
    from planner.policy import Decision
    from planner.scenario import Scenario
    from planner.verdict import MissionReport


PHASES: tuple[str, ...] = tuple(m.value for m in Phase)
SOURCES: tuple[str, ...] = tuple(m.value for m in Source)
OUTCOMES: tuple[str, ...] = tuple(m.value for m in Outcome)
"""The modes' strings in order (:mod:`planner.modes`), for tables and file formats."""

_M = TypeVar("_M", bound=Enum)


class EventError(HopperSimError, ValueError):
    """An event was built with a bad field (unknown phase, wrong array shape...)."""


def _mode(name: str, value: str, modes: type[_M]) -> _M:
    try:
        return modes(value)
    except ValueError:
        allowed = tuple(m.value for m in modes)
        raise EventError(f"{name} must be one of {allowed}, got {value!r}") from None


def _as_array(name: str, value: object, shape: tuple[int | None, ...]) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as err:
        raise EventError(f"{name} must be numeric, got {value!r}") from err
    arr.flags.writeable = False
    if arr.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(arr.shape, shape, strict=True)
    ):
        want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
        raise EventError(f"{name} must have shape {want}, got {arr.shape}")
    return arr


@dataclass(frozen=True)
class RunStart:
    """A run begins.

    Attributes:
        run_index: 0-based index of the run within the invocation.
        scenario: the scenario being run (with the runner settings actually used).
        seed: the seed of this run's random generator.
    """

    run_index: int
    scenario: Scenario
    seed: int


@dataclass(frozen=True)
class HopEvent:
    """One hop, from an interstitial state to the next.

    Attributes:
        run_index: the run.
        step: 0-based hop number within the run.
        phase: ``"exploration"``, ``"goal_reaching"`` or ``"fallback"`` (no nonviolating
            action in the current state: the action maximising worst-case satisfaction).
        source: which policy chose the requested action, ``"LTL"`` or ``"RL"``.
        backup: whether the low-level backup switch replaced the requested action.
        requested_action: the action the policy chose (``"N1"``.. ``"W2"``).
        executed_action: the action executed (differs from the request on a backup).
        start_pos: CoM ``(x, y)`` at the departure interstitial state, m.
        target: centre ``(x, y)`` of the executed action's target cell, m.
        landing: CoM ``(x, y)`` at the next interstitial state, m.
        com_path: ``(T, 3)`` CoM positions from departure to the next interstitial state, m.
        foot: ``(3,)`` foot position at touchdown, m.
        touchdown_time: time of the touchdown since the hop's departure interstitial state, s.
        cell: flat index of the landing cell (``nx * ny`` for ``out``).
        product_state: index of the product (IMDP x automaton) state after the hop.
        p_worst: worst-case satisfaction probability of that product state.
        reward: reward collected by this hop.
        total_reward: reward collected in the run so far, this hop included.
        com_time: optional ``(T,)`` times of the ``com_path`` samples since the hop's
            departure, s (the last one ends the hop); recorders offset them by the hop's
            start to animate the CoM along ``sim_time``.
    """

    run_index: int
    step: int
    phase: Phase
    source: Source
    backup: bool
    requested_action: str
    executed_action: str
    start_pos: np.ndarray
    target: np.ndarray
    landing: np.ndarray
    com_path: np.ndarray
    foot: np.ndarray
    touchdown_time: float
    cell: int
    product_state: int
    p_worst: float
    reward: float
    total_reward: float
    com_time: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "phase", _mode("phase", self.phase, Phase))
        object.__setattr__(self, "source", _mode("source", self.source, Source))
        for name in ("start_pos", "target", "landing"):
            object.__setattr__(self, name, _as_array(name, getattr(self, name), (2,)))
        object.__setattr__(self, "foot", _as_array("foot", self.foot, (3,)))
        path = _as_array("com_path", self.com_path, (None, 3))
        object.__setattr__(self, "com_path", path)
        if self.com_time is not None:
            times = _as_array("com_time", self.com_time, (path.shape[0],))
            object.__setattr__(self, "com_time", times)

    @classmethod
    def of_hop(
        cls,
        run_index: int,
        step: int,
        decision: Decision,
        info: StepInfo,
        landing: np.ndarray,
        cell: int,
        *,
        product_state: int,
        p_worst: float,
        reward: float,
        total_reward: float,
    ) -> HopEvent:
        """The event of hop ``step``: the policy's ``decision``, the environment's step
        ``info`` and the landing (CoM ``(x, y)`` and cell) in product state
        ``product_state``."""
        from planner.imdp.grid import ACTIONS

        hop, chosen = info.hop, info.decision
        has_path = len(hop.com_path) > 0
        return cls(
            run_index=run_index,
            step=step,
            phase=decision.phase,
            source=decision.source,
            backup=chosen.backup_used,
            requested_action=ACTIONS[chosen.requested],
            executed_action=ACTIONS[chosen.executed],
            start_pos=info.start_pos,
            target=info.target,
            landing=landing,
            com_path=hop.com_path if has_path else np.zeros((0, 3)),
            foot=hop.foot,
            touchdown_time=hop.touchdown_time,
            cell=cell,
            product_state=product_state,
            p_worst=p_worst,
            reward=reward,
            total_reward=total_reward,
            com_time=hop.com_path_time if has_path else None,
        )


@dataclass(frozen=True)
class ResynthesisRecord:
    """What one (re-)synthesis of a run found, for reports.

    Attributes:
        step: hops done in the run when it ran (0 for the initial synthesis).
        p_worst_current: worst-case satisfaction probability ``P̌`` of the run's current
            product state under this synthesis (the number the switch compares with P_sat).
        p_worst_initial: ``P̌`` of the initial product state.
        num_data: hops the GPs were fitted on.
        gp: the landing-error model's report of this fit
            (:class:`~planner.gp.landing.FitReport`): every numeric field but ``num_data``
            (its hyperparameters and what it estimated), flattened to a tuple of floats;
            a field with a non-finite value (e.g. the loss of a fit without data) is left out.
        mec_states: states of the end component exploration steers to (0: none).
        mec_probability: worst-case probability of reaching it from the current state.
        mec_average_reward: its average reward still to be collected.
    """

    step: int
    p_worst_current: float
    p_worst_initial: float
    num_data: int
    gp: dict[str, tuple[float, ...]] = field(default_factory=dict)
    mec_states: int = 0
    mec_probability: float | None = None
    mec_average_reward: float | None = None

    @classmethod
    def of_synthesis(cls, step: int, res: Resynthesis, current: int) -> ResynthesisRecord:
        """The record of re-synthesis ``res``, run after ``step`` hops in product state
        ``current``."""
        fit, mec = res.fit, res.mec
        values = res.satisfaction.values
        gp = {}
        for f in fields(fit):
            value = np.asarray(getattr(fit, f.name))
            if f.name != "num_data" and value.dtype.kind in "iuf" and np.isfinite(value).all():
                gp[f.name] = tuple(float(v) for v in value.ravel())
        return cls(
            step=step,
            p_worst_current=float(np.clip(values[current], 0.0, 1.0)),
            p_worst_initial=float(np.clip(values[res.product.initial], 0.0, 1.0)),
            num_data=int(fit.num_data),
            gp=gp,
            mec_states=0 if mec is None else len(mec.component),
            mec_probability=None if mec is None else float(mec.probability),
            mec_average_reward=None if mec is None else float(mec.average_reward),
        )


@dataclass(frozen=True)
class SynthesisEvent:
    """The GPs were refitted and the strategy re-synthesised.

    Attributes:
        run_index: the run.
        step: hops done in the run when the synthesis ran (0 for the initial one).
        grid_x: ``(Gx,)`` x coordinates of the GP evaluation grid, m.
        grid_y: ``(Gy,)`` y coordinates of the GP evaluation grid, m.
        gp_mean: ``(Gx, Gy, 2)`` posterior mean of the landing error (x, y), m.
        gp_std: ``(Gx, Gy, 2)`` posterior standard deviation of the landing error, m.
        p_worst_initial: worst-case satisfaction probability of the initial product state.
        timings: wall-clock seconds per stage (e.g. ``{"gp_fit": 0.8, "imdp": 0.1}``).
        record: the synthesis's report (current ``P̌``, GP hyperparameters, chosen MEC).
    """

    run_index: int
    step: int
    grid_x: np.ndarray
    grid_y: np.ndarray
    gp_mean: np.ndarray
    gp_std: np.ndarray
    p_worst_initial: float
    timings: dict[str, float] = field(default_factory=dict)
    record: ResynthesisRecord | None = None

    def __post_init__(self) -> None:
        gx = _as_array("grid_x", self.grid_x, (None,))
        gy = _as_array("grid_y", self.grid_y, (None,))
        object.__setattr__(self, "grid_x", gx)
        object.__setattr__(self, "grid_y", gy)
        for name in ("gp_mean", "gp_std"):
            value = _as_array(name, getattr(self, name), (gx.size, gy.size, 2))
            object.__setattr__(self, name, value)

    @classmethod
    def of_model(
        cls,
        run_index: int,
        step: int,
        gp: LandingErrorGP,
        grid_x: np.ndarray,
        grid_y: np.ndarray,
        timings: dict[str, float],
        record: ResynthesisRecord,
    ) -> SynthesisEvent:
        """The event of a synthesis with landing-error model ``gp``, mapped on the points
        ``grid_x x grid_y``: per point the mean over the actions and the largest std."""
        gx, gy = np.meshgrid(grid_x, grid_y, indexing="ij")
        mean, std = gp.predict(np.stack([gx.ravel(), gy.ravel()], axis=1))
        mean, std = mean.mean(axis=1), std.max(axis=1)
        shape = (*gx.shape, 2)
        return cls(
            run_index=run_index,
            step=step,
            grid_x=grid_x,
            grid_y=grid_y,
            gp_mean=mean.reshape(shape),
            gp_std=std.reshape(shape),
            p_worst_initial=record.p_worst_initial,
            timings=dict(timings),
            record=record,
        )


@dataclass(frozen=True)
class RunEnd:
    """A run ended.

    Attributes:
        run_index: the run.
        outcome: ``"success"`` (every hazard-free continuation of the run satisfies the
            formula, e.g. the goal reached), ``"violation"`` (hazard, out, a fall, or no
            continuation satisfies), ``"satisfying"`` (at the step cap the formula is open
            and the last window, repeated forever, satisfies it: a recurrence or safety
            obligation met so far) or ``"timeout"`` (the step cap otherwise);
            :mod:`planner.verdict`.
        steps: number of hops.
        reward: total reward collected.
        switch_step: hop at which goal reaching began, or ``None`` if it never did.
        p_switch: worst-case satisfaction probability at the switch, or ``None``.
        backups: number of hops where the backup switch replaced the action.
        seconds: wall-clock duration of the run, s.
        timings: wall-clock seconds per stage summed over the run (``batch_max``: the longest
            single re-synthesis).
        reason: what ended the run in words (``"hazard"``, ``"left the map"``,
            ``"hop failed: ..."``, ``"specification satisfied"``, ``"step cap"``...).
        left_plan_step: the hop at which the robot left the goal-reaching plan of the switch
            (its state had no action in that plan's satisfying sub-model; the policy went back
            to exploration), or ``None`` if it never did: only a run with ``None`` here was
            held to the guarantee ``p_switch`` to the end (:mod:`planner.policy`).
        resyntheses: one :class:`ResynthesisRecord` per synthesis of the run, in order.
        collections: cells whose reward the run collected (first landings in a cell with a
            nonzero reward), whatever the scenario's ``collect``.
        mission: what the end says about the formula (:class:`planner.verdict.MissionReport`:
            verdict, remaining obligation, the judged window, Rabin ``G`` visits in it,
            whether the run ended in an accepting end component).
    """

    run_index: int
    outcome: Outcome
    steps: int
    reward: float
    switch_step: int | None
    p_switch: float | None
    backups: int
    seconds: float
    timings: dict[str, float] = field(default_factory=dict)
    reason: str = ""
    left_plan_step: int | None = None
    resyntheses: tuple[ResynthesisRecord, ...] = ()
    collections: int = 0
    mission: MissionReport | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "outcome", _mode("outcome", self.outcome, Outcome))

    @property
    def p_worst_trace(self) -> tuple[float, ...]:
        """``P̌`` at the current state after each synthesis, in order."""
        return tuple(r.p_worst_current for r in self.resyntheses)


@runtime_checkable
class ObserverProtocol(Protocol):
    """What the runner calls; any object with these four methods will do."""

    def on_run_start(self, event: RunStart) -> None: ...
    def on_hop(self, event: HopEvent) -> None: ...
    def on_synthesis(self, event: SynthesisEvent) -> None: ...
    def on_run_end(self, event: RunEnd) -> None: ...


class Observer:
    """Base class with no-op handlers: subclass and override the ones you need."""

    def on_run_start(self, event: RunStart) -> None:
        """A run begins."""

    def on_hop(self, event: HopEvent) -> None:
        """A hop was made."""

    def on_synthesis(self, event: SynthesisEvent) -> None:
        """The GPs were refitted and the strategy re-synthesised."""

    def on_run_end(self, event: RunEnd) -> None:
        """A run ended."""

    def close(self) -> None:
        """Release resources (files, streams); called once after the last run."""


class Observers(Observer):
    """Fans every event out to several observers, in the given order."""

    def __init__(self, observers: Iterable[ObserverProtocol]) -> None:
        self.observers = tuple(observers)

    def on_run_start(self, event: RunStart) -> None:
        for o in self.observers:
            o.on_run_start(event)

    def on_hop(self, event: HopEvent) -> None:
        for o in self.observers:
            o.on_hop(event)

    def on_synthesis(self, event: SynthesisEvent) -> None:
        for o in self.observers:
            o.on_synthesis(event)

    def on_run_end(self, event: RunEnd) -> None:
        for o in self.observers:
            o.on_run_end(event)

    def close(self) -> None:
        for o in self.observers:
            close = getattr(o, "close", None)
            if close is not None:
                close()
