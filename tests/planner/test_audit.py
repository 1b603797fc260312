from __future__ import annotations

import numpy as np
import pytest

from planner.audit import audit_counts
from planner.errors import IntervalError
from planner.intervals import TransitionIntervals


def _intervals() -> TransitionIntervals:
    # state 0, action 1: successor 0 in [0.2, 0.4], successor 1 in [0.4, 0.8]
    return TransitionIntervals(
        state=np.array([0, 0]),
        action=np.array([1, 1]),
        successor=np.array([0, 1]),
        lower=np.array([0.2, 0.4]),
        upper=np.array([0.4, 0.8]),
        num_states=3,
    )


def test_audit_passes_inside_and_flags_outside_with_the_binomial_margin():
    n = 400
    margin = 2.5758293 * np.sqrt(0.25 / n)  # 0.0644
    inside = audit_counts(_intervals(), [0], [1], np.array([[100, 300, 0]]))
    assert inside.fraction == 1.0 and inside.num_triples == 2
    assert inside.margin[0] == pytest.approx(margin)
    # frequency 0.5 of successor 0: 0.1 above its upper bound, outside the margin;
    # 0.05 in the unlisted successor 2: bounds [0, 0], within the margin
    res = audit_counts(_intervals(), [0], [1], np.array([[200, 180, 20]]))
    assert res.num_triples == 3
    assert [o.successor for o in res.offenders] == [0]
    assert res.offenders[0].excess == pytest.approx(0.5 - 0.4 - margin)
    assert res.fraction == pytest.approx(2 / 3)


def test_audit_rejects_bad_input():
    with pytest.raises(IntervalError, match="counts of shape"):
        audit_counts(_intervals(), [0], [1], np.array([[1, 2]]))
    with pytest.raises(IntervalError, match="no samples"):
        audit_counts(_intervals(), [0], [1], np.array([[0, 0, 0]]))
    with pytest.raises(IntervalError, match="only once"):
        audit_counts(_intervals(), [0, 0], [1, 1], np.ones((2, 3), dtype=int))
