"""``hopnav sweep``: reproduce the paper's Table I (reward / steps over P_RL,ee = C x eps).

Runs ``--runs`` complete navigation runs for each cell of the grid
``P_RL,ee = C in {0.25, 0.5, 0.75}`` x ``eps in {0.0025, 0.005, 0.0075}`` on a scenario
(default: case study ``a``), in parallel worker processes (``--backend process``, the
default), in this process (``serial``) or on a Ray cluster (``ray``, optional extra). Prints
the table beside the paper's and writes ``sweep_runs.csv`` (one row per run),
``sweep_summary.csv`` (per cell, 95 % Student-t intervals), ``table_i.md`` and the plot
``table_i.png`` (reward and steps with their intervals against C and eps, the paper's values
overlaid; :mod:`hopper_sim.viz.sweep_plot`) to ``--out``.
The seeds derive from ``--seed`` alone, so the table does not depend on the backend or on the
number of workers. ``--set KEY=VALUE`` (repeatable) changes a setting of every run's
configuration tree (``hopnav config`` lists the keys), except those the sweep sets itself
(``switching.p_rl_explore``, ``switching.c``, ``switching.eps``, ``run.seed``, ``run.runs``).

``sweep_runs.csv`` is rewritten (atomically) after every finished run, so an interrupted
(Ctrl-C, SIGTERM, or even SIGKILL) sweep leaves the runs it finished; ``--resume`` reuses
them and runs the rest. ``sweep_meta.json``, written before the first run, names the
scenario (its digest) and the grid (C and eps values, runs per cell, seed): ``--resume``
refuses a folder of another scenario or grid, and a sweep without ``--resume`` refuses a
folder that holds a sweep's results unless ``--force`` replaces them. Every file carries
the provenance of :mod:`hopper_sim.experiments.provenance` (CSV columns, ``sweep_meta.json``, a line
under the Markdown table).
"""

from __future__ import annotations

import argparse
import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hopnav.arguments import add_set_argument, non_negative_int, output_folder, positive_int
from hopnav.errors import RunFailed, UsageError, is_interrupt
from hopnav.kernels import prepare_kernels

META_FILE = "sweep_meta.json"


#: The files of a sweep's results in ``--out`` (a folder holding one is a sweep's).
RESULT_FILES = (
    META_FILE,
    "sweep_runs.csv",
    "sweep_summary.csv",
    "table_i.md",
    "table_i.png",
)


def _levels(text: str) -> tuple[float, ...]:
    parts = text.split(",")
    try:
        values = tuple(float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated numbers such as 0.25,0.5, got {text!r}"
        ) from None
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return values


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "sweep",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--scenario", default="a", help="shipped name (a-d) or TOML path [a]")
    p.add_argument("--runs", type=positive_int, default=10, help="runs per cell [10]")
    p.add_argument("--seed", type=non_negative_int, default=0, help="base seed of all runs [0]")
    p.add_argument(
        "--workers", type=positive_int, default=None, help="parallel workers [number of cores]"
    )
    p.add_argument(
        "--backend", choices=("process", "serial", "ray"), default="process", help="[process]"
    )
    p.add_argument("--ray-address", default=None, help="Ray cluster address [local instance]")
    p.add_argument(
        "--cs", type=_levels, default=None, help="comma-separated C values [0.25,0.5,0.75]"
    )
    p.add_argument(
        "--epss", type=_levels, default=None, help="comma-separated eps [0.0025,0.005,0.0075]"
    )
    p.add_argument("--out", default=os.path.join("runs", "sweep"), help="[runs/sweep]")
    add_set_argument(p)
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--resume", action="store_true", help="reuse the finished runs found in --out"
    )
    mode.add_argument(
        "--force", action="store_true", help="replace the results of another sweep in --out"
    )
    p.set_defaults(func=run)


def _kept(finished: list, rows: Path) -> str:
    if not finished:
        return "no run had finished; add --resume to start where it stopped"
    return f"the {len(finished)} finished runs are in {rows}; add --resume to run only the others"


#: keys of the configuration tree that the sweep sets itself (per cell and run)
SWEPT_KEYS = (
    "planner.switching.p_rl_explore",
    "planner.switching.c",
    "planner.switching.eps",
    "run.seed",
    "run.runs",
)


def grid_record(spec: Any, sets: dict[str, str] | None = None) -> dict[str, Any]:
    """The grid of a sweep as recorded in ``sweep_meta.json`` (what ``--resume`` must match),
    with the ``--set`` changes where there are any."""
    grid = {"cs": list(spec.cs), "epss": list(spec.epss), "runs": spec.runs, "seed": spec.seed}
    if sets:
        grid["set"] = dict(sets)
    return grid


