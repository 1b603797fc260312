"""Empirical audit of transition intervals against sampled successor frequencies.

For each audited (state, action) pair the caller samples ``n`` hops and counts the successors.
A triple (state, action, successor) passes when its empirical frequency ``f`` lies in
``[lower - m, upper + m]``, ``m = z * sqrt(1 / (4 n))`` the two-sided binomial margin at the
given confidence with the worst-case variance ``p (1 - p) <= 1/4`` (normal approximation,
``z = Phi^-1((1 + confidence) / 2)``). Triples without an interval row have bounds ``[0, 0]``.
The audited triples are those with an interval row or at least one observed landing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri

from planner.errors import IntervalError
from planner.intervals import TransitionIntervals


@dataclass(frozen=True)
class Offender:
    """A triple outside its widened interval; ``excess`` is how far outside (>= 0)."""

    state: int
    action: int
    successor: int
    frequency: float
    lower: float
    upper: float
    excess: float


@dataclass(frozen=True)
class AuditResult:
    """``fraction`` of audited triples inside ``[lower - margin, upper + margin]``."""

    fraction: float
    num_triples: int
    margin: np.ndarray
    offenders: tuple[Offender, ...]


def audit_counts(
    intervals: TransitionIntervals,
    state: np.ndarray,
    action: np.ndarray,
    counts: np.ndarray,
    *,
    confidence: float = 0.99,
) -> AuditResult:
    """Audit sampled pairs: ``state``, ``action`` ``(P,)``, ``counts`` ``(P, num_states)``
    successor counts (each row sums to its number of samples). Offenders are sorted by
    decreasing excess."""
    state = np.asarray(state, dtype=np.int64)
    action = np.asarray(action, dtype=np.int64)
    counts = np.asarray(counts)
    p = state.shape[0]
    if action.shape != (p,) or counts.shape != (p, intervals.num_states):
        raise IntervalError(
            f"need state, action of shape (P,) and counts of shape (P, {intervals.num_states}), "
            f"got {state.shape}, {action.shape}, {counts.shape}"
        )
    if (counts < 0).any() or counts.dtype.kind not in "iu":
        raise IntervalError("counts must be non-negative integers")
    n = counts.sum(axis=1)
    if (n == 0).any():
        raise IntervalError(f"pair {int(np.flatnonzero(n == 0)[0])} has no samples")
    if not 0.0 < confidence < 1.0:
        raise IntervalError(f"confidence must lie in (0, 1), got {confidence}")
    z = float(ndtri(0.5 * (1.0 + confidence)))
    margin = z * np.sqrt(0.25 / n)
    lo = np.zeros(counts.shape)
    hi = np.zeros(counts.shape)
    listed = np.zeros(counts.shape, dtype=bool)
    key = {(int(s), int(a)): k for k, (s, a) in enumerate(zip(state, action, strict=True))}
    if len(key) != p:
        raise IntervalError("each (state, action) pair may be audited only once")
    pair_of = np.full(intervals.state.shape, -1, dtype=np.int64)
    code = intervals.state * (int(intervals.action.max(initial=0)) + 1) + intervals.action
    wanted = state * (int(intervals.action.max(initial=0)) + 1) + action
    order = np.argsort(wanted)
    pos = np.searchsorted(wanted[order], code)
    hit = (pos < p) & (wanted[order][np.minimum(pos, p - 1)] == code)
    pair_of[hit] = order[pos[hit]]
    sel = pair_of >= 0
    lo[pair_of[sel], intervals.successor[sel]] = intervals.lower[sel]
    hi[pair_of[sel], intervals.successor[sel]] = intervals.upper[sel]
    listed[pair_of[sel], intervals.successor[sel]] = True
    freq = counts / n[:, None]
    audited = listed | (counts > 0)
    m = margin[:, None]
    excess = np.maximum(lo - m - freq, freq - hi - m).clip(min=0.0)
    bad = audited & (excess > 0)
    rows, cols = np.nonzero(bad)
    order = np.argsort(-excess[rows, cols], kind="stable")
    offenders = tuple(
        Offender(
            int(state[r]),
            int(action[r]),
            int(c),
            float(freq[r, c]),
            float(lo[r, c]),
            float(hi[r, c]),
            float(excess[r, c]),
        )
        for r, c in zip(rows[order], cols[order], strict=True)
    )
    total = int(audited.sum())
    return AuditResult(1.0 - len(offenders) / max(total, 1), total, margin, offenders)
