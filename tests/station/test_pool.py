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
