"""Analyses of a product model (:class:`~planner.imdp.product.ProductIMDP`): functions of it.

Worst-case satisfaction (:func:`satisfaction`, :attr:`Adversary.PESSIMISTIC`) is the exact
value of the game ``P_check = max_pi min_zeta P(formula)`` with a dynamic interval adversary,
also where lower bounds are 0 (the adversary chooses supports): :mod:`planner.imdp.rabin`. It
is *not* in general the worst-case probability of reaching the robustly accepting end
components (:func:`accepting_end_components`, the paper's candidates for the MEC choice):
that probability is a lower bound, equal to ``P_check`` when the automaton's accepting states
are absorbing (co-safe formulas such as ``!Haz U Goal``) but smaller when the adversary can
keep a satisfying run outside every such component (``G !c``). Best-case satisfaction
(:attr:`Adversary.OPTIMISTIC`): the adversary cooperates, so the product is a Markov decision
process over the polytopes, and the value is the maximal probability of reaching its
accepting end components (exact).

The paper's sets (Section V): the *failure states* have best-case probability 0
(:func:`failure_states`); the *nonviolating* sub-model keeps the actions that cannot reach
one (:func:`nonviolating`); the *satisfying* sub-model keeps the states and actions whose
worst-case probability exceeds ``P_sat`` (:func:`satisfying`). Nothing is cached: a result
that a later step needs is passed to it (``failure=``, ``solution=``, ``winning=``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.errors import ProductError
from planner.imdp import graph
from planner.imdp.closed import closed_accepting
from planner.imdp.graph import EndComponent, SubModel
from planner.imdp.model import IMDP
from planner.imdp.product import ProductIMDP
from planner.imdp.rabin import almost_sure_region, robust_satisfaction
from planner.imdp.solve import Problem, ReachAvoid, Solution, Specification, ValueIteration, solve
from planner.modes import Adversary


def _rows(product: ProductIMDP, allowed: np.ndarray | None) -> np.ndarray | None:
    return None if allowed is None else graph.rows_from_actions(product.model, allowed)


def accepting_end_components(product: ProductIMDP) -> list[EndComponent]:
    """Robustly accepting maximal end components of every Rabin pair (``pair`` set)."""
    out: list[EndComponent] = []
    for i, (g, b) in enumerate(zip(product.good, product.bad, strict=True)):
        for ec in graph.accepting_end_components(product.model, g, b):
            out.append(EndComponent(ec.states, ec.rows, pair=i))
    return out


def end_components(product: ProductIMDP, allowed: np.ndarray | None = None) -> list[EndComponent]:
    """Maximal end components (pessimistic: closed under every adversary) of the sub-model
    with the ``(n_states, n_actions)`` mask ``allowed`` of actions; with the nonviolating
    sub-model's actions these are the exploration candidates."""
    return graph.maximal_end_components(product.model, rows=_rows(product, allowed))


def accepting_states(
    product: ProductIMDP, components: list[EndComponent] | None = None
) -> np.ndarray:
    """Union of the states of the accepting end components (default: computed)."""
    mask = np.zeros(product.n_states, dtype=bool)
    for ec in accepting_end_components(product) if components is None else components:
        mask[ec.states] = True
    return mask


def optimistic_accepting_states(product: ProductIMDP, rows: np.ndarray | None = None) -> np.ndarray:
    """States of the end components that a cooperating adversary keeps on some pair."""
    target = np.zeros(product.n_states, dtype=bool)
    for g, b in zip(product.good, product.bad, strict=True):
        target |= graph.optimistic_accepting_states(product.model, g, b, rows)
    return target


def failure_states(product: ProductIMDP) -> np.ndarray:
    """States with best-case probability 0 of satisfying the formula (graph-exact): no
    ``upper > 0`` path to an end component that a cooperative adversary keeps visiting some
    ``G_i`` and no ``B_i``. For a pair whose ``G_i \\ B_i`` no row leaves
    (:func:`planner.imdp.closed.closed_accepting`) that set stands in for its components:
    its every state has a path to one inside it (a bottom strongly connected component of
    its rows, all of whose states are in ``G_i``), and every such component lies inside it
    (one that visits ``G_i \\ B_i`` cannot leave it)."""
    m = product.model
    target = np.zeros(product.n_states, dtype=bool)
    for g, b in zip(product.good, product.bad, strict=True):
        closed = closed_accepting(m, g, b)
        target |= graph.optimistic_accepting_states(m, g, b) if closed is None else closed
    return ~graph.possible_reach(m, target)


