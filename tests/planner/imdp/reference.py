"""An independent, deliberately simple implementation (per-state Python loops) used to
check the vectorised planner, plus a random model generator."""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from planner.imdp import IMDP


def random_imdp(
    rng: np.random.Generator,
    n_states: int = 25,
    n_actions: int = 3,
    max_succ: int = 4,
    zero_lower: bool = True,
    labels: bool = True,
) -> IMDP:
    """A random IMDP whose rows bracket 1 (an interval around a random distribution)."""
    s, a, t, lo, up = [0], [0], [0], [1.0], [1.0]  # state 0: an absorbing sink
    for q in range(1, n_states):
        acts = rng.choice(n_actions, size=rng.integers(1, n_actions + 1), replace=False)
        for act in acts:
            k = int(rng.integers(1, max_succ + 1))
            succ = rng.choice(n_states, size=k, replace=False)
            if rng.random() < 0.3 and 0 not in succ:
                succ[0] = 0
            p = rng.dirichlet(np.ones(k))
            lower = p * rng.uniform(0.3, 1.0, size=k)
            if zero_lower:
                lower[rng.random(k) < 0.4] = 0.0
            upper = np.minimum(1.0, p + rng.uniform(0.0, 0.3, size=k))
            s += [q] * k
            a += [int(act)] * k
            t += succ.tolist()
            lo += lower.tolist()
            up += upper.tolist()
    lab = None
    if labels:
        kind = rng.random(n_states)
        lab = [("goal",) if x < 0.1 else ("bad",) if x < 0.3 else () for x in kind]
        lab[0] = ()
    return IMDP(
        n_states, s, a, t, lo, up, n_actions=n_actions, labels=lab, propositions=("bad", "goal")
    )


def sticky_imdp(rng: np.random.Generator, n: int) -> IMDP:
    """One action per state, half the states with a self-loop, every lower bound positive:
    mass circulates long among states of nearly equal value."""
    s, t, lo, up = [], [], [], []
    for q in range(n):
        k = int(rng.integers(1, 4))
        succ = rng.choice(n, size=k, replace=False)
        if rng.random() < 0.5 and q not in succ:
            succ[0] = q
        p = rng.dirichlet(np.ones(k))
        lower = np.maximum(p * rng.uniform(0.2, 1.0, size=k), 1e-3)
        lower = lower / max(1.0, lower.sum() / 0.999)
        upper = np.maximum(np.minimum(1.0, p + rng.uniform(0.0, 0.3, size=k)), lower)
        if upper.sum() < 1.0:
            upper = np.minimum(1.0, upper / upper.sum() * 1.001)
        s += [q] * k
        t += succ.tolist()
        lo += lower.tolist()
        up += upper.tolist()
    kind = rng.random(n)
    labels = [("goal",) if x < 0.15 else ("bad",) if x < 0.35 else () for x in kind]
    return IMDP(n, s, [0] * len(s), t, lo, up, labels=labels, propositions=("bad", "goal"))


def side_by_side(a: IMDP, b: IMDP) -> IMDP:
    """The disjoint union of two models (``b``'s states after ``a``'s): no row of one
    reaches the other."""
    sa, aa, ta, la, ua = a.coo()
    sb, ab, tb, lb, ub = b.coo()
    return IMDP(
        a.n_states + b.n_states,
        np.concatenate([sa, sb + a.n_states]),
        np.concatenate([aa, ab]),
        np.concatenate([ta, tb + a.n_states]),
        np.concatenate([la, lb]),
        np.concatenate([ua, ub]),
        labels=list(a.labels) + list(b.labels),
        propositions=a.propositions,
    )


def rows_of(model: IMDP) -> dict[tuple[int, int], list[tuple[int, float, float]]]:
    out: dict[tuple[int, int], list[tuple[int, float, float]]] = {}
    s, a, t, lo, up = model.coo()
    for i in range(len(s)):
        out.setdefault((int(s[i]), int(a[i])), []).append((int(t[i]), float(lo[i]), float(up[i])))
    return out


def ref_expectation(row: list[tuple[int, float, float]], values, minimize: bool) -> float:
    entries = sorted(row, key=lambda e: values[e[0]], reverse=not minimize)
    rem = 1.0 - sum(e[1] for e in entries)
    total = 0.0
    for succ, lo, up in entries:
        give = min(up - lo, max(rem, 0.0))
        rem -= give
        total += (lo + give) * values[succ]
    return total


def ref_reach(
    model: IMDP,
    target: np.ndarray,
    avoid: np.ndarray,
    pessimistic: bool,
    maximize: bool = True,
    sweeps: int = 20000,
) -> np.ndarray:
    rows = rows_of(model)
    v = [1.0 if target[q] else 0.0 for q in range(model.n_states)]
    adv_min = maximize == pessimistic
    for _ in range(sweeps):
        new = list(v)
        for q in range(model.n_states):
            if target[q] or avoid[q]:
                continue
            vals = [ref_expectation(r, v, adv_min) for (s, _), r in rows.items() if s == q]
            new[q] = max(vals) if maximize else min(vals)
        diff = max(abs(x - y) for x, y in zip(new, v, strict=True))
        v = new
        if diff < 1e-14:
            break
    return np.array(v)


