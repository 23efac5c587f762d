"""Blocks of points shared out over threads.

The work of an iteration is a long run of independent points (projection, interpolation,
pull-back of the gradients). It is cut into blocks small enough for their temporaries to
stay in cache, and the blocks are shared out over the threads of a :class:`WorkerPool`:
numpy's loops and the compiled interpolation kernel release the GIL, so the threads run
in parallel.

The core uses one default pool (:func:`default_pool`) through :func:`for_each_span` and
:func:`for_each_block`. Its size is ``FESDIC_THREADS`` from the environment (default: the
CPUs, at most 8), changed with :func:`set_threads` or, for a block of code, with
``with threads(n): ...``; 1 runs everything on the calling thread. The threads start on
first use, are kept between calls, and are shut down at interpreter exit (or by
:meth:`WorkerPool.close`, after which the next call starts them again).
"""
from __future__ import annotations

import contextlib
import os
import threading
import weakref
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterator

from fesdic_core.errors import FesdicCoreError

__all__ = ["ThreadCountError", "WorkerPool", "default_pool", "default_threads", "for_each_block",
           "for_each_span", "set_threads", "threads"]

ENV_THREADS = "FESDIC_THREADS"


class ThreadCountError(FesdicCoreError, ValueError):
    """The environment variable ``FESDIC_THREADS`` is not a whole number of threads."""


#: set on the threads of every pool: work they submit runs in line (no pool waits on itself)
_worker = threading.local()


def default_threads() -> int:
    """``FESDIC_THREADS`` from the environment, else the CPUs (at most 8); at least 1."""
    text = os.environ.get(ENV_THREADS)
    if text is None:
        return min(os.cpu_count() or 1, 8)
    try:
        return max(1, int(text))
    except ValueError:
        raise ThreadCountError(f"{ENV_THREADS}={text!r}: expected a whole number of threads") from None


def _check_size(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"number of threads must be a whole number >= 1, got {n!r}")
    return n


def _mark_worker() -> None:
    _worker.active = True


def _in_worker() -> bool:
    return getattr(_worker, "active", False)


class WorkerPool:
    """A resizable pool of threads, started on first use and kept until :meth:`close`.

    Parameters
    ----------
    threads : int, optional
        Number of threads (default: :func:`default_threads`). 1 runs all work on the
        calling thread.

    Examples
    --------
    >>> with WorkerPool(2) as pool:
    ...     out = [0] * 4
    ...     pool.for_each_span(lambda k: out.__setitem__(k, k * k), 4)
    >>> out
    [0, 1, 4, 9]
    """

    def __init__(self, threads: int | None = None):
        self._threads = default_threads() if threads is None else _check_size(threads)
        self._lock = threading.Lock()
        self._executor: ThreadPoolExecutor | None = None
        self._finalizer: weakref.finalize | None = None

    @property
    def threads(self) -> int:
        """Number of threads of the pool."""
        return self._threads

    @threads.setter
    def threads(self, n: int) -> None:
        n = _check_size(n)
        with self._lock:
            if n == self._threads:
                return
            self._threads = n
            old = self._detach()
        if old is not None:
            old(wait=False)             # work already handed to the old threads still finishes

    @property
    def started(self) -> bool:
        """Whether the threads are running (they start on the first parallel call)."""
        return self._executor is not None

    def _detach(self):
        """Forget the executor (under the lock); return its shutdown call, or None."""
        finalizer, self._executor, self._finalizer = self._finalizer, None, None
        detached = finalizer.detach() if finalizer is not None else None
        return None if detached is None else detached[1]      # (pool, shutdown, args, kwargs)

    def _start(self) -> ThreadPoolExecutor:
        """The running executor, started if needed (under the lock)."""
        if self._executor is None:
            executor = ThreadPoolExecutor(self._threads, thread_name_prefix="fesdic",
                                          initializer=_mark_worker)
            # shut down when the pool is collected or, at the latest, at interpreter exit
            self._finalizer = weakref.finalize(self, executor.shutdown, wait=False)
            self._executor = executor
        return self._executor

    def for_each_span(self, work: Callable[[int], None], n_spans: int) -> None:
        """Call ``work(k)`` for ``k`` in ``range(n_spans)`` on the pool's threads.

        A call from a thread of a pool (nested blocks) runs in line, so a pool never waits
        on itself; the first exception of a span is raised here.
        """
        if self._threads == 1 or n_spans < 2 or _in_worker():
            for k in range(n_spans):
                work(k)
            return
        with self._lock:            # all spans handed over before a resize or close may act
            results = self._start().map(work, range(n_spans))
        for _ in results:
            pass

    def for_each_block(self, work: Callable[[slice], None], n: int, block: int) -> None:
        """Call ``work(span)`` for consecutive spans of ``block`` items covering ``range(n)``."""
        spans = [slice(a, min(a + block, n)) for a in range(0, n, block)]
        self.for_each_span(lambda k: work(spans[k]), len(spans))

    def close(self) -> None:
        """Stop the threads (after their work); the next parallel call starts new ones."""
        with self._lock:
            shutdown = self._detach()
        if shutdown is not None:
            shutdown(wait=True)

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


_DEFAULT = WorkerPool()


def default_pool() -> WorkerPool:
    """The pool used by :func:`for_each_span` and :func:`for_each_block`."""
    return _DEFAULT


def set_threads(n: int) -> int:
    """Set the number of threads of the default pool; return the previous number."""
    previous = _DEFAULT.threads
    _DEFAULT.threads = n
    return previous


@contextlib.contextmanager
def threads(n: int) -> Iterator[WorkerPool]:
    """Run a block with ``n`` threads in the default pool, then restore the previous size.

    The size is that of the one default pool, so other threads using the core meanwhile
    see it too.
    """
    previous = set_threads(n)
    try:
        yield _DEFAULT
    finally:
        set_threads(previous)


def for_each_span(work: Callable[[int], None], n_spans: int) -> None:
    """Call ``work(k)`` for ``k`` in ``range(n_spans)`` on the default pool's threads.

    A call from one of those threads (nested blocks) runs in line, so the pool never waits
    on itself; an exception of a block is raised here.
    """
    _DEFAULT.for_each_span(work, n_spans)


def for_each_block(work: Callable[[slice], None], n: int, block: int) -> None:
    """Call ``work(span)`` for consecutive spans of ``block`` items covering ``range(n)``."""
    _DEFAULT.for_each_block(work, n, block)
