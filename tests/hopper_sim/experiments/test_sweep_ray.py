"""A small sweep of real navigation runs on a real local Ray instance gives the same table as
the process backend (the `ray` extra; CI installs it)."""

from __future__ import annotations

import dataclasses

import pytest

from hopper_sim.experiments.sweep import SweepSpec, run_sweep
from hopper_sim.experiments.sweep_files import markdown_table
from planner.scenario import load_scenario

ray = pytest.importorskip("ray", reason="ray is the optional extra hopnav[ray]")


def _timeless(rows):
    return [dataclasses.replace(r, seconds=0.0) for r in rows]


@pytest.mark.slow
def test_real_runs_on_local_ray_equal_the_process_backend():
    scenario = load_scenario("a").with_runner(max_steps=6)
    spec = SweepSpec(cs=(0.25, 0.75), epss=(0.005,), runs=1, seed=3)
    done: list[int] = []
    on_ray = run_sweep(
        scenario, spec, backend="ray", workers=1, progress=lambda d, t, row: done.append(d)
    )
    assert not ray.is_initialized()  # the sweep started its own instance and shut it down
    in_processes = run_sweep(scenario, spec, backend="process", workers=1)
    assert on_ray.backend == "ray" and in_processes.backend == "process"
    assert done == [1, 2] and len(on_ray.rows) == spec.n_runs
    assert all(r.steps >= 1 for r in on_ray.rows)
    assert _timeless(on_ray.rows) == _timeless(in_processes.rows)
    assert markdown_table(on_ray) == markdown_table(in_processes)