def ref_discounted(
    model: IMDP, reward: np.ndarray, gamma: float, pessimistic: bool, sweeps: int = 5000
) -> np.ndarray:
    rows = rows_of(model)
    v = [0.0] * model.n_states
    for _ in range(sweeps):
        target = [reward[q] + gamma * v[q] for q in range(model.n_states)]
        new = [
            max(ref_expectation(r, target, pessimistic) for (s, _), r in rows.items() if s == q)
            for q in range(model.n_states)
        ]
        diff = max(abs(x - y) for x, y in zip(new, v, strict=True))
        v = new
        if diff < 1e-13:
            break
    return np.array(v)


def slow_leak_imdp(
    rng: np.random.Generator, n_states: int = 7, leak: float = 1e-5, tolerance: float = 1e-9
) -> IMDP:
    """Random IMDP whose states keep ``1 - leak`` of their mass on themselves: value
    iteration from 0 creeps up by about ``leak`` per sweep. State 0 is a sink, state 1 the
    (absorbing) goal; the other states have two actions, each with a forced (``lower > 0``)
    leak into the sink, so no state but the goal has value 1. ``tolerance``: the model's
    bound tolerance (forced masses below it count as 0 in the graph analyses)."""
    s, a, t, lo, up = [0, 1], [0, 0], [0, 1], [1.0, 1.0], [1.0, 1.0]
    for q in range(2, n_states):
        for act in range(2):
            others = [x for x in range(1, n_states) if x != q]
            succ = np.concatenate(
                ([0], rng.choice(others, size=int(rng.integers(1, 4)), replace=False))
            )
            p = rng.dirichlet(np.ones(succ.size)) * leak
            lower = p * rng.uniform(0.3, 1.0, size=succ.size)
            lower[1:][rng.random(succ.size - 1) < 0.4] = 0.0
            upper = p * rng.uniform(1.0, 2.0, size=succ.size)
            s += [q] * (succ.size + 1)
            a += [act] * (succ.size + 1)
            t += [*succ.tolist(), q]
            lo += [*lower.tolist(), 1.0 - 3 * leak]
            up += [*upper.tolist(), 1.0 - 0.5 * leak]
    labels = [(), ("goal",)] + [()] * (n_states - 2)
    return IMDP(n_states, s, a, t, lo, up, n_actions=2, labels=labels, tolerance=tolerance)


def _robust_positive(rows: dict, target: np.ndarray, strategy: dict[int, int]) -> np.ndarray:
    """States from which the strategy reaches ``target`` with positive probability under
    every adversary (per-state fixpoint loop)."""
    x = target.copy()
    changed = True
    while changed:
        changed = False
        for q, act in strategy.items():
            if x[q]:
                continue
            row = rows[(q, act)]
            forced = any(lo > 0 and x[j] for j, lo, _ in row)
            out_up = sum(up for j, _, up in row if not x[j])
            touches = any(up > 0 and x[j] for j, _, up in row)
            if forced or (touches and out_up < 1.0 - 1e-12):
                x[q] = True
                changed = True
    return x


def ref_strategy_value(model: IMDP, target: np.ndarray, strategy: dict[int, int]) -> np.ndarray:
    """Worst-case reachability value of a memoryless strategy by linear programming.

    After the states where the adversary forces probability 0 are set to 0, the value is
    the greatest ``x`` with ``x_q <= min_p p . x`` for all strategy rows, written with the
    dual of the inner minimum: ``x_q <= l . x + (1 - sum l) t_q - sum_j (u_j - l_j) mu_qj``,
    ``mu_qj >= t_q - x_j``, ``mu >= 0``.
    """
    from scipy.optimize import linprog

    rows = rows_of(model)
    pos = _robust_positive(rows, target, strategy)
    val = np.where(target, 1.0, 0.0)
    live = [q for q in strategy if pos[q] and not target[q]]
    if not live:
        return val
    xi = {q: k for k, q in enumerate(live)}
    nx = len(live)
    ti = {q: nx + k for k, q in enumerate(live)}
    mu = {}
    for q in live:
        for j, _, _ in rows[(q, strategy[q])]:
            mu[(q, j)] = 2 * nx + len(mu)
    nv = 2 * nx + len(mu)
    a_ub, b_ub = [], []
    for q in live:
        row = rows[(q, strategy[q])]
        c = np.zeros(nv)
        rhs = 0.0
        c[xi[q]] += 1.0
        c[ti[q]] -= 1.0 - sum(lo for _, lo, _ in row)
        for j, lo, up in row:
            if j in xi:
                c[xi[j]] -= lo
            else:
                rhs += lo * val[j]
            c[mu[(q, j)]] += up - lo
            d = np.zeros(nv)
            d[ti[q]] = 1.0
            d[mu[(q, j)]] = -1.0
            r2 = 0.0
            if j in xi:
                d[xi[j]] -= 1.0
            else:
                r2 = val[j]
            a_ub.append(d)
            b_ub.append(r2)
        a_ub.append(c)
        b_ub.append(rhs)
    cost = np.zeros(nv)
    cost[:nx] = -1.0
    bounds = [(0.0, 1.0)] * nx + [(-1.0, 2.0)] * nx + [(0.0, None)] * len(mu)
    res = linprog(cost, A_ub=np.array(a_ub), b_ub=np.array(b_ub), bounds=bounds, method="highs")
    assert res.status == 0, res.message
    val[live] = res.x[:nx]
    return val


