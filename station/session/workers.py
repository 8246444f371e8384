"""The process pool of a session's fits (cross-validation and bootstrap replicates).

:class:`FitWorkers` creates the pool on first use (``pipeline.workers`` > 1; else
plain ``map``) under the station's pool policy (:func:`station.pool.forkserver_pool`:
``forkserver`` — the session process runs device threads, so it must not fork) and shuts it down with :meth:`FitWorkers.close`.
Its workers end themselves when the session process is gone (a SIGKILLed session
cannot shut its pool down) and ignore Ctrl-C, which the session process handles.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from station.pool import forkserver_pool

PRELOAD = ["station.calibration", "pipeline.fit", "pipeline.uncertainty", "station.qa.report"]
"""Modules the forkserver imports once, so that each worker starts warm (the fits' and the
report's: :func:`station.qa.report.draw_figures` draws in these processes too)."""


class FitWorkers:
    """``map`` over ``n`` worker processes (created when first used), or the builtin ``map`` for ``n <= 1``."""

    def __init__(self, n: int) -> None:
        self.n = int(n)
        self._pool: Any = None
        self._warming: threading.Thread | None = None

    @property
    def map(self) -> Callable[[Callable[[Any], Any], Iterable[Any]], Iterator[Any]]:
        if self.n <= 1:
            return map
        self._join_warming()
        return self._create().map

    def _create(self) -> Any:
        if self._pool is None:
            self._pool = forkserver_pool(self.n, PRELOAD, _exit_with_session, (os.getpid(),))
        return self._pool

    def warm_up(self) -> None:
        """Start the pool's processes now, in the background (``n > 1``; a no-op otherwise).

        The forkserver imports :data:`PRELOAD` (a second or two) and forks the workers while
        the session captures, on the other core, instead of when the first fit needs them.
        Returns at once; :attr:`map` and :meth:`close` wait for the start to end."""
        if self.n <= 1 or self._pool is not None:
            return
        pool = self._create()  # the forkserver is started here, from this (main) thread

        def spawn() -> None:  # blocks until the forkserver has imported PRELOAD and forked
            with contextlib.suppress(Exception):  # a pool that cannot start fails again, visibly, in map
                for f in [pool.submit(int) for _ in range(self.n)]:
                    f.result()

        self._warming = threading.Thread(target=spawn, name="harp-pool-warm-up", daemon=True)
        self._warming.start()

    def _join_warming(self) -> None:
        if self._warming is not None:
            self._warming.join()
            self._warming = None

    def close(self) -> None:
        """Shut the pool down (pending fits are cancelled)."""
        self._join_warming()
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None


def _exit_with_session(pid: int, period_s: float = 0.5) -> None:
    """Process-pool initializer: the worker ends itself once the session process
    ``pid`` is gone. A SIGKILLed session cannot shut its pool down, and its idle
    workers would otherwise wait on the pool's queue (and keep its forkserver) forever.
    (SIGINT is ignored by the pool's policy, :mod:`station.pool`: the session process
    handles Ctrl-C, the frames are kept, the pool is shut down.)"""

    def watch() -> None:
        while True:
            time.sleep(period_s)
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                os._exit(0)
            except PermissionError:  # alive, owned by someone else (cannot happen for our parent)
                continue

    threading.Thread(target=watch, name="harp-session-watch", daemon=True).start()
