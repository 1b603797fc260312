"""What a finite run has settled about an LTL formula, read off its Rabin automaton.

A run of the product is a finite prefix ``u`` of an infinite word; the automaton state ``q``
reached after ``u`` decides what the prefix settles:

* **accepted** (``q`` in the *accepting region*): every continuation ``w`` is accepted, i.e.
  every run of the automaton from ``q`` (over every input) is accepting. For a deterministic
  complete automaton that holds iff no strongly connected set of states reachable from ``q``
  is *rejecting* (meets, for every pair ``(G_i, B_i)``, no ``G_i`` state or some ``B_i``
  state): the Streett emptiness check of the complement, by recursive SCC decomposition.
  Accepting sinks are the simplest case; ``G a`` reaches none, but ``F a`` after an ``a`` does.
* **rejected** (``q`` in the *rejecting region*): no continuation is accepted: no strongly
  connected set reachable from ``q`` meets some ``G_i`` and avoids ``B_i`` (Rabin emptiness:
  per pair, the nontrivial SCCs of the graph without ``B_i`` that hold a ``G_i`` state).
* **open**: otherwise; what is left is an obligation on the infinite future (the
  recurrence/persistence part of the formula, e.g. "visit ``a`` infinitely often").

A finite run that ends open is judged by its last *window*: the lasso word
``u' (window)^omega`` (the prefix up to the window, then the window repeated forever) is
accepted iff the automaton, reading the window again and again from the state at the window's
start, settles into a cycle of states whose set is accepting (:func:`window_accepts`). That
is the run's outcome ``"satisfying"``: "the run behaves, in its last window, as a run that
satisfies the formula", with the remaining obligation that it keeps doing so forever.

Everything here depends on the automaton only (its table and pairs), never on a model; the
regions are over all letters of ``2^AP``, including letter combinations a given world may not
have.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from planner.automaton import RabinAutomaton
from planner.modes import Outcome

ACCEPTED = "accepted"
REJECTED = "rejected"
OPEN = "open"


def _graph(automaton: RabinAutomaton, keep: np.ndarray, letters: np.ndarray) -> sp.csr_matrix:
    """The automaton's state graph (an edge ``q -> delta(q, l)`` for every letter ``l`` of
    the mask ``letters``) restricted to the states ``keep``."""
    table = automaton.transitions[:, letters]
    n = automaton.n_states
    src = np.repeat(np.arange(n), table.shape[1])
    dst = table.ravel()
    ok = keep[src] & keep[dst]
    return sp.csr_matrix((np.ones(ok.sum(), dtype=np.int8), (src[ok], dst[ok])), shape=(n, n))


def _cycles(g: sp.csr_matrix, keep: np.ndarray) -> list[np.ndarray]:
    """The nontrivial SCCs of ``g`` among ``keep`` (more than one state, or a self-loop)."""
    _, comp = connected_components(g, directed=True, connection="strong")
    loops = g.diagonal() > 0
    out = []
    for c in np.unique(comp[keep]):
        members = np.flatnonzero((comp == c) & keep)
        if members.size > 1 or loops[members[0]]:
            out.append(members)
    return out


def _reaches(g: sp.csr_matrix, target: np.ndarray) -> np.ndarray:
    """States of ``g`` with a path to a ``target`` state (``target`` included)."""
    n = g.shape[0]
    out = target.copy()
    rev = g.T.tocsr()
    for t in np.flatnonzero(target):
        out[breadth_first_order(rev, int(t), directed=True, return_predecessors=False)] = True
    return out[:n]


@dataclass(frozen=True)
class AutomatonVerdicts:
    """The accepting and rejecting regions of a Rabin automaton (see the module docstring).

    Attributes:
        automaton: the automaton judged.
        excluded: a proposition whose letters no continuation reads (``None``: all letters
            count). The runner passes the hazard label: the world ends every run that lands
            on a hazard cell in violation, so only hazard-free continuations are judged
            (``F goal & G !haz`` succeeds once the goal is reached).
    """

    automaton: RabinAutomaton
    excluded: str | None = None

    @cached_property
    def letters(self) -> np.ndarray:
        """``(n_letters,)`` mask of the letters continuations may read."""
        a = self.automaton
        ok = np.ones(a.n_letters, dtype=bool)
        if self.excluded is not None and self.excluded in a.propositions:
            bit = a.propositions.index(self.excluded)
            ok &= (np.arange(a.n_letters) >> bit & 1) == 0
        return ok

    def _all(self, keep: np.ndarray | None = None) -> sp.csr_matrix:
        n = self.automaton.n_states
        return _graph(
            self.automaton, np.ones(n, dtype=bool) if keep is None else keep, self.letters
        )

    def _rejecting_cores(self, keep: np.ndarray) -> np.ndarray:
        """States on rejecting strongly connected sets inside ``keep`` (Streett emptiness:
        a set that satisfies pair ``i`` must lose its ``G_i`` states to lose the pair)."""
        n = self.automaton.n_states
        good, bad = self._masks()
        rejecting = np.zeros(n, dtype=bool)
        stack = [keep.copy()]
        while stack:
            part = stack.pop()
            for members in _cycles(self._all(part), part):
                inside = np.zeros(n, dtype=bool)
                inside[members] = True
                won = (good & inside).any(axis=1) & ~(bad & inside).any(axis=1)
                if not won.any():
                    rejecting |= inside
                else:
                    stack.append(inside & ~good[won].any(axis=0))
        return rejecting

    def _masks(self) -> tuple[np.ndarray, np.ndarray]:
        a = self.automaton
        n = a.n_states
        good = [np.isin(np.arange(n), sorted(p.good)) for p in a.pairs]
        bad = [np.isin(np.arange(n), sorted(p.bad)) for p in a.pairs]
        return np.array(good).reshape(-1, n), np.array(bad).reshape(-1, n)

    @cached_property
    def accepting_region(self) -> np.ndarray:
        """``(n_states,)``: states from which every continuation is accepted."""
        n = self.automaton.n_states
        return ~_reaches(self._all(), self._rejecting_cores(np.ones(n, dtype=bool)))

    @cached_property
    def rejecting_region(self) -> np.ndarray:
        """``(n_states,)``: states from which no continuation is accepted."""
        n = self.automaton.n_states
        return ~_reaches(self._all(), self._accepting_cores(np.ones(n, dtype=bool)))

    def _accepting_cores(self, keep: np.ndarray) -> np.ndarray:
        """States on accepting strongly connected sets inside ``keep`` (Rabin emptiness: per
        pair, the nontrivial SCCs without ``B_i`` states that hold a ``G_i`` state)."""
        good, bad = self._masks()
        core = np.zeros(self.automaton.n_states, dtype=bool)
        for g, b in zip(good, bad, strict=True):
            part = keep & ~b
            for members in _cycles(self._all(part), part):
                if g[members].any():
                    core[members] = True
        return core

    @cached_property
    def open_region(self) -> np.ndarray:
        """``(n_states,)``: states neither accepting nor rejecting."""
        return ~self.accepting_region & ~self.rejecting_region

    @cached_property
    def safety_remaining(self) -> np.ndarray:
        """``(n_states,)``: open states whose remaining obligation is pure safety: every
        continuation that stays open forever is accepted (only entering the rejecting region
        fails). Elsewhere among the open states the obligation is recurrence or persistence
        (something must happen infinitely often, or from some point on)."""
        op = self.open_region
        return op & ~_reaches(self._all(op), self._rejecting_cores(op))

    def verdict(self, state: int) -> str:
        """:data:`ACCEPTED`, :data:`REJECTED` or :data:`OPEN` for automaton state ``state``."""
        if self.accepting_region[state]:
            return ACCEPTED
        if self.rejecting_region[state]:
            return REJECTED
        return OPEN

    @cached_property
    def guarantee_remaining(self) -> np.ndarray:
        """``(n_states,)``: open states from which no run staying open is accepted: the run
        must still reach the accepting region (a co-safe obligation such as ``F goal``)."""
        op = self.open_region
        return op & ~_reaches(self._all(op), self._accepting_cores(op))

    def obligation(self, state: int) -> str:
        """What an open ``state`` still asks of the future: ``"guarantee"`` (something must
        still happen, :attr:`guarantee_remaining`), ``"safety"`` (nothing bad may ever
        happen, :attr:`safety_remaining`) or ``"recurrence"`` (something must happen
        infinitely often, or hold from some point on); ``""`` for a settled state."""
        if not self.open_region[state]:
            return ""
        if self.guarantee_remaining[state]:
            return "guarantee"
        return "safety" if self.safety_remaining[state] else "recurrence"


def window_accepts(automaton: RabinAutomaton, start: int, letters: np.ndarray) -> bool:
    """Whether reading ``letters`` (a non-empty window) forever from automaton state
    ``start`` is an accepting run: iterate the window until its start state repeats; the
    states visited in the repeating blocks are the run's infinitely-often set."""
    letters = np.asarray(letters, dtype=np.int64)
    if letters.size == 0:
        raise ValueError("the window must hold at least one letter")
    table = automaton.transitions
    s = int(start)
    seen: dict[int, int] = {}
    blocks: list[set[int]] = []
    while s not in seen:
        seen[s] = len(blocks)
        block = set()
        for letter in letters:
            s = int(table[s, letter])
            block.add(s)
        blocks.append(block)
    inf = set().union(*blocks[seen[s] :])
    return automaton.is_accepting_cycle(inf)