def _sets(scenario: Any, items: list[str]) -> dict[str, str]:
    """The ``--set`` changes by full key, checked on ``scenario``'s configuration tree.

    Raises:
        UsageError: a malformed or unknown key, a bad value, or a key the sweep sets.
    """
    if not items:
        return {}  # (and the tree's modules stay unimported until the runs start)
    from hopper_sim.navigation.config import (
        ConfigError,
        NavigationConfig,
        parse_assignments,
        resolve_key,
    )

    try:
        given = parse_assignments(items)
        sets = {resolve_key(k, "--set: "): v for k, v in given.items()}
        for key in sets:
            if key in SWEPT_KEYS:
                raise UsageError(
                    f"--set {key}: the sweep sets it (per cell: --cs, --epss; per run: "
                    "--runs, --seed)"
                )
        NavigationConfig.from_scenario(scenario).override(sets, text=True, source="--set")
    except ConfigError as err:
        raise UsageError(str(err)) from None
    return sets


def _describe(grid: Any) -> str:
    if not isinstance(grid, dict):
        return repr(grid)
    sets = grid.get("set")
    changes = f", --set {' '.join(f'{k}={v}' for k, v in sets.items())}" if sets else ""
    return (
        f"C {grid.get('cs')}, eps {grid.get('epss')}, {grid.get('runs')} runs per cell, "
        f"seed {grid.get('seed')}{changes}"
    )


def _refuse_overwrite(out: Path, force: bool) -> None:
    """Refuse to write into a folder holding another sweep's results, unless ``force``
    (then those files are removed first)."""
    present = [name for name in RESULT_FILES if (out / name).exists()]
    if not present:
        return
    if not force:
        raise UsageError(
            f"--out {out} holds the results of a sweep ({', '.join(present)}); add --resume "
            "to continue that sweep, --force to replace its results, or choose another --out"
        )
    for name in present:
        (out / name).unlink()


def _prepare(args: argparse.Namespace, out: Path):
    """(scenario, spec, provenance, grid record, reused rows, ``--set`` overrides) of the
    sweep ``args`` asks for, with ``--out`` checked for ``--resume``/``--force`` and the Ray
    backend importable."""
    from hopper_sim.controller.checkpoint import DEFAULT_CHECKPOINT
    from hopper_sim.experiments.provenance import ProvenanceError, provenance
    from hopper_sim.experiments.sweep import (
        PAPER_CS,
        PAPER_EPSS,
        SweepBackendError,
        SweepError,
        SweepSpec,
    )
    from hopper_sim.experiments.sweep_files import SweepFileError, read_rows_csv
    from planner.errors import ScenarioError
    from planner.scenario import load_scenario

    try:
        scenario = load_scenario(args.scenario)
        spec = SweepSpec(
            cs=PAPER_CS if args.cs is None else args.cs,
            epss=PAPER_EPSS if args.epss is None else args.epss,
            runs=args.runs,
            seed=args.seed,
        )
        prov = provenance(scenario, DEFAULT_CHECKPOINT)  # the runs use the shipped controller
        sets = _sets(scenario, args.set)
        grid = grid_record(spec, sets)
        if args.resume:
            previous = _previous_rows(out, prov, grid, read_rows_csv)
        else:
            _refuse_overwrite(out, args.force)
            previous = []
        if args.backend == "ray":
            from hopper_sim.experiments.sweep import _import_ray

            _import_ray()
    except (ScenarioError, SweepError, SweepFileError, ProvenanceError, SweepBackendError) as err:
        raise UsageError(str(err)) from None
    return scenario, spec, prov, grid, previous, sets


