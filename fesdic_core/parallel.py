"""Blocks of points shared out over threads.

The work of an iteration is a long run of independent points (projection, interpolation,
pull-back of the gradients). It is cut into blocks small enough for their temporaries to
stay in cache, and the blocks are shared out over ``THREADS`` threads: numpy's loops and
the compiled interpolation kernel release the GIL, so the threads run in parallel.
``FESDIC_THREADS`` in the environment sets the number of threads (default: the CPUs, at
most 8); 1 runs everything on the calling thread.
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

__all__ = ["THREADS", "for_each_block", "for_each_span"]

THREADS = max(1, int(os.environ.get("FESDIC_THREADS", min(os.cpu_count() or 1, 8))))


_POOL: ThreadPoolExecutor | None = None


def _pool() -> ThreadPoolExecutor:
    """The threads of the core, started on first use and kept (no start-up cost per call)."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(THREADS, thread_name_prefix="fesdic")
    return _POOL


def for_each_span(work: Callable[[int], None], n_spans: int) -> None:
    """Call ``work(k)`` for ``k`` in ``range(n_spans)``, on the core's threads.

    A call from one of those threads (nested blocks) runs in line, so the pool never waits
    on itself; an exception of a block is raised here.
    """
    if THREADS == 1 or n_spans < 2 or threading.current_thread().name.startswith("fesdic"):
        for k in range(n_spans):
            work(k)
        return
    for _ in _pool().map(work, range(n_spans)):
        pass


def for_each_block(work: Callable[[slice], None], n: int, block: int) -> None:
    """Call ``work(span)`` for consecutive spans of ``block`` items covering ``range(n)``."""
    spans = [slice(a, min(a + block, n)) for a in range(0, n, block)]
    for_each_span(lambda k: work(spans[k]), len(spans))
