"""Thread counts in tests: one place that pins torch to a single intra-op thread and always restores it.

Why it matters beyond speed: a float64 convolution or matrix product sums in an order that depends on how the work
is split over threads, so a test that leaks `torch.set_num_threads(1)` changes the rounding of every later test in
the process (and makes it differ from a fresh process, which starts with one thread per core). A test that compares
floats computed under different thread counts (a fresh process, a CLI command in-process: the CLI applies the
thread policy of bodyschema/threads.py, 1 thread on a busy machine) states its tolerance, as
tests/models/contract.py's FRESH_PROCESS_RTOL does; bit-identity holds only under one count.
"""

from __future__ import annotations

from bodyschema.threads import pinned


def one_thread():
    """Tiny tensors are all per-op overhead; a second thread only adds synchronisation on a shared 2-core machine."""
    return pinned(1)