def pair_visits(automaton: RabinAutomaton, states: np.ndarray) -> tuple[int, ...]:
    """Per Rabin pair, how many of the automaton ``states`` (a run's window) lie in ``G_i``."""
    states = np.asarray(states, dtype=np.int64)
    return tuple(int(np.isin(states, sorted(p.good)).sum()) for p in automaton.pairs)


OBLIGATIONS: tuple[str, ...] = ("", "guarantee", "safety", "recurrence")
"""Values of :attr:`MissionReport.obligation` (``""``: the run settled the formula)."""


@dataclass(frozen=True)
class MissionReport:
    """What a run's end says about its formula (see the module docstring).

    Attributes:
        verdict: :data:`ACCEPTED`, :data:`REJECTED` or :data:`OPEN` at the end.
        obligation: what an open end still owes (:meth:`AutomatonVerdicts.obligation`).
        window: hops in the judged last window (0 for a settled run).
        window_accepted: whether the last window repeated forever satisfies the formula.
        pair_visits: per Rabin pair, how many hops of the last window landed in ``G_i``.
        label_visits: per proposition of the automaton, how many hops of the last window
            landed in a cell carrying it.
        in_accepting_component: whether the run ended inside a robustly accepting end
            component of its last synthesis (``None``: not asked).
    """

    verdict: str
    obligation: str = ""
    window: int = 0
    window_accepted: bool = False
    pair_visits: tuple[int, ...] = ()
    label_visits: dict[str, int] = field(default_factory=dict)
    in_accepting_component: bool | None = None