def run(args: argparse.Namespace) -> int:
    out = output_folder(args.out, "--out")
    from tqdm import tqdm

    from hopper_sim.experiments.sweep import (
        SweepBackendError,
        SweepError,
        SweepRow,
        SweepRunError,
        run_sweep,
    )
    from hopper_sim.experiments.sweep_files import (
        ROWS_FILE,
        atomic_write_text,
        rows_csv,
        write_outputs,
    )

    scenario, spec, prov, grid, previous, sets = _prepare(args, out)
    if args.backend != "serial" or spec.n_runs > len(previous):
        prepare_kernels("hopnav sweep", quiet=args.json)  # once, before the workers start
    order = {(t.c, t.eps, t.run, t.seed): t.index for t in spec.tasks()}
    finished: list[SweepRow] = [r for r in previous if (r.c, r.eps, r.run, r.seed) in order]
    # the folder is this sweep's from now on (written before the first run starts)
    meta = {**prov, "provenance": prov, "grid": grid}
    atomic_write_text(out / META_FILE, json.dumps(meta, indent=2) + "\n")
    bar = tqdm(total=spec.n_runs, unit="run", desc=f"sweep {scenario.name}", disable=args.json)

    def progress(done: int, total: int, row: SweepRow) -> None:
        if done == 1:
            bar.update(spec.n_runs - total - bar.n)  # the reused runs
        finished.append(row)
        finished.sort(key=lambda r: order[(r.c, r.eps, r.run, r.seed)])
        atomic_write_text(out / ROWS_FILE, rows_csv(finished, prov))
        bar.update(1)
        bar.set_postfix_str(f"C={row.c:g} eps={row.eps:g} {row.outcome} {row.steps} hops")

    try:
        result = run_sweep(
            scenario,
            spec,
            run=_run_function(sets),
            backend=args.backend,
            workers=args.workers,
            ray_address=args.ray_address,
            progress=progress,
            previous=previous,
        )
    except (SweepBackendError, SweepError) as err:
        raise UsageError(str(err)) from None
    except SweepRunError as err:
        if is_interrupt(err):  # Ctrl-C inside a compiled kernel of a serial run
            raise RunFailed(f"interrupted; {_kept(finished, out / ROWS_FILE)}") from None
        raise RunFailed(f"{err}; {_kept(finished, out / ROWS_FILE)}, after a fix") from None
    except KeyboardInterrupt:
        raise RunFailed(f"interrupted; {_kept(finished, out / ROWS_FILE)}") from None
    finally:
        bar.close()
    paths = write_outputs(result, args.out, prov)
    from hopper_sim.viz.sweep_plot import PLOT_FILE, write_table_plot

    paths["plot"] = write_table_plot(result.cells, out / PLOT_FILE, metadata=prov)
    _print_results(args, result, spec, paths)
    return 0


def _print_results(args: argparse.Namespace, result: Any, spec: Any, paths: dict) -> None:
    """The sweep's table (or, with ``--json``, its JSON record) and the files written."""
    from hopper_sim.experiments.sweep_files import format_table

    if args.json:
        record = result.to_json()
        record["files"] = {k: str(v) for k, v in paths.items()}
        print(json.dumps(record, indent=2, allow_nan=False))
        return
    print(format_table(result))
    print(
        f"\n{spec.n_runs} runs in {result.seconds:.1f} s ({result.backend}, {result.workers} "
        "workers)"
    )
    for kind, path in paths.items():
        print(f"{kind}: {path}")


def _run_function(sets: dict[str, str]) -> Callable | None:
    """The run function of the workers: the default one, with the ``--set`` changes."""
    if not sets:
        return None
    import functools

    from hopper_sim.navigation.runner import run_single

    return functools.partial(run_single, overrides=sets)


def _previous_rows(
    out: Path, prov: dict[str, Any], grid: dict[str, Any], read_rows: Callable[[Path], list[Any]]
) -> list[Any]:
    """The finished rows in ``out`` for ``--resume``; empty if there are none.

    Raises:
        SweepError: ``sweep_meta.json`` is missing, unreadable or not a JSON object, or
            records another grid.
        ProvenanceError: the meta file or a row belongs to another scenario.
        SweepFileError: the rows file is unreadable.
    """
    import csv
    import io

    from hopper_sim.experiments.provenance import ProvenanceError, require_same_scenario
    from hopper_sim.experiments.sweep import SweepError
    from hopper_sim.experiments.sweep_files import MAX_CSV_BYTES, ROWS_FILE, SweepFileError
    from planner._util.textfile import read_text

    rows_path, meta_path = out / ROWS_FILE, out / META_FILE
    if not rows_path.is_file() and not meta_path.exists():
        return []
    try:
        meta = json.loads(read_text(meta_path, SweepError, 1 << 20))
    except ValueError as err:  # SweepError, or a JSONDecodeError
        raise SweepError(f"cannot resume: {meta_path} is missing or unreadable ({err})") from None
    if not isinstance(meta, dict):
        raise SweepError(
            f"cannot resume: {meta_path} holds a {type(meta).__name__}, not a JSON object "
            "(use another --out, or --force to start over)"
        )
    try:
        require_same_scenario(meta, prov, f"{meta_path}")
        if not rows_path.is_file():
            digests: set[Any] = set()
        else:
            text = read_text(rows_path, SweepFileError, MAX_CSV_BYTES)
            digests = {row.get("scenario_sha256") for row in csv.DictReader(io.StringIO(text))}
        for digest in digests - {prov["scenario_sha256"]}:
            require_same_scenario({"scenario_sha256": digest}, prov, f"a row of {rows_path}")
    except ProvenanceError as err:
        raise ProvenanceError(f"cannot resume: {err} (or use another --out)") from None
    except csv.Error as err:
        raise SweepFileError(f"cannot resume: {rows_path}: malformed CSV ({err})") from None
    if meta.get("grid") != grid:
        raise SweepError(
            f"cannot resume: {out} holds a sweep of another grid ({_describe(meta.get('grid'))}); "
            f"this one is {_describe(grid)} (use the same --cs/--epss/--runs/--seed/--set, another "
            "--out, or --force to start over)"
        )
    return read_rows(rows_path) if rows_path.is_file() else []
