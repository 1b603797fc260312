"""Robust Q-learning on interval MDPs with the minimising (state-ordering) adversary.

Reward ``W`` is collected on *landing* (docs/design.md), so for a row ``(s, a)`` with interval
bounds ``l <= p <= u`` the robust Q-value is the worst case over the interval polytope::

    Q(s, a) = min_{l <= p <= u, sum p = 1}  sum_{s'} p(s') (W(s') + gamma V(s')),
    V(s)    = max_{a allowed in s} Q(s, a)        (0 where no action is allowed)

The minimum is evaluated by :class:`planner.imdp.OrderingAdversary` (Lahijanian et al. 2015),
so the values are lower bounds on the reward of every distribution inside the intervals.

* Known ``W``: :func:`robust_q_iteration` solves the equations by the discounted-reward
  value iteration of :func:`planner.imdp.solve` (a contraction with factor ``gamma``: error
  ``<= gamma / (1 - gamma) * residual``) and returns the Q-values of every row.
* Unknown ``W``: :class:`RobustQLearner` learns the reward of a cell from visits (the mean of
  the rewards observed on landing there; unvisited cells carry ``prior_reward``, 0 by default;
  where a cell pays only on its first landing of a run the caller observes only those
  landings) and learns ``Q`` by
  asynchronous robust updates ``Q(s, a) <- (1 - alpha) Q(s, a) + alpha * target(s, a)`` on
  the visited rows (online, epsilon-greedy) plus full sweeps after each re-synthesis.
  ``Q`` and the learned rewards are saved and loaded (:meth:`RobustQLearner.save`,
  :meth:`RobustQLearner.load`) so they persist across runs while the GP data is reset.

States of the model are mapped to reward *cells* by ``state_cell`` (identity by default; for a
product model, the grid cell of each product state), so that rewards are learned per cell.

Reward paid once per run (a scenario's ``collect = "once"``): the rewards still to be collected
are ``W`` with the cells collected so far set to 0, and the plan is the robust Q-iteration on
those (:attr:`RobustQLearner.collected` does this for the learner). That is a Markov
approximation: the true reward depends on the set of cells collected, which the state does not
hold, so the plan values an uncollected cell as if it paid on every future landing (a loop over
two uncollected cells looks worth more than it is), and it cannot plan an order of
collection. Re-solving after every collection (as the runner does) keeps the plan from going
back to a cell it has emptied; what it gives up is the tour optimisation over subsets of cells
(exponential in their number).
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planner._util.atomic import atomic_write
from planner._util.sealed import SealError, read_limited, seal, unseal
from planner.errors import QTableError
from planner.imdp import (
    IMDP,
    DiscountedReward,
    OrderingAdversary,
    Problem,
    Specification,
    ValueIteration,
    solve,
)

FORMAT_TAG = "hopnav-robust-q"
FORMAT_VERSION = 1
#: The kind named in the header of the sealed file (:mod:`planner._util.sealed`).
SEAL_KIND = "robust-q-table"
#: Largest Q-table file read [bytes].
MAX_FILE_BYTES = 1 << 30


def _allowed_rows(model: IMDP, allowed: np.ndarray | None) -> np.ndarray:
    if allowed is None:
        return np.ones(model.n_rows, dtype=bool)
    allowed = np.asarray(allowed)
    if allowed.dtype != bool or allowed.shape != (model.n_states, model.n_actions):
        raise QTableError(
            f"allowed must be a boolean ({model.n_states}, {model.n_actions}) mask, got "
            f"{allowed.dtype} {allowed.shape}"
        )
    return allowed[model.row_state, model.row_action]


def _state_values(model: IMDP, q_rows: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``V(s) = max`` over the allowed rows of ``s`` (0 where none is allowed)."""
    qq = np.where(rows, q_rows, -np.inf)
    v = np.maximum.reduceat(qq, model.state_ptr[:-1]) if model.n_rows else np.zeros(0)
    return np.where(np.isfinite(v), v, 0.0)


def _rows_to_table(model: IMDP, q_rows: np.ndarray) -> np.ndarray:
    table = np.full((model.n_states, model.n_actions), np.nan)
    table[model.row_state, model.row_action] = q_rows
    return table


