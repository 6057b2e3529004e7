"""Thread counts in tests: one place that pins torch to a single intra-op thread and always restores it.

Why it matters beyond speed: a float64 convolution or matrix product sums in an order that depends on how the work
is split over threads, so a test that leaks `torch.set_num_threads(1)` changes the rounding of every later test in
the process (and makes it differ from a fresh process, which starts with one thread per core).
"""

from __future__ import annotations

from contextlib import contextmanager

import torch


@contextmanager
def one_thread():
    """Tiny tensors are all per-op overhead; a second thread only adds synchronisation on a shared 2-core machine."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