def memoryless_strategies(model: IMDP, target: np.ndarray):
    """Every memoryless strategy (a dict state -> action) on the non-target states."""
    from itertools import product as cartesian

    rows = rows_of(model)
    free = [q for q in range(model.n_states) if not target[q]]
    choices = [sorted(a for (s, a) in rows if s == q) for q in free]
    for combo in cartesian(*choices):
        yield dict(zip(free, combo, strict=True))


def ref_reach_by_strategies(model: IMDP, target: np.ndarray) -> np.ndarray:
    """Worst-case maximal reachability as the best of all memoryless strategies' values
    (:func:`ref_strategy_value`); no value iteration."""
    best = np.where(target, 1.0, 0.0)
    for strategy in memoryless_strategies(model, target):
        best = np.maximum(best, ref_strategy_value(model, target, strategy))
    return best


def exact_strategy_value(model: IMDP, target: np.ndarray, strategy: dict[int, int]) -> list:
    """Worst-case reachability value of a memoryless strategy in exact rational arithmetic
    (the floats of the model taken as the exact binary fractions they are), for models in
    which every strategy row leaks into a value-0 sink with a positive lower bound (no end
    components besides the sink: the Bellman operator has one fixed point). States without
    a path to the target are 0. Adversary policy iteration:
    sort the successors by value, hand out the remaining mass in that order, solve the
    chain exactly (Gauss-Jordan over ``Fraction``), until the values repeat."""
    rows = rows_of(model)
    n = model.n_states
    val = [Fraction(1) if target[q] else Fraction(0) for q in range(n)]
    reach = target.copy()  # states with a path (upper > 0) to the target; the rest are 0
    changed = True
    while changed:
        changed = False
        for q, act in strategy.items():
            if not reach[q] and any(up > 0 and reach[j] for j, _, up in rows[(q, act)]):
                reach[q] = changed = True
    free = [q for q in strategy if reach[q] and not target[q]]
    exact_rows = {
        q: [(j, Fraction(lo), Fraction(up)) for j, lo, up in rows[(q, strategy[q])]] for q in free
    }
    idx = {q: i for i, q in enumerate(free)}
    k = len(free)
    for _ in range(100):
        mat = [[Fraction(0)] * (k + 1) for _ in range(k)]
        for q in free:
            i = idx[q]
            mat[i][i] += 1
            rem = 1 - sum(lo for _, lo, _ in exact_rows[q])
            for j, lo, up in sorted(exact_rows[q], key=lambda e: val[e[0]]):
                p = lo + min(up - lo, max(rem, Fraction(0)))
                rem -= p - lo
                if j in idx:
                    mat[i][idx[j]] -= p
                else:
                    mat[i][k] += p * val[j]
        x = solve_rational(mat)
        new = list(val)
        for q in free:
            new[q] = x[idx[q]]
        if new == val:
            return val
        val = new
    raise AssertionError("adversary policy iteration did not settle")


def exact_reach_by_strategies(model: IMDP, target: np.ndarray) -> np.ndarray:
    """Worst-case maximal reachability, the best memoryless strategy's exact value
    (:func:`exact_strategy_value`), rounded to float at the end."""
    best = None
    for strategy in memoryless_strategies(model, target):
        v = exact_strategy_value(model, target, strategy)
        best = v if best is None else [max(a, b) for a, b in zip(best, v, strict=True)]
    return np.array([float(x) for x in best])


def solve_rational(mat: list[list[Fraction]]) -> list[Fraction]:
    """The solution of the ``k x (k + 1)`` augmented system ``mat`` (non-singular) by
    Gauss-Jordan elimination in rational arithmetic (``mat`` is overwritten)."""
    k = len(mat)
    for c in range(k):
        piv = next(r for r in range(c, k) if mat[r][c] != 0)
        mat[c], mat[piv] = mat[piv], mat[c]
        for r in range(k):
            if r != c and mat[r][c] != 0:
                f = mat[r][c] / mat[c][c]
                mat[r] = [a - f * b for a, b in zip(mat[r], mat[c], strict=True)]
    return [mat[i][k] / mat[i][i] for i in range(k)]
