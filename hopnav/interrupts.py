"""Ctrl-C and SIGTERM delivered where Python code can take them.

The commands turn SIGINT and SIGTERM into ``KeyboardInterrupt`` so that an interrupted run
keeps what finished. Python raises it at the next bytecode of the main thread, wherever
that is, and some places cannot take it (each measured on ``hopnav run`` or ``hopnav
sweep`` interrupted in its first seconds; ``docs/design.md``, "Interruptions"):

- numba compiling or loading a kernel from its cache: its llvmlite objects free their
  LLVM handles in Python finalisers, and an exception raised there leaves a handle half
  disposed; the process later aborts on it (SIGABRT or SIGSEGV, about 2 of 100 tries, the
  faulthandler's last frame in ``llvmlite/binding/ffi.py``);
- torch, whose C++ calls back into Python (pybind11): an exception there either ends the
  process with ``std::terminate`` (SIGABRT, "pybind11::error_already_set") or passes
  through ``PyRun_String``, which marks the interrupt as unhandled for the whole process,
  so that Python kills itself with SIGINT when it exits, although the command caught it
  and said "interrupted" (exit status -2 instead of 1; 19 of 184 tries);
- an import, which runs such modules' initialisation;
- a thread pool starting a worker (``concurrent/futures/thread.py``): interrupted inside
  ``Thread.start``, the thread runs but is not registered for the pool's shutdown, and the
  interpreter waits for it at exit for ever (4 of 184 tries).

:func:`interrupt_here` defers such a signal by 10 ms until no such frame is on the stack,
which delays an interrupt by at most one import, kernel compilation or torch call.
"""

from __future__ import annotations

import _thread
import os
import time
from types import FrameType

_UNSAFE = (
    f"{os.sep}llvmlite{os.sep}",
    f"{os.sep}numba{os.sep}",
    f"{os.sep}torch{os.sep}",
    "<frozen importlib._bootstrap",  # both _bootstrap and _bootstrap_external
    f"{os.sep}concurrent{os.sep}futures{os.sep}thread.py",
)
_RETRY_S = 0.01


def in_unsafe_code(frame: FrameType | None) -> bool:
    """Whether ``frame`` or one of its callers runs code that an interrupt must not split:
    numba, llvmlite, torch, an import, or a thread pool's own code."""
    while frame is not None:
        name = frame.f_code.co_filename
        if any(part in name for part in _UNSAFE):
            return True
        frame = frame.f_back
    return False


def interrupt_here(signum: int, frame: FrameType | None) -> bool:
    """For a signal handler: whether to raise the interrupt now (``frame``, the handler's,
    is outside the code of :func:`in_unsafe_code`); else the signal is delivered to the
    main thread again in 10 ms (``_thread.interrupt_main``), and the handler should return."""
    if not in_unsafe_code(frame):
        return True
    deliver_again(signum)
    return False


def deliver_again(signum: int) -> None:
    """Deliver ``signum`` to the main thread again in 10 ms, from a bare thread:
    ``threading.Thread.start`` takes a lock that the interrupted code may hold (it may be
    starting a thread itself), and the interpreter never waits for a bare thread at exit."""
    _thread.start_new_thread(_deliver_later, (signum,))


def _deliver_later(signum: int) -> None:
    time.sleep(_RETRY_S)
    _thread.interrupt_main(signum)
