"""fesdic_core.parallel: a pool owned by an object, resizable, closable, nesting-safe."""
import threading

import numpy as np
import pytest

from fesdic_core import parallel
from fesdic_core.parallel import WorkerPool


def _squares(pool, n=1000, block=37):
    out = np.zeros(n)
    names = set()

    def work(span):
        names.add(threading.current_thread().name)
        out[span] = np.arange(n)[span] ** 2
    pool.for_each_block(work, n, block)
    return out, names


def test_results_are_identical_with_one_and_two_threads():
    with WorkerPool(1) as one, WorkerPool(2) as two:
        a, names_one = _squares(one)
        b, _ = _squares(two)
    np.testing.assert_array_equal(a, np.arange(1000.0) ** 2)
    np.testing.assert_array_equal(a, b)
    assert names_one == {threading.current_thread().name}          # 1 thread: in line


def test_nested_call_runs_in_line_without_deadlock():
    outer_threads, inner_threads = [], []
    pool = WorkerPool(2)

    def inner(k):
        inner_threads.append(threading.get_ident())

    def outer(k):
        outer_threads.append(threading.get_ident())
        pool.for_each_span(inner, 8)                               # would wait on itself
    done = threading.Event()
    runner = threading.Thread(target=lambda: (pool.for_each_span(outer, 4), done.set()),
                              daemon=True)
    runner.start()
    runner.join(timeout=30)
    assert done.is_set(), "nested for_each_span deadlocked"
    pool.close()
    assert len(outer_threads) == 4 and len(inner_threads) == 32
    assert set(inner_threads) <= set(outer_threads)               # inner spans ran in line


def test_an_exception_of_a_span_is_raised_to_the_caller():
    def work(k):
        if k == 3:
            raise ZeroDivisionError("span 3")
    with WorkerPool(2) as pool, pytest.raises(ZeroDivisionError, match="span 3"):
        pool.for_each_span(work, 6)


def test_resizing_restarts_the_threads_with_the_new_size():
    pool = WorkerPool(2)
    try:
        _squares(pool)
        first = pool._executor
        assert pool.started and first._max_workers == 2
        pool.threads = 3
        assert pool.threads == 3 and not pool.started
        out, names = _squares(pool, block=1)
        assert pool._executor._max_workers == 3 and pool._executor is not first
        np.testing.assert_array_equal(out, np.arange(1000.0) ** 2)
        assert all(name.startswith("fesdic") for name in names)
    finally:
        pool.close()
    with pytest.raises(ValueError, match=">= 1"):
        WorkerPool(0)


def test_closing_then_reusing_recreates_the_pool():
    pool = WorkerPool(2)
    _squares(pool)
    first = pool._executor
    pool.close()
    assert not pool.started and first._shutdown
    out, _ = _squares(pool)
    assert pool.started and pool._executor is not first
    np.testing.assert_array_equal(out, np.arange(1000.0) ** 2)
    pool.close()
    pool.close()                                                   # idempotent


def test_a_collected_pool_shuts_its_threads_down():
    import gc
    pool = WorkerPool(2)
    _squares(pool)
    executor = pool._executor
    del pool
    gc.collect()
    assert executor._shutdown


def test_default_pool_size_from_environment_and_context_manager(monkeypatch):
    monkeypatch.setenv(parallel.ENV_THREADS, "3")
    assert parallel.default_threads() == 3 and WorkerPool().threads == 3
    monkeypatch.setenv(parallel.ENV_THREADS, "many")
    with pytest.raises(ValueError, match="FESDIC_THREADS"):
        parallel.default_threads()
    before = parallel.default_pool().threads
    with parallel.threads(1) as pool:
        assert pool is parallel.default_pool() and pool.threads == 1
        seen = []
        parallel.for_each_span(lambda k: seen.append(threading.current_thread().name), 4)
        assert set(seen) == {threading.current_thread().name}
    assert parallel.default_pool().threads == before
    previous = parallel.set_threads(2)
    try:
        assert parallel.default_pool().threads == 2
    finally:
        parallel.set_threads(previous)


def test_resizing_while_other_threads_use_the_pool():
    pool, errors, results = WorkerPool(2), [], []

    def user():
        try:
            for _ in range(20):
                results.append(_squares(pool, n=300, block=7)[0])
        except Exception as exc:                                   # noqa: BLE001 (reported)
            errors.append(exc)
    users = [threading.Thread(target=user) for _ in range(3)]
    for t in users:
        t.start()
    for n in (3, 1, 2, 4, 2) * 4:
        pool.threads = n
    for t in users:
        t.join(timeout=60)
    pool.close()
    assert not errors and len(results) == 60
    for out in results:
        np.testing.assert_array_equal(out, np.arange(300.0) ** 2)
