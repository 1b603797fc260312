"""The C allocator's settings for a process that rebuilds large models again and again.

glibc serves an allocation above its mmap threshold with fresh pages from the kernel and
unmaps them on free; the threshold adapts to the sizes freed, but never beyond 32 MiB on
64-bit systems. A re-synthesis of the 100 x 100 benchmark grid of
``benchmarks/bench_vi.py`` allocates arrays above that size on every call (the product's
4.3M entries, its reverse index: 34.6 MB per array), so every call faults every page of
them in anew: about 55,000 page faults and 0.1 s of system time each, measured. With the
thresholds of :func:`reuse_freed_memory` freed arrays stay in the heap and the next call
reuses them: no faults, and the full re-synthesis about a tenth faster (seed 0: 0.95-0.99 s
instead of 1.06-1.10 s; seed 1: 0.68-0.70 s instead of 0.77-0.81 s, measured one after the
other on one machine). Solving a model that already exists gains nothing (its arrays are
not allocated again).

The setting belongs to the process, not to a library call: the ``hopnav`` command applies
it at start (``HOPNAV_REUSE_FREED_MEMORY=0`` in the environment leaves the allocator as
it is), as do ``scripts/run_simulation.py`` and ``scripts/make_figures.py``, and
``benchmarks/bench_vi.py``, which times re-syntheses. The price: up to ``threshold``
bytes freed at the top of the heap stay with the process instead of returning to the
system, and allocations below ``threshold`` come from the heap.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

DEFAULT_THRESHOLD = 512 << 20
"""Bytes: allocations below this come from the heap, and the heap gives back to the system
only what lies free above it at its top."""

ENVIRONMENT = "HOPNAV_REUSE_FREED_MEMORY"
"""Set to ``0`` to leave the allocator as it is (:func:`reuse_freed_memory_unless_disabled`)."""

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3


def reuse_freed_memory(threshold: int = DEFAULT_THRESHOLD) -> bool:
    """Raise glibc's mmap and trim thresholds to ``threshold`` bytes (``mallopt``), so that
    freed large arrays are reused rather than unmapped and faulted in again. Returns
    whether both settings took (``False`` on a C library without ``mallopt``, such as
    macOS's or musl's, or where glibc refuses the value: nothing is changed then, or only
    the trim threshold). Calling it again is harmless.

    Raises:
        ValueError: ``threshold`` not a positive int below 2**31.
    """
    if isinstance(threshold, bool) or not isinstance(threshold, int) or not 0 < threshold < 1 << 31:
        raise ValueError(f"threshold must be a positive int below 2**31 bytes, got {threshold!r}")
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    # the mmap threshold first: if glibc refuses it, the trim threshold stays as it was
    # (raised alone, it would turn off the adaptive mmap threshold and fault more)
    if mallopt(_M_MMAP_THRESHOLD, threshold) != 1:
        return False
    return mallopt(_M_TRIM_THRESHOLD, threshold) == 1


def reuse_freed_memory_unless_disabled() -> bool:
    """:func:`reuse_freed_memory` unless the environment variable :data:`ENVIRONMENT` is
    ``0``; whether it was applied."""
    if os.environ.get(ENVIRONMENT, "").strip() == "0":
        return False
    return reuse_freed_memory()
