"""Compile the numba kernels ahead of the first synthesis, saying so when it takes a while."""

from __future__ import annotations

import sys
import threading
import time


def prepare_kernels(prog: str, quiet: bool = False, after: float = 2.0) -> float:
    """:func:`planner.warmup.compile_kernels`, with a line on stderr when it takes longer than
    ``after`` seconds (a fresh installation compiles them, later runs load numba's cache).

    Returns:
        The seconds it took (imports included).
    """
    said = threading.Event()
    t0 = time.perf_counter()

    def notice() -> None:
        said.set()
        sys.stderr.write(
            f"{prog}: preparing the value-iteration kernels (numba compiles them once per "
            "installation and caches them)...\n"
        )
        sys.stderr.flush()

    timer = threading.Timer(after, notice)
    timer.daemon = True
    if not quiet:
        timer.start()
    try:
        from planner.warmup import compile_kernels

        compile_kernels()
    finally:
        timer.cancel()
        if timer.is_alive():
            timer.join()  # a notice being written ends before the result line
    seconds = time.perf_counter() - t0
    if said.is_set():
        sys.stderr.write(f"{prog}: kernels ready in {seconds:.1f} s\n")
        sys.stderr.flush()
    return seconds
