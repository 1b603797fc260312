"""Brute-force references for Rabin objectives on small interval MDPs (independent of the
planner's graph algorithms: plain Python loops, vertex enumeration, linear programs).

* :func:`vertices`: the vertices of a row's polytope ``{l <= p <= u, sum p = 1}``.
* :func:`product_mdp`: the product of an IMDP with a Rabin automaton, as plain dicts.
* :func:`strategy_value`: the worst case of a memoryless strategy against the *dynamic*
  adversary: the adversary's maximal probability of the Streett condition in the vertex
  MDP of the strategy, by its end components (refined for Streett) and a linear program.
* :func:`game_value`: the best of all memoryless strategies' worst cases (the controller of
  a Rabin game has optimal memoryless strategies on the product).
* :func:`mdp_satisfaction`: the maximal satisfaction of an ordinary MDP (accepting end
  components and a linear program); :func:`static_value`: the minimum of it over the
  vertex resolutions of the base model's rows (a *static* adversary).
"""

from __future__ import annotations

from itertools import product as cartesian

import numpy as np
from scipy.optimize import linprog

from planner.automaton import RabinAutomaton
from planner.imdp import IMDP


def vertices(row: list[tuple[int, float, float]]) -> list[dict[int, float]]:
    out: list[dict[int, float]] = []
    n = len(row)
    for free in range(n):
        others = [k for k in range(n) if k != free]
        for pick in cartesian((0, 1), repeat=len(others)):
            p = [0.0] * n
            for k, b in zip(others, pick, strict=True):
                p[k] = row[k][2] if b else row[k][1]
            p[free] = 1.0 - sum(p)
            if row[free][1] - 1e-12 <= p[free] <= row[free][2] + 1e-12:
                p[free] = min(max(p[free], row[free][1]), row[free][2])
                d: dict[int, float] = {}
                for k in range(n):
                    if p[k] > 1e-15:
                        d[row[k][0]] = d.get(row[k][0], 0.0) + p[k]
                if not any(_same(d, e) for e in out):
                    out.append(d)
    return out


def _same(a: dict[int, float], b: dict[int, float]) -> bool:
    return a.keys() == b.keys() and all(abs(a[k] - b[k]) < 1e-12 for k in a)


def rows_of(model: IMDP) -> dict[tuple[int, int], list[tuple[int, float, float]]]:
    out: dict[tuple[int, int], list[tuple[int, float, float]]] = {}
    s, a, t, lo, up = model.coo()
    for i in range(len(s)):
        out.setdefault((int(s[i]), int(a[i])), []).append((int(t[i]), float(lo[i]), float(up[i])))
    return out


class Product:
    """Product of an IMDP and a Rabin automaton: product states ``(s, q)`` reachable from
    the initial one, rows ``(state, action) -> [(succ, l, u)]``, pairs as sets."""

    def __init__(self, model: IMDP, aut: RabinAutomaton) -> None:
        rows = rows_of(model)
        letter = [
            aut.letter([p for p in model.labels[s] if p in aut.propositions])
            for s in range(model.n_states)
        ]
        s0 = int(model.initial[0])
        start = (s0, int(aut.transitions[aut.initial, letter[s0]]))
        index = {start: 0}
        states = [start]
        self.rows: dict[int, dict[int, list[tuple[int, float, float]]]] = {}
        k = 0
        while k < len(states):
            s, q = states[k]
            acts = {}
            for (ms, a), row in rows.items():
                if ms != s:
                    continue
                new = []
                for t, lo, up in row:
                    nxt = (t, int(aut.transitions[q, letter[t]]))
                    if nxt not in index:
                        index[nxt] = len(states)
                        states.append(nxt)
                    new.append((index[nxt], lo, up))
                acts[a] = new
            self.rows[k] = acts
            k += 1
        self.states = states
        self.pairs = [
            (
                {i for i, (_, q) in enumerate(states) if q in p.good},
                {i for i, (_, q) in enumerate(states) if q in p.bad},
            )
            for p in aut.pairs
        ]


def _sccs(nodes: set[int], succ: dict[int, set[int]]) -> list[set[int]]:
    """Strongly connected components (iterative Tarjan) of the graph restricted to nodes."""
    index: dict[int, int] = {}
    low: dict[int, int] = {}
    on: set[int] = set()
    stack: list[int] = []
    out: list[set[int]] = []
    counter = 0
    for root in sorted(nodes):
        if root in index:
            continue
        work = [(root, iter(sorted(succ.get(root, set()) & nodes)))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            advanced = False
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(succ.get(w, set()) & nodes))))
                    advanced = True
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = set()
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.add(w)
                    if w == v:
                        break
                out.append(comp)
    return out


