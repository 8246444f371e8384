"""station/pool.py: the one worker-pool policy (issue 22 item 5)."""

from __future__ import annotations

import signal


def _disposition(_x: int) -> object:
    import os

    return signal.getsignal(signal.SIGINT), os.environ.get("HARP_POOL_TEST_INIT")


def _mark(value: str) -> None:
    import os

    os.environ["HARP_POOL_TEST_INIT"] = value


def test_forkserver_workers_ignore_ctrl_c_and_run_the_callers_initializer():
    from station.pool import forkserver_pool

    pool = forkserver_pool(1, ["station.pool"], _mark, ("ran",))
    try:
        assert list(pool.map(_disposition, [0])) == [(signal.SIG_IGN, "ran")]
    finally:
        pool.shutdown(cancel_futures=True)


# the session's pool (formerly station.session.workers.FitWorkers): started ahead of the first fit,
# shut down on close


def _pid(_: int) -> int:
    import os

    return os.getpid()


def test_warm_up_starts_the_processes_that_map_then_uses():
    import os

    from station.pool import WorkerPool

    pool = WorkerPool(2)
    try:
        pool.warm_up()  # returns at once; the processes start in the background
        assert pool._pool is not None
        pool.warm_up()  # a second call changes nothing
        assert list(pool.map(abs, [-3, 2, -1])) == [3, 2, 1]
        pids = set(pool.map(_pid, range(8)))
        assert os.getpid() not in pids and 1 <= len(pids) <= 2
    finally:
        pool.close()
    assert pool._pool is None


def test_one_worker_means_no_processes():
    from station.pool import WorkerPool

    pool = WorkerPool(1)
    pool.warm_up()
    assert pool._pool is None and pool.map is map
    pool.close()


def test_forked_workers_ignore_ctrl_c_too():
    """One policy for both start methods: a forked worker ignores SIGINT as a forkserver's does."""
    from station.pool import WorkerPool

    with WorkerPool(2, fork=True) as pool:
        assert [d for d, _ in pool.map(_disposition, [0, 1])] == [signal.SIG_IGN, signal.SIG_IGN]


def _sleep(seconds: float) -> float:
    import time

    time.sleep(seconds)
    return seconds


def _deaf_sleep(seconds: float) -> float:
    import signal
    import time

    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # as a worker hung in a SIGTERM handler: terminate() is not heard
    time.sleep(seconds)
    return seconds


def test_a_worker_deaf_to_sigterm_is_killed_and_the_stop_leaves_no_manager_thread():
    """A job that ignores SIGTERM (standing for a worker hung in a library's crash handler after a fork): the stop
    kills it after :data:`station.pool.TERMINATE_WAIT_S`, well before its job's 60 s, and the executor's manager
    thread has ended."""
    import os
    import threading
    import time

    import pytest

    from station.pool import TERMINATE_WAIT_S, WorkerPool

    pool = WorkerPool(2, fork=True)
    futures = pool.submit_all(_deaf_sleep, [60.0, 60.0])
    while not all(f.running() for f in futures):
        time.sleep(0.01)
    time.sleep(0.5)  # the jobs have set their handlers
    pids = list(pool._pool._processes)
    t0 = time.monotonic()
    pool.stop()
    assert time.monotonic() - t0 < 4 * TERMINATE_WAIT_S
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    assert not [t for t in threading.enumerate() if type(t).__name__ == "_ExecutorManagerThread" and t.is_alive()]


def test_an_exception_leaving_the_pool_stops_its_running_workers():
    """Ctrl-C (any exception) inside ``with WorkerPool``: the running workers are terminated at once,
    not awaited (their jobs would take a minute)."""
    import os
    import time

    import pytest

    from station.pool import WorkerPool

    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt), WorkerPool(2, ["station.pool"]) as pool:
        futures = pool.submit_all(_sleep, [60.0, 60.0, 60.0])
        while not any(f.running() for f in futures):
            time.sleep(0.01)
        pids = list(pool._pool._processes)
        raise KeyboardInterrupt
    assert time.monotonic() - t0 < 30
    assert len(pids) == 2
    assert not any(f.done() and not f.cancelled() and f.exception() is None for f in futures)  # none ran to its end
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_stopped_pool_leaves_no_manager_thread_for_the_exit_hook():
    """After :meth:`WorkerPool.stop` (Ctrl-C) the executor's manager thread has ended, its wake-up pipe
    closed, before the command exits: Python 3.11's exit hook writes to that pipe without a lock and,
    racing the close, printed a traceback after "harp: interrupted" (CPython gh-125451). Without the
    join in ``stop`` the thread was still alive after about half the stops; four stops in a row."""
    import threading

    from station.pool import WorkerPool

    for _ in range(4):
        pool = WorkerPool(2, fork=True)
        pool.submit_all(_sleep, [30.0, 30.0, 30.0])
        pool.stop()
        alive = [t for t in threading.enumerate() if type(t).__name__ == "_ExecutorManagerThread" and t.is_alive()]
        assert not alive
