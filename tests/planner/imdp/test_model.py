import numpy as np
import pytest

from planner.errors import (
    DuplicateSuccessorError,
    IndexOutOfRangeError,
    IntervalBoundsError,
    MissingRowError,
    ModelError,
    RowSumError,
    UnknownLabelError,
)
from planner.imdp import IMDP


def two_state(**kw):
    args = dict(
        n_states=2,
        state=[0, 0, 1],
        action=[0, 0, 0],
        successor=[0, 1, 1],
        lower=[0.2, 0.3, 1.0],
        upper=[0.7, 0.8, 1.0],
    )
    args.update(kw)
    return IMDP(**args)


def test_layout_is_sorted_and_indexed():
    m = IMDP(
        2,
        [1, 0, 0, 0],
        [0, 1, 0, 0],
        [1, 1, 1, 0],
        [1, 1, 0.5, 0.5],
        [1, 1, 0.5, 0.5],
        labels=[("a",), ()],
    )
    assert m.n_rows == 3
    assert m.row_state.tolist() == [0, 0, 1]
    assert m.row_action.tolist() == [0, 1, 0]
    assert m.successor.tolist() == [0, 1, 1, 1]
    assert m.enabled.tolist() == [[True, True], [True, False]]
    assert m.row_index[0, 1] == 1 and m.row_index[1, 1] == -1
    assert m.states_labelled("a").tolist() == [True, False]


def test_lower_above_upper():
    with pytest.raises(IntervalBoundsError, match="state 0, action 0, successor 1"):
        two_state(lower=[0.2, 0.9, 1.0])


def test_bounds_outside_unit_interval():
    with pytest.raises(IntervalBoundsError, match="not inside"):
        two_state(upper=[0.7, 1.2, 1.0])
    with pytest.raises(IntervalBoundsError):
        two_state(lower=[-0.1, 0.3, 1.0])
    with pytest.raises(IntervalBoundsError):
        two_state(upper=[np.nan, 0.8, 1.0])


def test_row_not_bracketing_one():
    with pytest.raises(RowSumError, match="state 0, action 0"):
        two_state(upper=[0.4, 0.5, 1.0])
    with pytest.raises(RowSumError, match="sum of lower"):
        two_state(lower=[0.6, 0.6, 1.0], upper=[0.7, 0.8, 1.0])
    # within the stated tolerance is accepted
    two_state(upper=[0.5, 0.5 - 1e-10, 1.0])


def test_duplicate_successor():
    with pytest.raises(DuplicateSuccessorError, match="successor 1"):
        IMDP(2, [0, 0, 1], [0, 0, 0], [1, 1, 1], [0, 0, 1], [1, 1, 1])


def test_shuffled_entries_give_the_sorted_model_and_name_the_right_entry():
    rng = np.random.default_rng(4)
    n, n_act, k = 40, 3, 5
    state = np.repeat(np.arange(n), n_act * k)
    action = np.tile(np.repeat(np.arange(n_act), k), n)
    succ = np.concatenate([rng.choice(n, size=k, replace=False) for _ in range(n * n_act)])
    p = rng.dirichlet(np.ones(k), size=n * n_act).ravel()
    lo, up = 0.5 * p, np.minimum(1.0, 1.5 * p)
    key = np.lexsort((succ, action, state))
    ref = IMDP(n, state[key], action[key], succ[key], lo[key], up[key])
    shuffle = rng.permutation(state.size)
    args = (state[shuffle], action[shuffle], succ[shuffle], lo[shuffle], up[shuffle])
    m = IMDP(n, *args)
    for name in ("row_state", "row_action", "row_ptr", "successor", "lower", "upper"):
        np.testing.assert_array_equal(getattr(m, name), getattr(ref, name))
    # errors found after the sorting still name the entry as given
    dup = succ[shuffle].copy()
    row = (state[shuffle] == 7) & (action[shuffle] == 2)
    first, second = np.flatnonzero(row)[:2]
    dup[second] = dup[first]
    with pytest.raises(
        DuplicateSuccessorError, match=f"state 7, action 2 lists successor {dup[first]} "
    ):
        IMDP(n, args[0], args[1], dup, args[3], args[4])
    low = args[4].copy()
    low[row] = 0.1
    with pytest.raises(RowSumError, match="state 7, action 2:"):
        IMDP(n, args[0], args[1], args[2], args[3], np.maximum(low, args[3]))


def test_unknown_label():
    with pytest.raises(UnknownLabelError, match="state 1"):
        two_state(labels=[(), ("goal",)], propositions=("Haz",))
    m = two_state(labels=[(), ("goal",)])
    with pytest.raises(UnknownLabelError):
        m.states_labelled("Haz")


def test_label_sets_of_every_kind_give_each_state_its_own_set():
    """The constructor converts each distinct label set once; every state still gets the
    set its own labels give, whatever container holds them (equal keys that stringify
    differently, such as ``(1,)`` and ``(1.0,)``, stay apart)."""
    n = 9
    given = [
        ("a", "b"),
        ["b"],
        "ab",  # a string is an iterable of one-letter labels, as any iterable
        (x for x in ("c",)),
        frozenset({"a"}),
        ("a", "b"),
        (1,),
        (1.0,),
        np.array(["b", "c"]),
    ]
    expected = [
        {"a", "b"},
        {"b"},
        {"a", "b"},
        {"c"},
        {"a"},
        {"a", "b"},
        {"1"},
        {"1.0"},
        {"b", "c"},
    ]
    m = IMDP(n, np.arange(n), np.zeros(n, int), np.arange(n), np.ones(n), np.ones(n), labels=given)
    assert m.propositions == ("1", "1.0", "a", "b", "c")
    assert [set(ls) for ls in m.labels] == expected
    col = {p: i for i, p in enumerate(m.propositions)}
    for i, want in enumerate(expected):
        assert {p for p in m.propositions if m.label_matrix[i, col[p]]} == want
    assert m.states_labelled("b").tolist() == [bool({"b"} & w) for w in expected]
    # more propositions than a 64-bit code of a row holds
    many = [(f"p{i:02d}", f"p{(i + 1) % 70:02d}") for i in range(70)] + [()] * 2
    k = len(many)
    wide = IMDP(
        k, np.arange(k), np.zeros(k, int), np.arange(k), np.ones(k), np.ones(k), labels=many
    )
    assert len(wide.propositions) == 70
    assert [set(ls) for ls in wide.labels] == [set(ls) for ls in many]
    # the first state whose set holds an undeclared label is named
    with pytest.raises(UnknownLabelError, match="state 3 carries label"):
        IMDP(
            n,
            np.arange(n),
            np.zeros(n, int),
            np.arange(n),
            np.ones(n),
            np.ones(n),
            labels=[("a",)] * 3 + [("z",), ("a",)] + [("z",)] * 4,
            propositions=("a",),
        )


def test_index_out_of_range_and_missing_rows():
    with pytest.raises(IndexOutOfRangeError, match="successor 2"):
        two_state(successor=[0, 2, 1])
    with pytest.raises(IndexOutOfRangeError, match="action"):
        two_state(n_actions=1, action=[0, 0, 1])
    with pytest.raises(MissingRowError, match="state 2"):
        two_state(n_states=3)
    with pytest.raises(IndexOutOfRangeError, match="initial"):
        two_state(initial=[5])
    with pytest.raises(ModelError, match="equal length"):
        two_state(lower=[0.2, 0.3])
