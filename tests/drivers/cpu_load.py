"""Busy worker processes that keep every core occupied while a test runs.

:func:`cpu_load` starts one process per core (``os.cpu_count()``, at least
2), each spinning on arithmetic until it is stopped or a deadline passes (it
stops by itself: nothing outlives the test even if the test is killed). The
OS then preempts the test's own threads as a loaded station computer would,
which is what exposes cross-thread ordering bugs such as a simulator thread
being descheduled between sending a reply and updating shared state.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import time
from collections.abc import Iterator


def _spin(stop: mp.synchronize.Event, deadline_s: float) -> None:
    end = time.monotonic() + deadline_s
    x = 0
    while time.monotonic() < end and not stop.is_set():
        for i in range(10_000):
            x = (x * 31 + i) % 1_000_003


@contextlib.contextmanager
def cpu_load(processes: int | None = None, deadline_s: float = 120.0) -> Iterator[int]:
    """Keep ``processes`` (default: every core, at least 2) busy inside the block; yields the count."""
    n = processes or max(2, os.cpu_count() or 2)
    ctx = mp.get_context("spawn")  # no fork of a process that runs emulator threads
    stop = ctx.Event()
    workers = [ctx.Process(target=_spin, args=(stop, deadline_s), daemon=True) for _ in range(n)]
    for w in workers:
        w.start()
    try:
        time.sleep(0.3)  # let them start spinning
        yield n
    finally:
        stop.set()
        for w in workers:
            w.join(5.0)
            if w.is_alive():
                w.terminate()
                w.join(5.0)