@dataclass(frozen=True)
class QSolution:
    """Result of :func:`robust_q_iteration`.

    Attributes:
        q: ``(n_states, n_actions)`` robust Q-values (``nan`` for disabled actions).
        values: ``(n_states,)`` ``V = max`` over allowed actions.
        residual: last ``max |V_k - V_{k-1}|``.
        iterations: number of sweeps.
        converged: ``residual < tolerance``.
    """

    q: np.ndarray
    values: np.ndarray
    residual: float
    iterations: int
    converged: bool


def robust_q_iteration(
    model: IMDP,
    reward: np.ndarray,
    *,
    discount: float,
    allowed: np.ndarray | None = None,
    initial: np.ndarray | None = None,
    tolerance: float = 1e-8,
    max_iterations: int = 100_000,
    adversary: OrderingAdversary | None = None,
    callback: Callable[[int, float], None] | None = None,
) -> QSolution:
    """Robust Q-iteration for a known reward ``reward`` (per model state, collected on landing).

    Args:
        model: the interval MDP.
        reward: ``(n_states,)`` reward of landing in each state.
        discount: ``gamma`` in ``[0, 1)`` (a run's: :attr:`QLearningConfig.discount`).
        allowed: ``(n_states, n_actions)`` mask of the actions ``V`` may maximise over
            (a sub-model); default all enabled actions.
        initial: ``(n_states, n_actions)`` Q-table to warm-start from (``nan`` ignored).
        tolerance: stop when ``max |V_k - V_{k-1}| < tolerance``.
        max_iterations: at most this many sweeps.
        adversary: a minimising :class:`OrderingAdversary` of ``model`` to reuse.
        callback: ``callback(iteration, residual)`` after every sweep.
    """
    w = np.asarray(reward, dtype=np.float64)
    if w.shape != (model.n_states,) or not np.isfinite(w).all():
        raise QTableError(f"reward must be a finite array of shape ({model.n_states},)")
    if not 0.0 <= discount < 1.0:
        raise QTableError(f"discount must lie in [0, 1), got {discount}")
    if not tolerance > 0.0 or max_iterations < 1:
        raise QTableError(f"need tolerance > 0 and max_iterations >= 1, got {tolerance}")
    rows = _allowed_rows(model, allowed)
    adv = adversary if adversary is not None else OrderingAdversary(model, minimize=True)
    if adv.model is not model or not adv.minimize:
        raise QTableError("adversary must be a minimising OrderingAdversary of this model")
    v0 = None
    if initial is not None:
        init = np.asarray(initial, dtype=np.float64)
        if init.shape != (model.n_states, model.n_actions):
            raise QTableError(
                f"initial Q-table must have shape ({model.n_states}, {model.n_actions}), "
                f"got {init.shape}"
            )
        q0 = init[model.row_state, model.row_action]
        v0 = _state_values(model, np.nan_to_num(q0, nan=-np.inf), rows)
    spec = Specification(DiscountedReward(w, discount))
    sol = solve(
        Problem(model, spec, None if allowed is None else np.asarray(allowed)),
        ValueIteration(tolerance, max_iterations, callback, certified=False, initial=v0),
    )
    q_rows = adv.expectation(w + discount * sol.values)
    return QSolution(
        _rows_to_table(model, q_rows), sol.values, sol.residual, sol.iterations, sol.converged
    )


TIE_TOLERANCE = 1e-6
"""Q-values within ``TIE_TOLERANCE * max(1, |best|)`` of the best are ties (the Q-iteration
stops at a residual of about this size, so smaller differences carry no information)."""


def greedy_action(
    q_row: np.ndarray,
    allowed: np.ndarray,
    prefer: int = -1,
    rng: np.random.Generator | None = None,
    tolerance: float = TIE_TOLERANCE,
) -> int:
    """The allowed action of largest Q-value; ``allowed`` is an ``(n_actions,)`` mask.

    Ties (values within ``tolerance * max(1, |best|)`` of the best, :data:`TIE_TOLERANCE`) go
    to ``prefer`` when it is among them (the policy passes its LTL action, so that a reward
    indifferent between actions does not pull against the task); otherwise to a tied action
    drawn uniformly from ``rng`` (one draw, only when there is a tie); without ``rng`` to the
    lowest index (deterministic, e.g. for tests). Where no allowed action has a finite value
    every allowed action ties.
    """
    allowed = np.asarray(allowed, dtype=bool)
    if not allowed.any():
        raise QTableError("no allowed action to choose from")
    scores = np.where(allowed, np.nan_to_num(np.asarray(q_row, float), nan=-np.inf), -np.inf)
    best = scores.max()
    if np.isfinite(best):
        tied = np.flatnonzero(scores >= best - tolerance * max(1.0, abs(best)))
    else:
        tied = np.flatnonzero(allowed)
    if tied.size == 1:
        return int(tied[0])
    if 0 <= prefer < allowed.size and prefer in tied:
        return int(prefer)
    if rng is None:
        return int(tied[0])
    return int(tied[rng.integers(tied.size)])