def _mecs(nodes: set[int], actions: dict[int, list[dict[int, float]]]) -> list[set[int]]:
    """Maximal end components of an MDP (actions: per state, a list of distributions)
    restricted to ``nodes``."""
    nodes = set(nodes)
    while True:
        acts = {s: [d for d in actions.get(s, []) if set(d) <= nodes] for s in nodes}
        alive = {s for s in nodes if acts[s]}
        succ = {s: {t for d in acts[s] for t in d} for s in alive}
        comps = _sccs(alive, succ)
        new_nodes = set()
        changed = alive != nodes
        result = []
        for c in comps:
            ok = {s for s in c if any(set(d) <= c for d in acts[s])}
            if ok != c:
                changed = True
            new_nodes |= ok
            result.append(c)
        if not changed:
            return [c for c in result if any(any(set(d) <= c for d in acts[s]) for s in c)]
        nodes = new_nodes
        if not nodes:
            return []


def _max_reach(n: int, actions: dict[int, list[dict[int, float]]], target: set[int]) -> np.ndarray:
    """Maximal reachability of ``target`` in an MDP, by a linear program (minimise sum x
    with x_s >= p . x for every action, x = 1 on the target, 0 where unreachable)."""
    reach = set(target)
    changed = True
    while changed:
        changed = False
        for s in range(n):
            if s not in reach and any(set(d) & reach for d in actions.get(s, [])):
                reach.add(s)
                changed = True
    x = np.zeros(n)
    free = [s for s in range(n) if s in reach and s not in target]
    for s in target:
        x[s] = 1.0
    if not free:
        return x
    col = {s: k for k, s in enumerate(free)}
    a_ub, b_ub = [], []
    for s in free:
        for d in actions.get(s, []):
            row = np.zeros(len(free))
            row[col[s]] -= 1.0
            rhs = 0.0
            for t, p in d.items():
                if t in col:
                    row[col[t]] += p
                elif t in target:
                    rhs -= p
            a_ub.append(row)
            b_ub.append(rhs)
    res = linprog(
        np.ones(len(free)),
        A_ub=np.array(a_ub),
        b_ub=np.array(b_ub),
        bounds=[(0, 1)] * len(free),
        method="highs",
    )
    assert res.status == 0, res.message
    for s in free:
        x[s] = res.x[col[s]]
    return x


def strategy_value(prod: Product, sigma: dict[int, int]) -> np.ndarray:
    """Worst-case satisfaction of the memoryless strategy ``sigma`` (dynamic adversary)."""
    n = len(prod.states)
    actions = {s: vertices(prod.rows[s][sigma[s]]) for s in range(n)}
    bad: set[int] = set()
    work = [set(range(n))]
    while work:
        nodes = work.pop()
        for c in _mecs(nodes, actions):
            sat = [i for i, (g, b) in enumerate(prod.pairs) if (c & g) and not (c & b)]
            if not sat:
                bad |= c
            else:
                rest = c - set().union(*(prod.pairs[i][0] for i in sat))
                if rest:
                    work.append(rest)
    return 1.0 - _max_reach(n, actions, bad)


def game_value(prod: Product) -> tuple[float, dict[int, int], np.ndarray]:
    """``max_sigma`` of :func:`strategy_value` over all memoryless strategies: at the
    initial state, a strategy attaining it, and per product state (the maximum at each
    state separately)."""
    n = len(prod.states)
    choices = [sorted(prod.rows[s]) for s in range(n)]
    best, arg = -1.0, {}
    per_state = np.zeros(n)
    for combo in cartesian(*choices):
        sigma = dict(enumerate(combo))
        vals = strategy_value(prod, sigma)
        per_state = np.maximum(per_state, vals)
        if vals[0] > best + 1e-12:
            best, arg = float(vals[0]), sigma
    return best, arg, per_state


def mdp_satisfaction(prod: Product, dist: dict[int, dict[int, dict[int, float]]]) -> float:
    """Maximal satisfaction at the initial state of the product MDP with the distributions
    ``dist[s][a]`` (accepting end components, then maximal reachability)."""
    n = len(prod.states)
    actions = {s: list(dist[s].values()) for s in range(n)}
    acc: set[int] = set()
    for g, b in prod.pairs:
        for c in _mecs(set(range(n)) - b, actions):
            if c & g:
                acc |= c
    return float(_max_reach(n, actions, acc)[0])


