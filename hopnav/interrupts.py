"""Ctrl-C and SIGTERM delivered where Python code can take them.

The commands turn SIGINT and SIGTERM into ``KeyboardInterrupt`` so that an interrupted run
keeps what finished. Python raises it at the next bytecode of the main thread, wherever
that is, and one place cannot take it: numba compiling or loading a kernel from its cache,
whose llvmlite objects free their LLVM handles in Python finalisers. An exception raised
there leaves a handle half disposed, and the process later aborts on it (SIGABRT or
SIGSEGV: measured on ``hopnav run`` interrupted early, about 2 of 100 tries, with the
faulthandler's last frame in ``llvmlite/binding/ffi.py``). :func:`interrupt_here` defers
such a signal by 10 ms until no frame of numba or llvmlite is on the stack, which delays an
interrupt by at most one kernel's compilation.
"""

from __future__ import annotations

import _thread
import os
import threading
from types import FrameType

_COMPILER = (f"{os.sep}llvmlite{os.sep}", f"{os.sep}numba{os.sep}")
_RETRY_S = 0.01


def in_compiler(frame: FrameType | None) -> bool:
    """Whether ``frame`` or one of its callers runs code of numba or llvmlite."""
    while frame is not None:
        name = frame.f_code.co_filename
        if any(part in name for part in _COMPILER):
            return True
        frame = frame.f_back
    return False


def interrupt_here(signum: int, frame: FrameType | None) -> bool:
    """For a signal handler: whether to raise the interrupt now (``frame``, the handler's,
    is outside numba and llvmlite); else the signal is delivered to the main thread again
    in 10 ms (``_thread.interrupt_main``), and the handler should return."""
    if not in_compiler(frame):
        return True
    threading.Timer(_RETRY_S, _thread.interrupt_main, (signum,)).start()
    return False
