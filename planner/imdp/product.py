"""The multi-task product IMDP (MT-PIMDP) of an IMDP, a Rabin automaton and a reward.

Per docs/design.md the automaton reads the label of the state being *entered*: the product
transition ``(s, q) --a--> (s', q')`` has the interval of ``s --a--> s'`` and
``q' = delta(q, L(s'))``; the initial product state is ``(s0, delta(q0, L(s0)))``.
Product state ``(s, q)`` has index ``s * n_q + q``. The reward ``W(s)`` of a model state
is carried to every ``(s, q)`` and is collected on landing.

Acceptance is Rabin with pairs ``(G_i, B_i)`` of automaton states lifted to
``S x G_i``, ``S x B_i``. Worst-case satisfaction of the formula = worst-case maximal
probability of reaching the union of the robustly accepting end components.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.automaton import RabinAutomaton
from planner.errors import ProductError
from planner.imdp import graph
from planner.imdp.graph import EndComponent, SubModel
from planner.imdp.model import IMDP
from planner.imdp.solve import (
    Problem,
    ReachAvoid,
    Solution,
    Specification,
    ValueIteration,
    solve,
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
        ProductError: an automaton proposition the model does not declare, or a reward
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
        self.base = model
        self.automaton = automaton
        nq = automaton.n_states
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
        s, a, t, lo, up = model.coo()
        # every model state's block of entries once per automaton state, in the order
        # (s, q, a, t): product state s * nq + q, so the entries come out sorted
        start = model.row_ptr[model.state_ptr[:-1]]
        length = model.row_ptr[model.state_ptr[1:]] - start
        seg_start = np.repeat(start, nq)
        seg_len = np.repeat(length, nq)
        offsets = np.concatenate(([0], np.cumsum(seg_len)[:-1]))
        idx = np.arange(int(seg_len.sum()), dtype=np.int64) + np.repeat(
            seg_start - offsets, seg_len
        )
        q = np.repeat(np.tile(np.arange(nq, dtype=np.int64), model.n_states), seg_len)
        s, a, t, lo, up = s[idx], a[idx], t[idx], lo[idx], up[idx]
        ps = s * nq + q
        pt = t * nq + delta[q, self.letters[t]]
        init = model.initial * nq + delta[automaton.initial, self.letters[model.initial]]
        self.model: IMDP = IMDP(
            model.n_states * nq,
            ps,
            a,
            pt,
            lo,
            up,
            n_actions=model.n_actions,
            labels=[model.labels[i // nq] for i in range(model.n_states * nq)],
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
            target = np.zeros(self.n_states, dtype=bool)
            for g, b in zip(self.good, self.bad, strict=True):
                for ec in graph.optimistic_accepting_end_components(self.model, g, b):
                    target[ec.states] = True
            self._failure = ~graph.possible_reach(self.model, target)
        return self._failure.copy()

    def satisfaction(
        self,
        pessimistic: bool = True,
        allowed: np.ndarray | None = None,
        algorithm: ValueIteration | None = None,
    ) -> Solution:
        """Max probability of satisfying the formula per product state (worst case by
        default), with a strategy that reaches the accepting end components.

        The pessimistic solution without ``allowed`` is cached. The optimistic value uses
        the optimistic accepting components.
        """
        cache = pessimistic and allowed is None and algorithm is None
        if cache and self._satisfaction is not None:
            return self._satisfaction
        if pessimistic:
            target = self.accepting_states()
        else:
            target = np.zeros(self.n_states, dtype=bool)
            for g, b in zip(self.good, self.bad, strict=True):
                for ec in graph.optimistic_accepting_end_components(self.model, g, b):
                    target[ec.states] = True
        spec = Specification(ReachAvoid(target), "pessimistic" if pessimistic else "optimistic")
        sol = solve(Problem(self.model, spec, allowed), algorithm)
        if cache:
            self._satisfaction = sol
        return sol

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
        """Action per product state that maximises the worst-case satisfaction probability:
        reach an accepting end component, then (inside) visit its ``G`` states again and
        again with its own actions. -1 where no action is allowed or the value is 0."""
        sol = self.satisfaction(allowed=allowed)
        strategy = sol.strategy.copy()
        rows = None if allowed is None else graph.rows_from_actions(self.model, allowed)
        for ec in self.accepting_end_components():
            strategy[ec.states] = self._inside_strategy(ec, rows)
        return strategy

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
        states of the accepting end components (so ``Pmax=? [F "accept"]`` is the
        satisfaction probability) and ``fail`` on the failure states."""
        acc, fail = self.accepting_states(), self.failure_states()
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
