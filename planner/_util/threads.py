"""Worker threads of the planner: one per purpose and process, and running two pieces of
work at once.

The compiled kernels release the GIL (``nogil``) and numpy and scipy release it in their
array operations, so work handed to a worker thread runs on a second core while the calling
thread goes on. Each purpose has its own single worker, so that work of one purpose never
waits behind another's: :mod:`planner.imdp.interval` passes the bound from above to
``"upper"``; :func:`planner.synthesis.synthesise` runs the safety steps on ``"synthesis"``
while the satisfaction probabilities are computed. A worker must not hand work to its own
purpose's worker (it would wait on itself).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, wait
from typing import TypeVar

import numpy as np

A = TypeVar("A")
B = TypeVar("B")

_WORKERS: dict[str, tuple[int, ThreadPoolExecutor]] = {}
_LOCK = threading.Lock()


def _new_lock_in_child() -> None:
    # a fork while another thread held the lock would leave the child's copy held for ever
    global _LOCK
    _LOCK = threading.Lock()


os.register_at_fork(after_in_child=_new_lock_in_child)


def worker(purpose: str) -> ThreadPoolExecutor:
    """The single worker thread of ``purpose`` in this process, created on first use (a
    forked child inherits the executor but not its thread, so it gets its own)."""
    with _LOCK:
        entry = _WORKERS.get(purpose)
        if entry is None or entry[0] != os.getpid():
            pool = ThreadPoolExecutor(1, thread_name_prefix=f"hopnav-{purpose}")
            entry = (os.getpid(), pool)
            _WORKERS[purpose] = entry
        return entry[1]


def concurrently(
    background: Callable[[], A], foreground: Callable[[], B], purpose: str
) -> tuple[A, B]:
    """``(background(), foreground())``, the first run on the worker of ``purpose`` while
    the second runs on the calling thread. An exception of ``foreground`` is raised once
    ``background`` has ended (its result dropped); one of ``background`` after
    ``foreground`` has returned. The two must not write to shared data."""
    future = worker(purpose).submit(background)
    try:
        out = foreground()
    except BaseException:
        wait([future])
        raise
    return future.result(), out


def in_halves(fill: Callable[[int, int], object], work: np.ndarray, purpose: str) -> None:
    """``fill(first, last)`` over ``[0, n)`` in two calls at once, ``n = len(work) - 1``,
    cut where the cumulative ``work`` (``work[i]``: the work before ``i``) reaches half of
    ``work[-1]``: ``fill(0, cut)`` on the worker of ``purpose``, ``fill(cut, n)`` here.
    The two calls must write disjoint data."""
    n = work.size - 1
    cut = min(int(np.searchsorted(work, work[-1] // 2)), n)
    concurrently(lambda: fill(0, cut), lambda: fill(cut, n), purpose)