@dataclass(frozen=True)
class GreedyQ:
    """Greedy actor on a fixed Q-table (known reward): ``act`` never explores; ties as in
    :func:`greedy_action` (``prefer``, else a draw from ``rng``)."""

    q: np.ndarray

    def act(
        self, state: int, allowed: np.ndarray, rng: np.random.Generator, prefer: int = -1
    ) -> int:
        return greedy_action(self.q[state], allowed, prefer=prefer, rng=rng)


@dataclass(frozen=True)
class QLearningConfig:
    """Settings of :class:`RobustQLearner`.

    ``discount`` gamma; ``learning_rate`` alpha of the asynchronous update; ``epsilon`` the
    probability of a uniformly random allowed action in :meth:`RobustQLearner.act`;
    ``prior_reward`` the reward assumed for unvisited cells (default 0, neutral). An optimistic
    prior (e.g. 5 against the case study's 0, -0.5, 5, 20) draws greedy choices towards
    unexplored cells; under wide intervals, though, the robust Q-value of one rewarding cell is
    0 while a patch of unexplored cells is worth the prior wherever the adversary sends the
    robot, so it kept drawing later runs away from the cells learned to be worth 20 (case
    (d)). The exploration of unknown rewards is left to the exploration tour
    (:mod:`planner.learning` makes it head for cells whose reward was never observed first)
    and to ``epsilon``.
    """

    discount: float = 0.95
    learning_rate: float = 0.5
    epsilon: float = 0.1
    prior_reward: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.discount < 1.0:
            raise QTableError(f"discount must lie in [0, 1), got {self.discount}")
        if not 0.0 < self.learning_rate <= 1.0:
            raise QTableError(f"learning_rate must lie in (0, 1], got {self.learning_rate}")
        if not 0.0 <= self.epsilon <= 1.0:
            raise QTableError(f"epsilon must lie in [0, 1], got {self.epsilon}")
        if not np.isfinite(self.prior_reward):
            raise QTableError(f"prior_reward must be finite, got {self.prior_reward}")


