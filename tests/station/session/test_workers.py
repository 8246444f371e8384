"""The session's worker processes: started ahead of the first fit, shut down on close."""

from __future__ import annotations

import os

from station.session.workers import FitWorkers


def _pid(_: int) -> int:
    return os.getpid()


def test_warm_up_starts_the_processes_that_map_then_uses():
    pool = FitWorkers(2)
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
    pool = FitWorkers(1)
    pool.warm_up()
    assert pool._pool is None and pool.map is map
    pool.close()