def satisfaction(
    product: ProductIMDP,
    adversary: Adversary = Adversary.PESSIMISTIC,
    allowed: np.ndarray | None = None,
    algorithm: ValueIteration | None = None,
) -> Solution:
    """Max probability of satisfying the formula per product state (worst case by default:
    ``P_check``, see the module docstring), with a memoryless optimal strategy and the
    certified bracket ``lower``/``upper`` (``values == lower``). The optimistic value uses
    the optimistic accepting components (the cooperating adversary makes it an MDP)."""
    if Adversary(adversary) == Adversary.PESSIMISTIC:
        good, bad = product.good_matrix(), product.bad_matrix()
        return robust_satisfaction(product.model, good, bad, allowed, algorithm)
    target = optimistic_accepting_states(product, _rows(product, allowed))
    spec = Specification(ReachAvoid(target), Adversary.OPTIMISTIC)
    return solve(Problem(product.model, spec, allowed), algorithm)


def winning_states(product: ProductIMDP, allowed: np.ndarray | None = None) -> np.ndarray:
    """States from which the formula holds with probability 1 against every adversary
    (:func:`planner.imdp.rabin.almost_sure_region`)."""
    good, bad = product.good_matrix(), product.bad_matrix()
    win, _ = almost_sure_region(product.model, good, bad, _rows(product, allowed))
    return win


def nonviolating(product: ProductIMDP, failure: np.ndarray | None = None) -> SubModel:
    """The nonviolating sub-model: remove actions that may reach a failure state, then the
    states left without actions, until stable (Jiang et al. 2023, Alg. 1). ``failure``
    defaults to :func:`failure_states`."""
    fail = failure_states(product) if failure is None else failure
    return graph.prune(product.model, fail)


def satisfying(
    product: ProductIMDP, threshold: float, solution: Solution | None = None
) -> SubModel:
    """The satisfying sub-model for ``P_sat = threshold``.

    Keeps the states whose worst-case satisfaction probability ``V`` exceeds the threshold,
    and there the actions whose worst-case value ``Q`` (the minimising adversary's
    expectation of ``V`` over the action's intervals) exceeds it too: any allowed action
    keeps the guaranteed satisfaction probability above ``P_sat`` when the optimal strategy
    is followed afterwards. Every kept state keeps its optimal action (``Q = V``).
    ``solution`` defaults to the worst-case :func:`satisfaction`.
    """
    m = product.model
    sol = satisfaction(product) if solution is None else solution
    keep = sol.values > threshold
    rows = keep[m.row_state] & (np.nan_to_num(sol.q_values, nan=-1.0) > threshold)
    states = keep & graph.has_row(m, rows)
    return SubModel(states, rows, graph.actions_from_rows(m, rows))


def goal_strategy(product: ProductIMDP, allowed: np.ndarray | None = None) -> np.ndarray:
    """Action per product state that maximises the worst-case satisfaction probability (the
    memoryless optimal strategy of :func:`satisfaction`: inside the almost-sure region it
    wins with probability 1, elsewhere it is optimal). -1 where no action is allowed or the
    state is settled without one."""
    return satisfaction(product, allowed=allowed).strategy.copy()


