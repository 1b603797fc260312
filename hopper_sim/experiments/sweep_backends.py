"""Where the runs of a sweep execute: ``serial`` (in this process), ``process`` (a pool of
worker processes started with ``spawn``, one thread each) and ``ray`` (the optional extra
``ray``; a local instance is started when no address is given).

Each backend yields ``(task, row)`` pairs in completion order; one torch thread per run in
every backend, so that float reductions, and hence the runs, do not depend on the backend.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager, nullcontext
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopper_sim.experiments.sweep_grid import (
    RunFunction,
    SweepBackendError,
    SweepRow,
    SweepRunError,
    SweepTask,
)
from hopper_sim.navigation.events import RunEnd

if TYPE_CHECKING:
    from planner.scenario import Scenario


def available_cores() -> int:
    """CPU cores this process may use (its affinity set where the OS reports one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def default_run_function() -> RunFunction:
    """The real navigation run, :func:`hopper_sim.navigation.runner.run_single` (imported now).

    Raises:
        SweepBackendError: this installation has no :mod:`hopper_sim.navigation.runner`.
    """
    try:
        from hopper_sim.navigation.runner import run_single
    except ModuleNotFoundError as err:
        if err.name != "hopper_sim.navigation.runner":
            raise
        raise SweepBackendError(
            "the navigation runner hopper_sim.navigation.runner is not available in this "
            "installation"
        ) from err

    return run_single


def _run_task(run: RunFunction, scenario: Scenario, task: SweepTask) -> SweepRow:
    where = f"run {task.run} of cell C={task.c:g}, eps={task.eps:g} (seed {task.seed})"
    sc = scenario.with_runner(p_rl_ee=task.c, c=task.c, eps=task.eps, seed=task.seed, runs=1)
    try:
        end = run(sc, task.seed, task.run)
    except Exception as err:
        raise SweepRunError(f"{where} failed: {type(err).__name__}: {err}") from err
    if not isinstance(end, RunEnd):
        raise SweepRunError(
            f"{where}: the run function must return a RunEnd, got {type(end).__name__}"
        )
    return SweepRow.from_run_end(task, end)


_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def die_with_parent(parent: int) -> None:
    """Make this process end when its parent (pid ``parent``) ends, also by SIGKILL: the
    kernel sends it SIGKILL then (Linux ``PR_SET_PDEATHSIG``; elsewhere a no-op). Exits at
    once if the parent has already gone."""
    import sys

    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig, sigkill = 1, 9
        libc.prctl(pr_set_pdeathsig, sigkill, 0, 0, 0)
    if os.getppid() != parent:  # the parent died before the line above took effect
        os._exit(1)


def _init_worker(parent: int | None = None) -> None:
    # Workers share the cores: one compute thread each (torch reads these when imported).
    for var in _THREAD_VARS:
        os.environ[var] = "1"
    import sys

    if parent is not None:
        die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    if hasattr(signal, "pthread_sigmask"):
        # blocked since the spawn (_signals_held); a Ctrl-C pending since is dropped
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGTERM, signal.SIG_DFL)

    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


def _iter_serial(
    run: RunFunction, scenario: Scenario, tasks: Sequence[SweepTask]
) -> Iterator[tuple[SweepTask, SweepRow]]:
    import sys

    for task in tasks:
        # One torch thread during each run, as in the workers, so that float reductions and
        # hence the runs do not depend on the backend; the caller's setting is restored.
        torch = sys.modules.get("torch")
        before = torch.get_num_threads() if torch is not None else None
        if torch is not None:
            torch.set_num_threads(1)
        try:
            row = _run_task(run, scenario, task)
        finally:
            if torch is not None:
                torch.set_num_threads(before)
        yield task, row


def _iter_process(
    run: RunFunction, scenario: Scenario, tasks: Sequence[SweepTask], workers: int
) -> Iterator[tuple[SweepTask, SweepRow]]:
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    pool: ProcessPoolExecutor | None = None
    pending: dict = {}
    main = threading.current_thread() is threading.main_thread()
    try:
        with _signals_held() if main else nullcontext():
            pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=ctx,
                initializer=_init_worker,
                initargs=(os.getpid(),),
            )
            pending = {pool.submit(_run_task, run, scenario, t): t for t in tasks}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                task = pending.pop(fut)
                yield task, fut.result()
    except BaseException:
        # interrupted (Ctrl-C, SIGTERM), a run failed or the consumer stopped: end the runs
        # in progress now instead of waiting for them (a SIGKILL of this process ends the
        # workers through die_with_parent)
        for fut in pending:
            fut.cancel()
        for proc in list((getattr(pool, "_processes", None) or {}).values()):
            proc.terminate()
        raise
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)


@contextmanager
def _signals_held() -> Iterator[None]:
    """Ctrl-C (SIGINT) and SIGTERM held while the workers start, then delivered (main
    thread only).

    SIGINT is blocked in this thread, so the workers spawned from it start with it blocked
    from their first instruction. A Ctrl-C reaches the whole process group, and it is the
    parent's alone to handle: no worker prints a traceback. Each worker ignores it once it
    is up (``_init_worker``). multiprocessing's resource tracker is started first: when the
    first spawn starts it, it unblocks SIGINT in this thread after its own spawn, and the
    workers would then start without the block.

    Meanwhile both signals are recorded rather than raised. A KeyboardInterrupt inside the
    executor's start-up could leave its state half made. A signal that came is raised again
    once the previous handlers are back. Before, SIGINT was ignored here; a Ctrl-C in this
    window was then lost, and the sweep went on to its end."""
    held: list[int] = []
    kinds = (signal.SIGINT, signal.SIGTERM)
    previous = [signal.signal(k, lambda signum, _frame: held.append(signum)) for k in kinds]
    blocked = False
    try:
        if hasattr(signal, "pthread_sigmask"):
            from multiprocessing import resource_tracker

            resource_tracker.ensure_running()
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            blocked = True
        yield
    finally:
        # the handlers come back whatever failed above (a pending Ctrl-C is recorded first)
        if blocked:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        for k, handler in zip(kinds, previous, strict=True):
            if handler is not None:
                signal.signal(k, handler)
    for signum in dict.fromkeys(held):
        signal.raise_signal(signum)


def _import_ray() -> Any:
    try:
        import ray
    except ImportError as err:
        raise SweepBackendError(
            "the 'ray' backend needs the optional extra: pip install 'hopnav[ray]' "
            "(or use --backend process)"
        ) from err
    return ray


def _iter_ray(
    run: RunFunction,
    scenario: Scenario,
    tasks: Sequence[SweepTask],
    workers: int,
    address: str | None,
) -> Iterator[tuple[SweepTask, SweepRow]]:
    ray = _import_ray()
    started = False
    if not ray.is_initialized():
        if address is None:
            # Local workers import this project from its source tree even when it is not
            # installed; remote clusters need it installed (pip install 'hopnav[ray]').
            root = str(Path(__file__).resolve().parents[2])
            path = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)
            ray.init(
                num_cpus=workers,
                include_dashboard=False,
                log_to_driver=False,
                runtime_env={"env_vars": {"PYTHONPATH": path, **dict.fromkeys(_THREAD_VARS, "1")}},
            )
        else:
            ray.init(address=address, log_to_driver=False)
        started = True
    try:
        remote = ray.remote(num_cpus=1)(_run_task)
        run_ref = ray.put(run)
        scenario_ref = ray.put(scenario)
        pending = {remote.remote(run_ref, scenario_ref, t): t for t in tasks}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                task = pending.pop(ref)
                yield task, ray.get(ref)
    finally:
        if started:
            ray.shutdown()
