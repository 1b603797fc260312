"""LTL front end: parsing, simplification, translation to deterministic Rabin automata, HOA.

Public API::

    parse(formula: str) -> Formula
    Formula.propositions() -> frozenset[str]
    check_propositions(formula: str | Formula, allowed: Iterable[str]) -> Formula
    simplify(formula: Formula) -> Formula
    translate(formula: str | Formula, propositions: Sequence[str] | None = None)
        -> RabinAutomaton
    to_hoa(automaton, name=None) -> str;  from_hoa(text: str) -> RabinAutomaton
    to_dot(automaton, title=None) -> str
"""

from planner.ltl.dot import to_dot
from planner.ltl.hoa import from_hoa, to_hoa
from planner.ltl.parser import check_propositions, parse
from planner.ltl.simplify import simplify
from planner.ltl.syntax import Formula
from planner.ltl.translate import translate

__all__ = [
    "Formula",
    "check_propositions",
    "from_hoa",
    "parse",
    "simplify",
    "to_dot",
    "to_hoa",
    "translate",
]