def static_value(model: IMDP, aut: RabinAutomaton, limit: int = 20000) -> float:
    """``min`` over the vertex resolutions of the base model's rows (one distribution per
    (state, action), the same in every automaton state) of the product MDP's maximal
    satisfaction: the issue's static reference, an upper bound of the game value."""
    rows = rows_of(model)
    keys = sorted(rows)
    verts = [vertices(rows[k]) for k in keys]
    prod = Product(model, aut)
    best = 2.0
    count = 0
    for combo in cartesian(*verts):
        count += 1
        if count > limit:
            break
        chosen = dict(zip(keys, combo, strict=True))
        dist: dict[int, dict[int, dict[int, float]]] = {}
        for ps, (s, q) in enumerate(prod.states):
            dist[ps] = {}
            for a in prod.rows[ps]:
                d = chosen[(s, a)]
                succ: dict[int, float] = {}
                for t, p in d.items():
                    qn = int(
                        aut.transitions[
                            q, aut.letter([x for x in model.labels[t] if x in aut.propositions])
                        ]
                    )
                    nxt = prod.states.index((t, qn))
                    succ[nxt] = succ.get(nxt, 0.0) + p
                dist[ps][a] = succ
        best = min(best, mdp_satisfaction(prod, dist))
    return best


def _attractor_choice(
    n: int, actions: dict[int, dict[int, dict[int, float]]], target: set[int], allowed
) -> dict[int, int]:
    """Backward breadth-first choice: each state joins by an allowed action with an edge
    into the states that joined before (``allowed(s, a)`` filters the actions)."""
    inside = set(target)
    choice: dict[int, int] = {}
    changed = True
    while changed:
        changed = False
        for s in range(n):
            if s in inside:
                continue
            for a, d in sorted(actions[s].items()):
                if allowed(s, a) and set(d) & inside:
                    choice[s] = a
                    inside.add(s)
                    changed = True
                    break
    return choice


def optimal_strategy(prod: Product, dist: dict[int, dict[int, dict[int, float]]]) -> dict[int, int]:
    """A memoryless optimal strategy of the product MDP: in the accepting end components
    head for the pair's ``G`` states with the component's own actions; elsewhere the
    actions optimal for the maximal reachability of them, tie-broken towards progress."""
    n = len(prod.states)
    flat = {s: list(dist[s].values()) for s in range(n)}
    sigma: dict[int, int] = {}
    acc: set[int] = set()
    for g, b in prod.pairs:
        for c in _mecs(set(range(n)) - b, flat):
            if not c & g or c & acc:
                continue
            acc |= c
            inner = {s: {a: d for a, d in dist[s].items() if set(d) <= c} for s in c}
            goal = c & g
            ch = _attractor_choice(
                n, {s: inner.get(s, {}) for s in range(n)}, goal, lambda s, a, c=c: s in c
            )
            for s in c:
                sigma[s] = ch.get(s, min(inner[s]))
    x = _max_reach(n, flat, acc)
    best = {s: max(sum(p * x[t] for t, p in d.items()) for d in dist[s].values()) for s in range(n)}

    def optimal(s: int, a: int) -> bool:
        q = sum(p * x[t] for t, p in dist[s][a].items())
        return q >= best[s] - 1e-9

    progress = _attractor_choice(n, dist, acc | {s for s in range(n) if x[s] <= 0}, optimal)
    for s in range(n):
        if s not in sigma:
            sigma[s] = progress.get(s, min(dist[s]))
    return sigma


def sample_resolution(
    prod: Product, model: IMDP, aut: RabinAutomaton, rng: np.random.Generator
) -> tuple[dict[int, dict[int, dict[int, float]]], dict[int, int]]:
    """A random static vertex resolution of the base model (as product distributions) and
    a memoryless strategy optimal for it."""
    rows = rows_of(model)
    chosen = {}
    for k, row in rows.items():
        vs = vertices(row)
        chosen[k] = vs[int(rng.integers(len(vs)))]
    dist: dict[int, dict[int, dict[int, float]]] = {}
    for ps, (s, q) in enumerate(prod.states):
        dist[ps] = {}
        for a in prod.rows[ps]:
            succ: dict[int, float] = {}
            for t, p in chosen[(s, a)].items():
                letter = aut.letter([x for x in model.labels[t] if x in aut.propositions])
                nxt = prod.states.index((t, int(aut.transitions[q, letter])))
                succ[nxt] = succ.get(nxt, 0.0) + p
            dist[ps][a] = succ
    return dist, optimal_strategy(prod, dist)
