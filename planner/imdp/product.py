"""The multi-task product IMDP (MT-PIMDP) of an IMDP, a Rabin automaton and a reward.

Per docs/design.md the automaton reads the label of the state being *entered*: the product
transition ``(s, q) --a--> (s', q')`` has the interval of ``s --a--> s'`` and
``q' = delta(q, L(s'))``; the initial product state is ``(s0, delta(q0, L(s0)))``.
Product state ``(s, q)`` has index ``s * n_q + q``. The reward ``W(s)`` of a model state
is carried to every ``(s, q)`` and is collected on landing.

Acceptance is Rabin with pairs ``(G_i, B_i)`` of automaton states lifted to
``S x G_i``, ``S x B_i``.

Worst-case satisfaction (:meth:`ProductIMDP.satisfaction`) is the exact value of the game
``P_check = max_pi min_zeta P(formula)`` with a dynamic interval adversary, also where
lower bounds are 0 (the adversary chooses supports): :mod:`planner.imdp.rabin`. It is *not*
in general the worst-case probability of reaching the robustly accepting end components
(:meth:`ProductIMDP.accepting_end_components`, the paper's candidates for the MEC choice):
that probability is a lower bound, equal to ``P_check`` when the automaton's accepting
states are absorbing (co-safe formulas such as ``!Haz U Goal``) but smaller when the
adversary can keep a satisfying run outside every such component (``G !c``). Best-case
satisfaction (``pessimistic=False``): the adversary cooperates, so the product is a Markov
decision process over the polytopes, and the value is the maximal probability of reaching
its accepting end components (exact).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

from planner.automaton import RabinAutomaton
from planner.errors import ProductError
from planner.imdp import graph
from planner.imdp.graph import EndComponent, SubModel
from planner.imdp.model import IMDP
from planner.imdp.rabin import almost_sure_region, robust_satisfaction
from planner.imdp.solve import (
    Problem,
    ReachAvoid,
    Solution,
    Specification,
    ValueIteration,
    solve,
)

#: Most product states ``n_states x n_q`` and transitions (successor entries of the model
#: times ``n_q``) built: a product of 2.56e7 transitions took 4.3 GB and 110 s to check.
MAX_PRODUCT_STATES = 1 << 22
MAX_PRODUCT_ENTRIES = 1 << 24


def check_product_size(n_states: int, n_entries: int, n_q: int) -> None:
    """Raise :class:`ProductError` if the product of a model of ``n_states`` states and
    ``n_entries`` successor entries with an automaton of ``n_q`` states would exceed
    :data:`MAX_PRODUCT_STATES` or :data:`MAX_PRODUCT_ENTRIES` (checked before building)."""
    for what, count, limit in (
        ("states", n_states * n_q, MAX_PRODUCT_STATES),
        ("transitions", n_entries * n_q, MAX_PRODUCT_ENTRIES),
    ):
        if count > limit:
            raise ProductError(
                f"the product of {n_states} model states and {n_q} automaton states would "
                f"have {count} {what}, more than the limit of {limit}"
            )


@dataclass(frozen=True)
class MecChoice:
    """The end component chosen to steer to (the paper's MEC choice).

    Attributes:
        index: its index in the candidate list.
        component: the end component.
        probability: worst-case probability of reaching it from the initial state.
        average_reward: mean of ``W`` over its states.
    """

    index: int
    component: EndComponent
    probability: float
    average_reward: float


class ProductIMDP:
    """MT-PIMDP ``I (x) R`` with reward ``W``.

    Args:
        model: the IMDP (e.g. from :meth:`GridWorld.imdp_from_intervals`).
        automaton: a complete deterministic Rabin automaton whose propositions are among
            the model's propositions.
        reward: ``W`` per model state, shape ``(model.n_states,)`` (default 0).

    Raises:
        ProductError: a product larger than :func:`check_product_size` allows, an
            automaton proposition the model does not declare, or a reward
            of the wrong shape.
    """

    def __init__(
        self, model: IMDP, automaton: RabinAutomaton, reward: np.ndarray | None = None
    ) -> None:
        unknown = [p for p in automaton.propositions if p not in model.propositions]
        if unknown:
            raise ProductError(
                f"automaton propositions {unknown} are not labels of the model "
                f"(model propositions: {model.propositions})"
            )
        w = np.zeros(model.n_states) if reward is None else np.asarray(reward, dtype=float)
        if w.shape != (model.n_states,) or not np.all(np.isfinite(w)):
            raise ProductError(f"reward must be finite with shape ({model.n_states},)")
        nq = automaton.n_states
        check_product_size(model.n_states, int(model.successor.size), nq)
        self.base = model
        self.automaton = automaton
        self.n_q = nq
        bits = np.array(
            [model.propositions.index(p) for p in automaton.propositions], dtype=np.int64
        )
        self.letters: np.ndarray = (
            (model.label_matrix[:, bits].astype(np.int64) << np.arange(bits.size)).sum(axis=1)
            if bits.size
            else np.zeros(model.n_states, dtype=np.int64)
        )
        """Automaton letter of each model state's label set."""
        delta = automaton.transitions
        layout = _product_layout(
            model.state_ptr,
            model.row_ptr,
            model.row_action,
            model.successor,
            model.lower,
            model.upper,
            delta,
            self.letters,
            nq,
        )
        init = model.initial * nq + delta[automaton.initial, self.letters[model.initial]]
        # every model state's rows once per automaton state, in the order (s, q, a, t):
        # product state s * nq + q and successors t * nq + q' come out sorted, and the
        # bounds are the model's (already checked)
        self.model: IMDP = IMDP._trusted(
            model.n_states * nq,
            *layout,
            n_actions=model.n_actions,
            label_matrix=np.repeat(model.label_matrix, nq, axis=0),
            propositions=model.propositions,
            initial=init,
            action_names=model.action_names,
            tolerance=model.tolerance,
        )
        self.reward: np.ndarray = np.repeat(w, nq)
        """``W`` per product state."""
        self.base_state: np.ndarray = np.arange(self.model.n_states) // nq
        self.automaton_state: np.ndarray = np.arange(self.model.n_states) % nq
        self.good: tuple[np.ndarray, ...] = tuple(
            np.isin(self.automaton_state, sorted(p.good)) for p in automaton.pairs
        )
        self.bad: tuple[np.ndarray, ...] = tuple(
            np.isin(self.automaton_state, sorted(p.bad)) for p in automaton.pairs
        )
        self._accepting: list[EndComponent] | None = None
        self._satisfaction: Solution | None = None
        self._failure: np.ndarray | None = None
        self._winning: np.ndarray | None = None

    # ------------------------------------------------------------------ indexing
    @property
    def n_states(self) -> int:
        return self.model.n_states

    @property
    def initial(self) -> int:
        """The (first) initial product state ``(s0, delta(q0, L(s0)))``."""
        return int(self.model.initial[0])

    def state_index(self, state: int | np.ndarray, q: int | np.ndarray) -> np.ndarray | int:
        """Product index of (model state, automaton state)."""
        return np.asarray(state) * self.n_q + np.asarray(q)

    def entry_state(self, state: int) -> int:
        """Product state in which a run starting in model state ``state`` begins."""
        q = self.automaton.transitions[self.automaton.initial, self.letters[state]]
        return int(state * self.n_q + q)

    def step(self, product_state: int, next_state: int) -> int:
        """Product state after landing in model state ``next_state``."""
        q = self.automaton.transitions[product_state % self.n_q, self.letters[next_state]]
        return int(next_state * self.n_q + q)

    # ------------------------------------------------------------------ analyses
    def accepting_end_components(self) -> list[EndComponent]:
        """Robustly accepting maximal end components of every Rabin pair (cached)."""
        if self._accepting is None:
            out: list[EndComponent] = []
            for i, (g, b) in enumerate(zip(self.good, self.bad, strict=True)):
                for ec in graph.accepting_end_components(self.model, g, b):
                    out.append(EndComponent(ec.states, ec.rows, pair=i))
            self._accepting = out
        return list(self._accepting)

    def end_components(self, allowed: np.ndarray | None = None) -> list[EndComponent]:
        """Maximal end components (pessimistic: closed under every adversary) of the
        sub-model with the ``(n_states, n_actions)`` mask ``allowed`` of actions; with the
        nonviolating sub-model's actions these are the exploration candidates."""
        rows = None if allowed is None else graph.rows_from_actions(self.model, allowed)
        return graph.maximal_end_components(self.model, rows=rows)

    def accepting_states(self) -> np.ndarray:
        """Union of the states of the accepting end components."""
        mask = np.zeros(self.n_states, dtype=bool)
        for ec in self.accepting_end_components():
            mask[ec.states] = True
        return mask

    def failure_states(self) -> np.ndarray:
        """States with best-case probability 0 of satisfying the formula (graph-exact):
        no ``upper > 0`` path to an end component that a cooperative adversary keeps
        visiting some ``G_i`` and no ``B_i`` (computed once, then a copy is returned)."""
        if self._failure is None:
            target = self._optimistic_accepting()
            self._failure = ~graph.possible_reach(self.model, target)
        return self._failure.copy()

    def satisfaction(
        self,
        pessimistic: bool = True,
        allowed: np.ndarray | None = None,
        algorithm: ValueIteration | None = None,
    ) -> Solution:
        """Max probability of satisfying the formula per product state (worst case by
        default: ``P_check``, see the module docstring), with a memoryless optimal strategy
        and the certified bracket ``lower``/``upper`` (``values == lower``).

        The pessimistic solution without ``allowed`` is cached. The optimistic value uses
        the optimistic accepting components (the cooperating adversary makes it an MDP).
        """
        cache = pessimistic and allowed is None and algorithm is None
        if cache and self._satisfaction is not None:
            return self._satisfaction
        if pessimistic:
            sol = robust_satisfaction(
                self.model, self._good_matrix(), self._bad_matrix(), allowed, algorithm
            )
        else:
            rows = None if allowed is None else graph.rows_from_actions(self.model, allowed)
            target = self._optimistic_accepting(rows)
            spec = Specification(ReachAvoid(target), "optimistic")
            sol = solve(Problem(self.model, spec, allowed), algorithm)
        if cache:
            self._satisfaction = sol
        return sol

    def winning_states(self, allowed: np.ndarray | None = None) -> np.ndarray:
        """States from which the formula holds with probability 1 against every adversary
        (:func:`planner.imdp.rabin.almost_sure_region`; cached without ``allowed``)."""
        if allowed is None and self._winning is not None:
            return self._winning.copy()
        rows = None if allowed is None else graph.rows_from_actions(self.model, allowed)
        win, _ = almost_sure_region(self.model, self._good_matrix(), self._bad_matrix(), rows)
        if allowed is None:
            self._winning = win
        return win.copy()

    def _optimistic_accepting(self, rows: np.ndarray | None = None) -> np.ndarray:
        """States of the end components that a cooperating adversary keeps on some pair."""
        target = np.zeros(self.n_states, dtype=bool)
        for g, b in zip(self.good, self.bad, strict=True):
            target |= graph.optimistic_accepting_states(self.model, g, b, rows)
        return target

    def _good_matrix(self) -> np.ndarray:
        if not self.good:
            return np.zeros((0, self.n_states), dtype=bool)
        return np.stack(self.good)

    def _bad_matrix(self) -> np.ndarray:
        if not self.bad:
            return np.zeros((0, self.n_states), dtype=bool)
        return np.stack(self.bad)

    def nonviolating(self) -> SubModel:
        """The nonviolating sub-model: remove actions that may reach a failure state, then
        the states left without actions, until stable (Jiang et al. 2023, Alg. 1)."""
        return graph.prune(self.model, self.failure_states())

    def satisfying(self, threshold: float, solution: Solution | None = None) -> SubModel:
        """The satisfying sub-model for ``P_sat = threshold``.

        Keeps the states whose worst-case satisfaction probability ``V`` exceeds the
        threshold, and there the actions whose worst-case value ``Q`` (the minimising
        adversary's expectation of ``V`` over the action's intervals) exceeds it too: any
        allowed action keeps the guaranteed satisfaction probability above ``P_sat`` when
        the optimal strategy is followed afterwards. Every kept state keeps its optimal
        action (``Q = V``). ``solution`` defaults to :meth:`satisfaction`.
        """
        sol = self.satisfaction() if solution is None else solution
        keep = sol.values > threshold
        rows = keep[self.model.row_state] & (np.nan_to_num(sol.q_values, nan=-1.0) > threshold)
        states = keep & graph.has_row(self.model, rows)
        return SubModel(states, rows, graph.actions_from_rows(self.model, rows))

    def goal_strategy(self, allowed: np.ndarray | None = None) -> np.ndarray:
        """Action per product state that maximises the worst-case satisfaction probability
        (the memoryless optimal strategy of :meth:`satisfaction`: inside the almost-sure
        region it wins with probability 1, elsewhere it is optimal). -1 where no action is
        allowed or the state is settled without one."""
        return self.satisfaction(allowed=allowed).strategy.copy()

    def _inside_strategy(self, ec: EndComponent, rows: np.ndarray | None) -> np.ndarray:
        m = self.model
        ec_rows = ec.row_mask(m.n_rows)
        if rows is not None and (ec_rows & rows).any():
            ec_rows &= rows
        mask = ec.state_mask(m.n_states)
        target = mask.copy()
        if ec.pair >= 0:
            target &= self.good[ec.pair]
        if not target.any():
            target = mask.copy()
        _, choice = graph.robust_almost_sure_reach(m, target, rows=ec_rows, region=mask)
        # states in the target (and any left over) keep a row of the component
        idx = np.flatnonzero(ec_rows)
        st = m.row_state[idx]
        u, i = np.unique(st, return_index=True)
        first = np.full(m.n_states, -1, dtype=np.int64)
        first[u] = idx[i]
        choice = np.where(choice >= 0, choice, first)
        sub = choice[ec.states]
        return np.where(sub >= 0, m.row_action[np.maximum(sub, 0)], -1)

    def choose_mec(
        self,
        candidates: Sequence[EndComponent],
        state: int | None = None,
        allowed: np.ndarray | None = None,
        algorithm: ValueIteration | None = None,
    ) -> MecChoice:
        """The paper's MEC choice from product state ``state`` (default: initial).

        Candidates reachable with worst-case probability 1 (decided by graph analysis)
        are preferred; if there are none, those with the highest worst-case probability.
        Among the remaining, the highest average reward ``mean W`` over the component.

        Raises:
            ProductError: if ``candidates`` is empty.
        """
        if not candidates:
            raise ProductError("no candidate end components to choose from")
        s0 = self.initial if state is None else int(state)
        rows = None if allowed is None else graph.rows_from_actions(self.model, allowed)
        probs = np.zeros(len(candidates))
        for k, ec in enumerate(candidates):
            mask = ec.state_mask(self.n_states)
            sure, _ = graph.robust_almost_sure_reach(self.model, mask, rows=rows)
            if sure[s0]:
                probs[k] = 1.0
                continue
            if (probs == 1.0).any():
                continue  # cannot beat a sure candidate
            sol = solve(Problem(self.model, Specification(ReachAvoid(mask)), allowed), algorithm)
            probs[k] = min(float(sol.values[s0]), np.nextafter(1.0, 0.0))
        avg = np.array([float(self.reward[ec.states].mean()) for ec in candidates])
        best = probs == probs.max()
        k = int(np.flatnonzero(best)[np.argmax(avg[best])])
        return MecChoice(k, candidates[k], float(probs[k]), float(avg[k]))

    def steer_strategy(
        self,
        component: EndComponent,
        allowed: np.ndarray | None = None,
        algorithm: ValueIteration | None = None,
    ) -> np.ndarray:
        """Action per product state that maximises the worst-case probability of reaching
        ``component`` and, inside it, keeps to the component's actions."""
        mask = component.state_mask(self.n_states)
        sol = solve(Problem(self.model, Specification(ReachAvoid(mask)), allowed), algorithm)
        strategy = sol.strategy.copy()
        rows = None if allowed is None else graph.rows_from_actions(self.model, allowed)
        strategy[component.states] = self._inside_strategy(component, rows)
        return strategy

    def labelled_model(self) -> IMDP:
        """The product model with two extra labels for other tools: ``accept`` on the
        almost-sure winning states (:meth:`winning_states`; ``Pmax=? [F "accept"]`` under
        the worst case is the satisfaction probability whenever every satisfying run must
        enter them, e.g. for co-safe formulas) and ``fail`` on the failure states."""
        acc, fail = self.winning_states(), self.failure_states()
        for name in ("accept", "fail"):
            if name in self.model.propositions:
                raise ProductError(f"the model already uses the label {name!r}")
        labels = [
            ls | ({"accept"} if a else set()) | ({"fail"} if f else set())
            for ls, a, f in zip(self.model.labels, acc, fail, strict=True)
        ]
        s, a, t, lo, up = self.model.coo()
        return IMDP(
            self.n_states,
            s,
            a,
            t,
            lo,
            up,
            n_actions=self.model.n_actions,
            labels=labels,
            propositions=(*self.model.propositions, "accept", "fail"),
            initial=self.model.initial,
            action_names=self.model.action_names,
            tolerance=self.model.tolerance,
        )

    def component_actions(self, component: EndComponent) -> np.ndarray:
        """``(n_states, n_actions)`` mask of the component's actions."""
        return graph.actions_from_rows(self.model, component.row_mask(self.model.n_rows))


@numba.njit(cache=True, nogil=True)
def _product_layout(state_ptr, row_ptr, row_action, successor, lower, upper, delta, letters, nq):
    """Rows and entries of the product, in the model's internal layout: per model state
    ``s`` and automaton state ``q``, the rows of ``s`` with successors
    ``t * nq + delta[q, letters[t]]``. Returns ``(row_state, row_action, row_ptr,
    successor, lower, upper)``."""
    n = state_ptr.size - 1
    n_rows = (state_ptr[n] - state_ptr[0]) * nq
    n_entries = 0
    for s in range(n):
        n_entries += (row_ptr[state_ptr[s + 1]] - row_ptr[state_ptr[s]]) * nq
    p_state = np.empty(n_rows, dtype=np.int64)
    p_action = np.empty(n_rows, dtype=np.int64)
    p_ptr = np.empty(n_rows + 1, dtype=np.int64)
    p_succ = np.empty(n_entries, dtype=np.int64)
    p_lo = np.empty(n_entries)
    p_up = np.empty(n_entries)
    r_out = 0
    e_out = 0
    for s in range(n):
        for q in range(nq):
            for r in range(state_ptr[s], state_ptr[s + 1]):
                p_state[r_out] = s * nq + q
                p_action[r_out] = row_action[r]
                p_ptr[r_out] = e_out
                for e in range(row_ptr[r], row_ptr[r + 1]):
                    t = successor[e]
                    p_succ[e_out] = t * nq + delta[q, letters[t]]
                    p_lo[e_out] = lower[e]
                    p_up[e_out] = upper[e]
                    e_out += 1
                r_out += 1
    p_ptr[n_rows] = e_out
    return p_state, p_action, p_ptr, p_succ, p_lo, p_up
