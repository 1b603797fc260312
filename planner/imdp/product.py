"""The multi-task product IMDP (MT-PIMDP) of an IMDP, a Rabin automaton and a reward: a model.

Per docs/design.md the automaton reads the label of the state being *entered*: the product
transition ``(s, q) --a--> (s', q')`` has the interval of ``s --a--> s'`` and
``q' = delta(q, L(s'))``; the initial product state is ``(s0, delta(q0, L(s0)))``.
Product state ``(s, q)`` has index ``s * n_q + q``. The reward ``W(s)`` of a model state
is carried to every ``(s, q)`` and is collected on landing.

Acceptance is Rabin with pairs ``(G_i, B_i)`` of automaton states lifted to
``S x G_i``, ``S x B_i``.

:class:`ProductIMDP` holds the data and answers questions about the automaton side of a
product state (its automaton state, the letter read on entering it, whether the automaton
state is a sink, the next product state after a landing). What is computed *on* the model
(failure states, satisfaction, end components, sub-models) is in
:mod:`planner.imdp.analysis`; the synthesis that composes it in :mod:`planner.synthesis`.
"""

from __future__ import annotations

import numba
import numpy as np

from planner._util.threads import in_halves
from planner.automaton import RabinAutomaton
from planner.errors import ProductError
from planner.imdp.kernels.search import SPLIT_ENTRIES
from planner.imdp.model import IMDP

#: Most product states ``n_states x n_q`` and transitions (successor entries of the model
#: times ``n_q``) built: a product of 2.56e7 transitions took 4.3 GB and 110 s to check.
MAX_PRODUCT_STATES = 1 << 22
MAX_PRODUCT_ENTRIES = 1 << 24