class MissionMonitor:
    """Follows one run's automaton states and judges it: the outcome rule of the runner.

    Args:
        verdicts: the automaton's regions (its ``excluded`` proposition: the hazard label).
        window: hops of the last window judged at the end of an open run (0: the last half
            of the run, at least one hop; a run's: :attr:`planner.config.RunConfig.window`).
    """

    def __init__(self, verdicts: AutomatonVerdicts, window: int) -> None:
        if window < 0:
            raise ValueError(f"window must be >= 0, got {window}")
        self.verdicts = verdicts
        self.window = int(window)
        self.states: list[int] = []
        self.letters: list[int] = []

    def start(self, state: int) -> str:
        """Begin a run in automaton state ``state`` (after the start cell's letter); returns
        its verdict."""
        self.states, self.letters = [int(state)], []
        return self.verdicts.verdict(int(state))

    def step(self, letter: int, state: int) -> str:
        """Record a hop that read ``letter`` into automaton state ``state``; its verdict."""
        self.letters.append(int(letter))
        self.states.append(int(state))
        return self.verdicts.verdict(int(state))

    def report(self, in_accepting_component: bool | None = None) -> MissionReport:
        """The report at the end of the run (open: the last window judged)."""
        a = self.verdicts.automaton
        q = self.states[-1]
        verdict = self.verdicts.verdict(q)
        if verdict != OPEN or not self.letters:
            return MissionReport(verdict, self.verdicts.obligation(q))
        n = len(self.letters)
        w = min(n, self.window) if self.window else max(1, n // 2)
        start = self.states[n - w]
        window = np.asarray(self.letters[n - w :], dtype=np.int64)
        bits = window[:, None] >> np.arange(len(a.propositions)) & 1
        return MissionReport(
            verdict,
            self.verdicts.obligation(q),
            w,
            window_accepts(a, start, window),
            pair_visits(a, np.asarray(self.states[n - w + 1 :])),
            dict(zip(a.propositions, (int(v) for v in bits.sum(axis=0)), strict=True)),
            in_accepting_component,
        )


def describe(report: MissionReport) -> tuple[Outcome, str]:
    """``(outcome, reason)`` of a run that ended at its step cap with ``report``:
    ``"satisfying"`` if its last window, repeated forever, satisfies the formula, else
    ``"timeout"``; the reason names what remains."""
    if not report.window_accepted:
        return Outcome.TIMEOUT, "step cap"
    visits = ", ".join(f"pair {i}: {v}" for i, v in enumerate(report.pair_visits))
    labels = ", ".join(f"{k}: {v}" for k, v in report.label_visits.items())
    ec = {True: "; in an accepting end component", False: "; outside every accepting end component"}
    where = ec.get(report.in_accepting_component, "")  # type: ignore[arg-type]
    if report.obligation == "safety":
        what = "nothing violated; the remaining obligation is to stay safe forever"
    else:
        what = "the remaining obligation is to repeat it infinitely often"
    return (
        Outcome.SATISFYING,
        f"{report.obligation}: the last {report.window} hops repeated forever satisfy the "
        f"formula (G visits {visits}; landings {labels}){where}; {what}",
    )