def labelled_model(
    product: ProductIMDP, winning: np.ndarray | None = None, failure: np.ndarray | None = None
) -> IMDP:
    """The product model with two extra labels for other tools: ``accept`` on the almost-sure
    winning states (:func:`winning_states`; ``Pmax=? [F "accept"]`` under the worst case is
    the satisfaction probability whenever every satisfying run must enter them, e.g. for
    co-safe formulas) and ``fail`` on the failure states (:func:`failure_states`)."""
    m = product.model
    for name in ("accept", "fail"):
        if name in m.propositions:
            raise ProductError(f"the model already uses the label {name!r}")
    acc = winning_states(product) if winning is None else winning
    fail = failure_states(product) if failure is None else failure
    labels = [
        ls | ({"accept"} if a else set()) | ({"fail"} if f else set())
        for ls, a, f in zip(m.labels, acc, fail, strict=True)
    ]
    s, a, t, lo, up = m.coo()
    return IMDP(
        product.n_states,
        s,
        a,
        t,
        lo,
        up,
        n_actions=m.n_actions,
        labels=labels,
        propositions=(*m.propositions, "accept", "fail"),
        initial=m.initial,
        action_names=m.action_names,
        tolerance=m.tolerance,
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


def choose_mec(
    product: ProductIMDP,
    candidates: Sequence[EndComponent],
    state: int | None = None,
    allowed: np.ndarray | None = None,
    algorithm: ValueIteration | None = None,
) -> MecChoice:
    """The paper's MEC choice from product state ``state`` (default: initial).

    Candidates reachable with worst-case probability 1 (decided by graph analysis) are
    preferred; if there are none, those with the highest worst-case probability. Among the
    remaining, the highest average reward ``mean W`` over the component (ties: the first).

    Raises:
        ProductError: if ``candidates`` is empty.
    """
    if not candidates:
        raise ProductError("no candidate end components to choose from")
    m = product.model
    s0 = product.initial if state is None else int(state)
    rows = _rows(product, allowed)
    probs = np.zeros(len(candidates))
    for k, ec in enumerate(candidates):
        mask = ec.state_mask(product.n_states)
        sure, _ = graph.robust_almost_sure_reach(m, mask, rows=rows)
        if sure[s0]:
            probs[k] = 1.0
            continue
        if (probs == 1.0).any():
            continue  # cannot beat a sure candidate
        sol = solve(Problem(m, Specification(ReachAvoid(mask)), allowed), algorithm)
        probs[k] = min(float(sol.values[s0]), np.nextafter(1.0, 0.0))
    avg = np.array([float(product.reward[ec.states].mean()) for ec in candidates])
    best = probs == probs.max()
    k = int(np.flatnonzero(best)[np.argmax(avg[best])])
    return MecChoice(k, candidates[k], float(probs[k]), float(avg[k]))


def steer_strategy(
    product: ProductIMDP,
    component: EndComponent,
    allowed: np.ndarray | None = None,
    algorithm: ValueIteration | None = None,
) -> np.ndarray:
    """Action per product state that maximises the worst-case probability of reaching
    ``component`` and, inside it, keeps to the component's actions (:func:`inside_strategy`)."""
    mask = component.state_mask(product.n_states)
    spec = Specification(ReachAvoid(mask))
    strategy = solve(Problem(product.model, spec, allowed), algorithm).strategy.copy()
    strategy[component.states] = inside_strategy(product, component, _rows(product, allowed))
    return strategy


def inside_strategy(
    product: ProductIMDP, component: EndComponent, rows: np.ndarray | None = None
) -> np.ndarray:
    """The component's own actions, per state of ``component`` (in its order): outside its
    target (the states of its pair's ``G``; all its states for ``pair = -1`` or no such
    state) the action of a row that reaches the target with probability 1 against every
    adversary within the component, elsewhere its first row of the component (-1: none).
    ``rows`` restricts the component's rows where it leaves any."""
    m = product.model
    ec_rows = component.row_mask(m.n_rows)
    if rows is not None and (ec_rows & rows).any():
        ec_rows &= rows
    mask = component.state_mask(m.n_states)
    target = mask.copy()
    if component.pair >= 0:
        target &= product.good[component.pair]
    if not target.any():
        target = mask.copy()
    _, choice = graph.robust_almost_sure_reach(m, target, rows=ec_rows, region=mask)
    # states in the target (and any left over) keep a row of the component
    idx = np.flatnonzero(ec_rows)
    u, i = np.unique(m.row_state[idx], return_index=True)
    first = np.full(m.n_states, -1, dtype=np.int64)
    first[u] = idx[i]
    choice = np.where(choice >= 0, choice, first)
    sub = choice[component.states]
    return np.where(sub >= 0, m.row_action[np.maximum(sub, 0)], -1)