def base_states(n_base: int, n_q: int) -> np.ndarray:
    """The base-model state of every product state: product state ``s * n_q + q`` pairs base
    state ``s`` with automaton state ``q`` (also before any product is built, e.g. to size a
    learner's tables)."""
    return np.arange(n_base * n_q) // n_q


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
        layout = _product_layout(model, delta, self.letters, nq)
        init = model.initial * nq + delta[automaton.initial, self.letters[model.initial]]
        # every model state's rows once per automaton state, in the order (s, q, a, t):
        # product state s * nq + q and successors t * nq + q' come out sorted, and the
        # bounds are the model's (already checked)
        self.model: IMDP = IMDP._trusted(
            model.n_states * nq,
            *layout[:6],
            entry_row=layout[6],
            row_sums=layout[7:],
            n_actions=model.n_actions,
            label_matrix=np.repeat(model.label_matrix, nq, axis=0),
            propositions=model.propositions,
            initial=init,
            action_names=model.action_names,
            tolerance=model.tolerance,
        )
        self.reward: np.ndarray = np.repeat(w, nq)
        """``W`` per product state."""
        self.base_state: np.ndarray = base_states(self.model.n_states // nq, nq)
        self.automaton_state: np.ndarray = np.arange(self.model.n_states) % nq
        self.good: tuple[np.ndarray, ...] = tuple(
            np.isin(self.automaton_state, sorted(p.good)) for p in automaton.pairs
        )
        self.bad: tuple[np.ndarray, ...] = tuple(
            np.isin(self.automaton_state, sorted(p.bad)) for p in automaton.pairs
        )

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
        return int(self.steps(np.asarray(product_state), np.asarray(next_state)))

    def steps(self, product_states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """:meth:`step` elementwise: ``next * n_q + delta(q, L(next))``."""
        q = self.automaton.transitions[product_states % self.n_q, self.letters[next_states]]
        return next_states * self.n_q + q

    def automaton_state_of(self, product_state: int) -> int:
        """Automaton state ``q`` of product state ``(s, q)``."""
        return int(product_state) % self.n_q

    def base_state_of(self, product_state: int) -> int:
        """Model state ``s`` of product state ``(s, q)``."""
        return int(product_state) // self.n_q

    def letter_of(self, product_state: int) -> int:
        """Automaton letter of the label of the model state of ``product_state`` (the letter
        the automaton read on entering it)."""
        return int(self.letters[int(product_state) // self.n_q])

    @property
    def absorbing(self) -> np.ndarray:
        """``(n_states,)`` mask of the product states whose automaton state is a sink (it
        stays itself under every letter): a run that enters one has settled the formula,
        in success or violation."""
        table = self.automaton.transitions
        sink = (table == np.arange(self.n_q)[:, None]).all(axis=1)
        return sink[self.automaton_state]

    def good_matrix(self) -> np.ndarray:
        """``(n_pairs, n_states)`` the Rabin pairs' ``G_i`` lifted to the product."""
        if not self.good:
            return np.zeros((0, self.n_states), dtype=bool)
        return np.stack(self.good)

    def bad_matrix(self) -> np.ndarray:
        """``(n_pairs, n_states)`` the Rabin pairs' ``B_i`` lifted to the product."""
        if not self.bad:
            return np.zeros((0, self.n_states), dtype=bool)
        return np.stack(self.bad)


def _product_layout(
    model: IMDP, delta: np.ndarray, letters: np.ndarray, nq: int
) -> tuple[np.ndarray, ...]:
    """Rows and entries of the product, in the model's internal layout: per model state
    ``s`` and automaton state ``q``, the rows of ``s`` with successors
    ``t * nq + delta[q, letters[t]]``. Returns ``(row_state, row_action, row_ptr,
    successor, lower, upper, entry_row, row_lower_sum, row_upper_sum)``: a product row's
    bound sums are its model row's."""
    m = model
    # product rows and entries before each model state
    row_start = m.state_ptr * nq
    entry_start = m.row_ptr[m.state_ptr] * nq
    out = _layout_arrays(int(row_start[-1]), int(entry_start[-1]))
    fields = (m.state_ptr, m.row_ptr, m.row_action, m.successor, m.lower, m.upper)
    fields += (m.row_lower_sum, m.row_upper_sum, delta, letters, nq, row_start, entry_start)
    n = m.n_states
    if entry_start[-1] < SPLIT_ENTRIES:
        _layout_states(*fields, 0, n, *out)
    else:
        in_halves(
            lambda first, last: _layout_states(*fields, first, last, *out), entry_start, "index"
        )
    out[2][-1] = entry_start[-1]
    return out


@numba.njit(cache=True, nogil=True)
def _layout_arrays(n_rows, n_entries):
    # numba's allocator: numpy would advise huge pages for these (see entries.py)
    return (
        np.empty(n_rows, dtype=np.int64),
        np.empty(n_rows, dtype=np.int64),
        np.empty(n_rows + 1, dtype=np.int64),
        np.empty(n_entries, dtype=np.int64),
        np.empty(n_entries),
        np.empty(n_entries),
        np.empty(n_entries, dtype=np.int64),
        np.empty(n_rows),
        np.empty(n_rows),
    )


@numba.njit(cache=True, nogil=True)
def _layout_states(
    state_ptr,
    row_ptr,
    row_action,
    successor,
    lower,
    upper,
    sum_lo,
    sum_up,
    delta,
    letters,
    nq,
    row_start,
    entry_start,
    first,
    last,
    p_state,
    p_action,
    p_ptr,
    p_succ,
    p_lo,
    p_up,
    p_row,
    p_sum_lo,
    p_sum_up,
):
    """Fill the product rows of the model states ``[first, last)``."""
    for s in range(first, last):
        r_out = row_start[s]
        e_out = entry_start[s]
        for q in range(nq):
            for r in range(state_ptr[s], state_ptr[s + 1]):
                p_state[r_out] = s * nq + q
                p_action[r_out] = row_action[r]
                p_ptr[r_out] = e_out
                p_sum_lo[r_out] = sum_lo[r]
                p_sum_up[r_out] = sum_up[r]
                for e in range(row_ptr[r], row_ptr[r + 1]):
                    t = successor[e]
                    p_succ[e_out] = t * nq + delta[q, letters[t]]
                    p_lo[e_out] = lower[e]
                    p_up[e_out] = upper[e]
                    p_row[e_out] = r_out
                    e_out += 1
                r_out += 1
