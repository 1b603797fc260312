"""LTL to an automaton, an interval MDP by hand, their product, and a robust check.

Translates ``!Haz U Goal`` to a deterministic Rabin automaton, builds the IMDP of a 5-cell
corridor (hazard in the middle, goal at the east end) whose hops land on their target with a
probability in [0.6, 0.9] and one cell short otherwise ([0.1, 0.4]), solves the worst- and
best-case probability of the formula on the product (0.6 and 0.9: the one risky hop is the
jump over the hazard), and writes the labelled product as a DRN file that Storm reads
(cross-checked with stormpy when installed).

    python examples/05_ltl_imdp_check.py [--out runs/corridor.drn]
"""

import argparse
from pathlib import Path

import numpy as np

from planner import (
    GridWorld,
    Problem,
    ProductIMDP,
    ReachAvoid,
    Specification,
    ValueIteration,
    labelled_model,
    read_model,
    solve,
    translate,
    write_model,
)


def corridor(n: int = 5) -> GridWorld:
    labels = [()] * n
    labels[2] = ("Haz",)
    labels[n - 1] = ("Goal",)
    return GridWorld(n, 1, 1.0, labels, "Haz")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="runs/corridor.drn")
    args = ap.parse_args()
    aut = translate("!Haz U Goal")
    print(f"automaton: {aut.n_states} states, {len(aut.pairs)} Rabin pair(s)")

    grid = corridor()
    s, a, t, lo, up = [], [], [], [], []
    for cell in range(grid.n_cells):
        for action in np.flatnonzero(grid.enabled[cell]):
            target = int(grid.target_cell[cell, action])
            short = target - int(np.sign(target - cell))  # one cell short (1-cell hop: stay)
            s += [cell, cell]
            a += [int(action)] * 2
            t += [target, short]
            lo += [0.6, 0.1]
            up += [0.9, 0.4]
    model = grid.imdp_from_intervals(
        np.array(s), np.array(a), np.array(t), np.array(lo), np.array(up), initial=[0]
    )
    product = ProductIMDP(model, aut)
    labelled = labelled_model(product)  # labels "accept" (accepting end components), "fail"
    values = {}
    for mode in ("pessimistic", "optimistic"):
        spec = Specification(ReachAvoid("accept", "fail"), mode)
        sol = solve(Problem(labelled, spec), ValueIteration(tolerance=1e-10))
        values[mode] = sol.values[product.initial]
        print(
            f"{mode}: P(!Haz U Goal) from the start = {values[mode]:.6f} "
            f"(residual {sol.residual:.1e}, {sol.iterations} iterations)"
        )
    assert abs(values["pessimistic"] - 0.6) < 1e-8 and abs(values["optimistic"] - 0.9) < 1e-8
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_model(labelled, out)
    back = read_model(out)
    assert back.n_states == labelled.n_states
    print(f"wrote {out} ({labelled.n_states} states)")
    try:
        import stormpy
    except ImportError:
        return
    storm_model = stormpy.build_model_from_drn[stormpy.Interval](str(out))
    prop = stormpy.parse_properties('Pmax=? [!"fail" U "accept"]')[0]
    result = stormpy.model_checking(
        storm_model,
        prop,
        only_initial_states=True,
        uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.ROBUST,
    )
    storm = result.get_value(product.initial)
    print(f"Storm (robust): {storm:.6f}")
    assert abs(storm - values["pessimistic"]) < 1e-6


if __name__ == "__main__":
    main()
