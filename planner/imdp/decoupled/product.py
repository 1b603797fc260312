"""The product of a decoupled model with a Rabin automaton, and its satisfaction."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from planner.automaton import RabinAutomaton
from planner.errors import ProductError
from planner.imdp.decoupled.model import DecoupledIMDP
from planner.imdp.decoupled.reach import (
    certify_candidate,
    expandable,
    expanded_imdp,
    settled_values,
    solve_reach,
)
from planner.imdp.solve import Problem, ReachAvoid, Solution, Specification, ValueIteration, solve
from planner.modes import Adversary


class DecoupledProduct:
    """The product of a decoupled model with a Rabin automaton (the automaton reads the
    label of the state entered, as :class:`planner.imdp.product.ProductIMDP`); product
    state ``(s, q)`` has index ``s * n_q + q``, and its rows keep the model's per-axis
    intervals with the successor map composed with the automaton.

    :meth:`satisfaction` covers formulas whose automaton accepts by reaching an absorbing
    accepting state (co-safe formulas such as ``!Haz U Goal``): then the worst-case
    satisfaction is the worst-case reachability of those states.

    Raises:
        ProductError: an automaton proposition the model does not declare.
    """

    def __init__(self, model: DecoupledIMDP, automaton: RabinAutomaton) -> None:
        unknown = [p for p in automaton.propositions if p not in model.propositions]
        if unknown:
            raise ProductError(f"automaton propositions {unknown} are not labels of the model")
        nq = automaton.n_states
        self.base, self.automaton, self.n_q = model, automaton, nq
        bits = np.array([model.propositions.index(p) for p in automaton.propositions], int)
        self.letters = (
            (model.label_matrix[:, bits].astype(np.int64) << np.arange(bits.size)).sum(axis=1)
            if bits.size
            else np.zeros(model.n_states, dtype=np.int64)
        )
        delta = automaton.transitions
        rs = model.row_state
        counts = np.diff(model.state_ptr)
        # rows: per model state s, per q, the rows of s
        rows = np.concatenate(
            [
                np.tile(np.arange(model.state_ptr[s], model.state_ptr[s + 1]), nq)
                for s in range(model.n_states)
            ]
        )
        qs = np.concatenate([np.repeat(np.arange(nq), counts[s]) for s in range(model.n_states)])
        maps = model.maps
        pmaps = (
            maps[:, None, :, :] * nq
            + delta[np.arange(nq)[None, :, None, None], self.letters[maps][:, None, :, :]]
        )
        pmaps = pmaps.reshape(-1, maps.shape[1], maps.shape[2])
        axes = []
        for ptr, b, lo, up in model.axes:
            lens = np.diff(ptr)[rows]
            idx = np.concatenate([np.arange(ptr[r], ptr[r + 1]) for r in rows])
            axes += [np.concatenate(([0], np.cumsum(lens))), b[idx], lo[idx], up[idx]]
        init = model.initial * nq + delta[automaton.initial, self.letters[model.initial]]
        self.model = DecoupledIMDP(
            model.n_states * nq,
            rs[rows] * nq + qs,
            model.row_action[rows],
            *axes,
            pmaps,
            model.row_map[rows] * nq + qs,
            n_actions=model.n_actions,
            label_matrix=np.repeat(model.label_matrix, nq, axis=0),
            propositions=model.propositions,
            initial=init,
            action_names=model.action_names,
            tolerance=model.tolerance,
        )
        q_of = np.arange(self.model.n_states) % nq
        self.good = tuple(np.isin(q_of, sorted(p.good)) for p in automaton.pairs)
        self.bad = tuple(np.isin(q_of, sorted(p.bad)) for p in automaton.pairs)

    @property
    def n_states(self) -> int:
        return self.model.n_states

    @property
    def initial(self) -> int:
        return int(self.model.initial[0])

    def accepting_sink(self) -> np.ndarray:
        """Product states whose automaton state is absorbing and accepting (a pair with
        ``B`` empty and ``G`` closed under every letter).

        Raises:
            ProductError: if the automaton does not accept that way (not co-safe).
        """
        aut = self.automaton
        sinks = set()
        for p in aut.pairs:
            g = sorted(p.good)
            if p.bad or not g or not np.isin(aut.transitions[g], g).all():
                raise ProductError(
                    "decoupled models support formulas accepted by reaching an absorbing "
                    "accepting automaton state (co-safe formulas such as !Haz U Goal) only"
                )
            sinks |= set(g)
        return np.isin(np.arange(self.n_states) % self.n_q, sorted(sinks))

    def satisfaction(
        self,
        adversary: Adversary = Adversary.PESSIMISTIC,
        algorithm: ValueIteration | None = None,
    ) -> Solution:
        """Maximal satisfaction probability per product state against the ``adversary``
        (:class:`planner.modes.Adversary`; a plain string is accepted: worst case, ``P_check``,
        by default; the cooperating adversary gives the best case), certified: by sweeps
        with the exact operator; where their bracket does not close (a region the
        controller can circulate in, with equal values) and the model has at most
        ``_EXPAND_MAX_ROWS`` rows (the direct sweeps are then capped at ``_DIRECT_SWEEPS``:
        they can creep where mass leaks slowly), by strategy iteration on the exact operator
        (its lowered values the lower bound, a checked candidate from its values the upper),
        else on :func:`expanded_imdp` by :func:`planner.imdp.solve.solve` (at most
        ``_EXPANDED_SWEEPS`` sweeps) when the expansion is built (:func:`expandable`);
        otherwise the direct bracket, open."""
        pessimistic = Adversary(adversary) == Adversary.PESSIMISTIC
        target = self.accepting_sink()
        alg = ValueIteration() if algorithm is None else algorithm
        small = self.model.n_rows <= _EXPAND_MAX_ROWS
        direct = (
            replace(alg, max_iterations=min(alg.max_iterations, _DIRECT_SWEEPS)) if small else alg
        )
        sol = solve_reach(self.model, target, None, pessimistic, direct)
        if sol.converged or not small:
            return sol
        free = np.flatnonzero(~sol.fixed)
        out = settled_values(self.model, free, sol.lower, sol.lower, pessimistic)
        if out is not None:
            x, x_low = out
            # the strategy's lowered values bound from below, whether or not its candidate
            # from above is shown
            low = np.maximum(sol.lower, x_low)
            sol = replace(sol, values=low, lower=low)
            certified = certify_candidate(self.model, free, low, sol, pessimistic, alg, x)
            if certified is not None and certified.converged:
                return certified
        if not expandable(self.model):
            return sol
        big, n = expanded_imdp(self.model)
        spec = Specification(
            ReachAvoid(np.concatenate([target, np.zeros(big.n_states - n, bool)])),
            Adversary(adversary),
        )
        # capped: where interval iteration stalls on an expansion too large for strategy
        # iteration, the sweeps that follow creep (a 68k-state expansion: 133k sweeps and
        # 3 minutes for a bracket still [0, 1])
        capped = replace(alg, max_iterations=min(alg.max_iterations, _EXPANDED_SWEEPS))
        full = solve(Problem(big, spec), capped)
        return Solution(
            values=np.maximum(sol.lower, full.lower[:n]),
            strategy=np.where(full.strategy[:n] >= 0, full.strategy[:n], sol.strategy),
            residual=full.residual,
            iterations=sol.iterations + full.iterations,
            converged=full.converged,
            evaluations=full.evaluations,
            fixed=sol.fixed,
            lower=np.maximum(sol.lower, full.lower[:n]),
            # the direct bound is not shown: a certified expansion stands on its own
            upper=full.upper[:n] if full.converged else np.minimum(sol.upper, full.upper[:n]),
            upper_sweeps=sol.upper_sweeps + full.upper_sweeps,
        )


_EXPAND_MAX_ROWS = 20_000
"""Rows up to which an uncertified decoupled solve falls back to the expanded model."""

_EXPANDED_SWEEPS = 5_000
"""Sweeps of the solve on the expanded model (interval iteration's rounds included)."""

_DIRECT_SWEEPS = 200
"""Sweeps of the direct solve before the fallback (it can creep where mass leaks slowly)."""
