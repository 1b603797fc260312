"""An independent, deliberately simple implementation (per-state Python loops) used to
check the vectorised planner, plus a random model generator."""

from __future__ import annotations

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
