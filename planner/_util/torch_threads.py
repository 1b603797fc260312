"""A context manager for torch's intra-op thread count.

The small batches of the GP fits and the leg-angle controller run fastest on one thread (on a
loaded machine several threads cost far more than they gain); callers pick the count for a
block of work and the previous setting comes back afterwards.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch


@contextmanager
def torch_threads(n: int | None) -> Iterator[None]:
    """Run with ``n`` intra-op torch threads (restored afterwards); ``None``: leave as is."""
    old = torch.get_num_threads()
    if n is not None:
        torch.set_num_threads(int(n))
    try:
        yield
    finally:
        torch.set_num_threads(old)
