"""LTL model checking of interval MDP models: the robust (or optimistic) maximal
probability of satisfying a formula over the model's labels.

The formula is translated by the project's own translator
(:func:`planner.ltl.translate.translate`) to a deterministic Rabin automaton over the
formula's propositions (each a label of the model), composed with the model
(:class:`planner.imdp.product.ProductIMDP`: the automaton reads the label of the state
being entered, a run from model state ``s`` starts in product state
``(s, delta(q0, L(s)))``) and solved:

* worst case (default): the exact value of the game against the interval adversary,
  ``P_check`` (:mod:`planner.imdp.rabin`);
* ``optimistic``: the adversary cooperates (a Markov decision process over the
  polytopes): maximal reachability of its accepting end components.

Both come with the certified bracket of :func:`planner.imdp.solve.solve`. With point
intervals (``lower == upper``) the model is an ordinary MDP and both are its maximal
satisfaction probability.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.errors import UnknownPropositionError
from planner.imdp.analysis import satisfaction
from planner.imdp.model import IMDP
from planner.imdp.product import ProductIMDP
from planner.imdp.solve import Solution, ValueIteration
from planner.ltl.budget import TranslationLimits
from planner.ltl.parser import parse
from planner.ltl.syntax import to_string
from planner.ltl.translate import translate
from planner.modes import Adversary


@dataclass(frozen=True)
class LTLCheck:
    """Result of :func:`check_ltl`.

    Attributes:
        values, lower, upper: ``(n_states,)`` per *model* state: the satisfaction
            probability of a run starting there (``values == lower``) and its bracket.
        initial: the model's initial states.
        automaton_states: size of the Rabin automaton.
        product: the product it was solved on; ``solution`` its solution.
    """

    values: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    initial: np.ndarray
    automaton_states: int
    product: ProductIMDP
    solution: Solution

    @property
    def converged(self) -> bool:
        return self.solution.converged


def check_ltl(
    model: IMDP,
    formula: str,
    optimistic: bool = False,
    algorithm: ValueIteration | None = None,
    limits: TranslationLimits | None = None,
) -> LTLCheck:
    """Satisfaction probability of ``formula`` from every state of ``model``; ``limits``
    bound the translation (default :class:`planner.ltl.budget.TranslationLimits`).

    Raises:
        LTLSyntaxError: the formula does not parse.
        UnknownPropositionError: the formula names a proposition that is not one of the
            model's labels.
        TranslationLimitError: the translation exceeds ``limits``.
        ProductError: the product would exceed
            :func:`planner.imdp.product.check_product_size`.
    """
    f = parse(formula)
    props = sorted(f.propositions())
    missing = [p for p in props if p not in model.propositions]
    if missing:
        have = ", ".join(model.propositions) if model.propositions else "none"
        raise UnknownPropositionError(
            f"formula {to_string(f)!r} uses proposition {missing[0]!r}, which is not a label "
            f"of the model (its labels: {have})"
        )
    automaton = translate(f, props, limits)
    product = ProductIMDP(model, automaton)
    adversary = Adversary.OPTIMISTIC if optimistic else Adversary.PESSIMISTIC
    sol = satisfaction(product, adversary, algorithm=algorithm)
    entry = (
        np.arange(model.n_states, dtype=np.int64) * product.n_q
        + automaton.transitions[automaton.initial, product.letters]
    )
    return LTLCheck(
        values=sol.values[entry],
        lower=sol.lower[entry],
        upper=sol.upper[entry],
        initial=model.initial.copy(),
        automaton_states=automaton.n_states,
        product=product,
        solution=sol,
    )