class RobustQLearner:
    """Online robust Q-learning with rewards learned from visits (see the module docstring).

    Args:
        n_states, n_actions: size of the models it will be used with.
        n_cells: number of reward cells.
        state_cell: ``(n_states,)`` cell of each model state (default: identity, then
            ``n_cells`` must equal ``n_states``).
        settings: learning settings.
    """

    def __init__(
        self,
        n_states: int,
        n_actions: int,
        n_cells: int,
        *,
        state_cell: np.ndarray | None = None,
        settings: QLearningConfig | None = None,
    ) -> None:
        if n_states < 1 or n_actions < 1 or n_cells < 1:
            raise QTableError(f"sizes must be positive, got {n_states}, {n_actions}, {n_cells}")
        if state_cell is None:
            if n_cells != n_states:
                raise QTableError("state_cell is required when n_cells != n_states")
            state_cell = np.arange(n_states)
        sc = np.asarray(state_cell)
        if sc.shape != (n_states,) or sc.dtype.kind not in "iu":
            raise QTableError(f"state_cell must be an integer array of shape ({n_states},)")
        if sc.size and (sc.min() < 0 or sc.max() >= n_cells):
            raise QTableError(f"state_cell values must lie in [0, {n_cells})")
        self.settings = settings or QLearningConfig()
        self.state_cell = sc.astype(np.int64)
        self.n_cells = int(n_cells)
        self.q = np.zeros((n_states, n_actions))
        self.reward_sum = np.zeros(n_cells)
        self.reward_count = np.zeros(n_cells, dtype=np.int64)
        self.collected = np.zeros(n_cells, dtype=bool)
        """Cells whose reward this run has already collected: they count 0 in
        :meth:`state_reward` (so in updates and sweeps), while :meth:`cell_reward` keeps what
        was learned. Set by the caller (reset to all False at the start of a run); not saved."""
        self._adv: OrderingAdversary | None = None
        #: free-form JSON-able record saved with the table (e.g. the provenance of the
        #: scenario it was learnt on); :meth:`load` restores it (``{}`` for older files).
        self.metadata: dict = {}

    @property
    def n_states(self) -> int:
        return self.q.shape[0]

    @property
    def n_actions(self) -> int:
        return self.q.shape[1]

    def cell_reward(self) -> np.ndarray:
        """Learned reward per cell: the mean observed reward, ``prior_reward`` if unvisited."""
        seen = self.reward_count > 0
        mean = self.reward_sum / np.maximum(self.reward_count, 1)
        return np.where(seen, mean, self.settings.prior_reward)

    def remaining_reward(self) -> np.ndarray:
        """Learned reward per cell still to be collected: :meth:`cell_reward`, 0 on the
        :attr:`collected` cells."""
        return np.where(self.collected, 0.0, self.cell_reward())

    def state_reward(self) -> np.ndarray:
        """Reward per model state still to be collected, ``(n_states,)``."""
        return self.remaining_reward()[self.state_cell]

    def observe_reward(self, state: int, reward: float) -> None:
        """Record the reward ``reward`` collected on landing in model state ``state``."""
        if not 0 <= state < self.n_states:
            raise QTableError(f"state {state} is not in [0, {self.n_states})")
        if not np.isfinite(reward):
            raise QTableError(f"reward observed in state {state} is not finite: {reward}")
        cell = self.state_cell[state]
        self.reward_sum[cell] += float(reward)
        self.reward_count[cell] += 1

    def _adversary(self, model: IMDP) -> OrderingAdversary:
        if model.n_states != self.n_states or model.n_actions != self.n_actions:
            raise QTableError(
                f"model has {model.n_states} states and {model.n_actions} actions, the "
                f"learner {self.n_states} and {self.n_actions}"
            )
        if self._adv is None or self._adv.model is not model:
            self._adv = OrderingAdversary(model, minimize=True)
        return self._adv

    def _targets(self, model: IMDP, allowed: np.ndarray | None) -> np.ndarray:
        rows = _allowed_rows(model, allowed)
        q_rows = np.nan_to_num(self.q[model.row_state, model.row_action], nan=-np.inf)
        v = _state_values(model, q_rows, rows)
        w = self.state_reward()
        return self._adversary(model).expectation(w + self.settings.discount * v)

    def update(
        self,
        model: IMDP,
        state: int,
        action: int,
        landed: int,
        reward: float,
        *,
        allowed: np.ndarray | None = None,
        learn_reward: bool = True,
    ) -> float:
        """One online step: learn ``reward`` of ``landed`` (unless ``learn_reward`` is False:
        a landing that says nothing about the cell's reward, such as a repeat landing where
        cells pay once per run), then update ``Q(state, action)``.

        Returns the new ``Q(state, action)``.
        """
        self._adversary(model)
        if not 0 <= state < self.n_states or not 0 <= action < self.n_actions:
            raise QTableError(f"(state {state}, action {action}) is outside the Q-table")
        row = int(model.row_index[state, action])
        if row < 0:
            raise QTableError(f"action {action} is not enabled in state {state} of the model")
        if learn_reward:
            self.observe_reward(landed, reward)
        elif not 0 <= landed < self.n_states:
            raise QTableError(f"state {landed} is not in [0, {self.n_states})")
        target = self._targets(model, allowed)[row]
        a = self.settings.learning_rate
        self.q[state, action] = (1.0 - a) * self.q[state, action] + a * target
        return float(self.q[state, action])

    def sweep(
        self,
        model: IMDP,
        *,
        allowed: np.ndarray | None = None,
        tolerance: float = 1e-6,
        max_iterations: int = 10_000,
    ) -> QSolution:
        """Robust Q-iteration on the learned rewards, warm-started from the current table."""
        sol = robust_q_iteration(
            model,
            self.state_reward(),
            discount=self.settings.discount,
            allowed=allowed,
            initial=self.q,
            tolerance=tolerance,
            max_iterations=max_iterations,
            adversary=self._adversary(model),
        )
        enabled = model.enabled
        self.q = np.where(enabled, np.nan_to_num(sol.q, nan=0.0), self.q)
        return sol

    def act(
        self, state: int, allowed: np.ndarray, rng: np.random.Generator, prefer: int = -1
    ) -> int:
        """Epsilon-greedy among ``allowed`` (n_actions,): one uniform draw, then maybe another
        (the random action, or a tie broken as in :func:`greedy_action`)."""
        allowed = np.asarray(allowed, dtype=bool)
        if not allowed.any():
            raise QTableError(f"no allowed action in state {state}")
        if rng.random() < self.settings.epsilon:
            return int(rng.choice(np.flatnonzero(allowed)))
        return greedy_action(self.q[state], allowed, prefer=prefer, rng=rng)

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike[str], metadata: dict | None = None) -> None:
        """Write Q-table, learned rewards, settings and ``metadata`` (default:
        :attr:`metadata`; JSON-able) to ``path`` (.npz) atomically."""
        path = Path(path)
        s = self.settings
        meta = self.metadata if metadata is None else metadata
        arrays = {
            "format": np.array(FORMAT_TAG),
            "version": np.array(FORMAT_VERSION),
            "q": self.q,
            "reward_sum": self.reward_sum,
            "reward_count": self.reward_count,
            "state_cell": self.state_cell,
            "settings": np.array([s.discount, s.learning_rate, s.epsilon, s.prior_reward]),
            "metadata_json": np.array(json.dumps(meta)),
        }
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        with atomic_write(path, fsync=True) as f:
            f.write(seal(SEAL_KIND, buf.getvalue()))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> RobustQLearner:
        """Read a file written by :meth:`save`; raises :class:`QTableError` naming the file and
        the field when it is unreadable, altered (the digest of the sealed file,
        :mod:`planner._util.sealed`, does not match) or inconsistent."""
        path = Path(path)
        try:
            data = read_limited(path, MAX_FILE_BYTES)
        except FileNotFoundError:
            raise
        except (OSError, SealError) as exc:
            raise QTableError(f"{path}: not a readable Q-table file ({exc})") from exc
        if data.startswith(b"PK\x03\x04"):
            raise QTableError(
                f"{path}: a Q-table written without a digest of its contents (an older "
                "hopnav); it cannot be checked, learn it again"
            )
        try:
            with np.load(io.BytesIO(unseal(data, SEAL_KIND)), allow_pickle=False) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except SealError as exc:
            raise QTableError(f"{path}: not a readable Q-table file: {exc}") from None
        except Exception as exc:  # zipfile and numpy raise many types for a damaged payload
            raise QTableError(f"{path}: not a readable Q-table file ({exc})") from exc
        need = ("format", "version", "q", "reward_sum", "reward_count", "state_cell", "settings")
        missing = [k for k in need if k not in arrays]
        if missing:
            raise QTableError(f"{path}: missing field(s) {missing}")
        if str(arrays["format"]) != FORMAT_TAG or int(arrays["version"]) != FORMAT_VERSION:
            raise QTableError(
                f"{path}: format {arrays['format']!s} version {arrays['version']!s}, expected "
                f"{FORMAT_TAG} version {FORMAT_VERSION}"
            )
        q, rs, rc = arrays["q"], arrays["reward_sum"], arrays["reward_count"]
        sc, st = arrays["state_cell"], arrays["settings"]
        if q.ndim != 2 or q.dtype != np.float64 or not np.isfinite(q).all():
            raise QTableError(f"{path}: field 'q' must be a finite float64 matrix")
        if rs.ndim != 1 or rc.shape != rs.shape or rc.dtype.kind not in "iu":
            raise QTableError(f"{path}: fields 'reward_sum'/'reward_count' are inconsistent")
        if not np.isfinite(rs).all() or (rc < 0).any():
            raise QTableError(f"{path}: field 'reward_sum' or 'reward_count' has bad values")
        if st.shape != (4,):
            raise QTableError(f"{path}: field 'settings' must hold 4 numbers")
        try:
            settings = QLearningConfig(*(float(x) for x in st))
            learner = cls(q.shape[0], q.shape[1], rs.shape[0], state_cell=sc, settings=settings)
        except QTableError as exc:
            raise QTableError(f"{path}: {exc}") from exc
        learner.q = q.copy()
        learner.reward_sum = rs.astype(np.float64)
        learner.reward_count = rc.astype(np.int64)
        if "metadata_json" in arrays:
            try:
                learner.metadata = json.loads(str(arrays["metadata_json"]))
            except ValueError as exc:
                raise QTableError(f"{path}: field 'metadata_json' is not JSON ({exc})") from exc
            if not isinstance(learner.metadata, dict):
                raise QTableError(f"{path}: field 'metadata_json' must hold a JSON object")
        return learner
