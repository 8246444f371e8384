"""The worker processes of the station: one pool, one policy, written once.

:class:`WorkerPool` runs every job the station shares out among processes: a session's fits
(:class:`station.session.executor.Executor`) and its report's figures
(:func:`station.qa.plots.draw_figures`), ``harp reprocess``'s focus settings
(:func:`station.reprocess.run_jobs`), ``harp calibrate``'s shots and candidates
(:mod:`station.cli.calibrate`). Its policy:

* **start method**: ``forkserver`` (the calling process may run threads, a session's devices,
  so it must not fork); the forkserver imports the pool's ``preload`` list once, so that each
  worker starts warm. A caller that runs no thread may ask to ``fork`` instead (``harp
  calibrate``: its workers share what it has imported and measured); the objects alive then
  are left alone by the garbage collector (``gc.freeze``) so that a worker copies only the
  memory pages it writes, not every page the collector would walk (2-4x fewer page faults).
* **Ctrl-C** is the command's (:mod:`station.ctrl_c`): the forkserver is started deaf to it
  (:func:`station.ctrl_c.start_forkserver_deaf_to_ctrl_c`), jobs are submitted, and so workers
  started, with SIGINT blocked (:func:`station.ctrl_c.sigint_blocked`: a Ctrl-C meanwhile is
  raised once they are), and every worker ignores SIGINT (:func:`ignore_ctrl_c`: Ctrl-C reaches
  the whole process group; no worker prints a traceback). An exception leaving the pool's
  ``with`` block (Ctrl-C) terminates the running workers and drops the jobs not started
  (:meth:`WorkerPool.stop`).
* **lifetime**: the processes are started when first used (or in the background by
  :meth:`WorkerPool.warm_up`); each worker ends itself once the process that started the pool
  is gone (a SIGKILLed command cannot shut its pool down, and its idle workers would wait on
  the pool's queue, and keep its forkserver, forever).
* ``n <= 1``: no process; :attr:`WorkerPool.map` is the built-in ``map``.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

from station.ctrl_c import sigint_blocked, start_forkserver_deaf_to_ctrl_c

TERMINATE_WAIT_S = 5.0
"""How long :meth:`WorkerPool.stop` waits for a worker to end after its SIGTERM before it kills it. Once, in a
clean-clone CI run, a forked worker did not end and the pool's manager thread outlived the stop
(``tests/station/test_pool.py``); its stderr showed a library's crash handler for SIGTERM ("*** Aborted at ...",
glog's), which in a child forked from a process with threads can hang on a lock no thread of the child holds."""


def ignore_ctrl_c() -> None:
    """In a worker: SIGINT ignored (Ctrl-C is the command's to handle)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _exit_with(pid: int, period_s: float = 0.5) -> None:
    """In a worker: end this process once the process ``pid`` (the pool's owner) is gone."""

    def watch() -> None:
        while True:
            time.sleep(period_s)
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                os._exit(0)
            except PermissionError:  # alive, owned by someone else (cannot happen for our parent)
                continue

    threading.Thread(target=watch, name="harp-pool-owner-watch", daemon=True).start()


def _start_worker(owner: int, initializer: Callable[..., None] | None, initargs: tuple[Any, ...]) -> None:
    ignore_ctrl_c()
    _exit_with(owner)
    if initializer is not None:
        initializer(*initargs)


def _process_pool(
    n: int,
    method: str,
    preload: Sequence[str] = (),
    initializer: Callable[..., None] | None = None,
    initargs: tuple[Any, ...] = (),
) -> Any:
    """A ``ProcessPoolExecutor`` of ``n`` workers started by ``method`` under the policy."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    ctx = mp.get_context(method)
    if method == "forkserver":
        ctx.set_forkserver_preload(list(preload))
        start_forkserver_deaf_to_ctrl_c()
    return ProcessPoolExecutor(
        max_workers=n, mp_context=ctx, initializer=_start_worker, initargs=(os.getpid(), initializer, initargs)
    )


def forkserver_pool(
    n: int,
    preload: Sequence[str],
    initializer: Callable[..., None] | None = None,
    initargs: tuple[Any, ...] = (),
) -> Any:
    """The ``ProcessPoolExecutor`` of a :class:`WorkerPool` that does not fork (module docstring);
    ``initializer(*initargs)`` runs in each worker after SIGINT is ignored."""
    return _process_pool(n, "forkserver", preload, initializer, initargs)


class WorkerPool:
    """``n`` worker processes under the station's policy (module docstring).

    Parameters
    ----------
    n : the number of processes (``<= 1``: none, the built-in ``map``).
    preload : modules the forkserver imports once.
    fork : fork the workers from this process instead (only for a process that runs no thread).
    """

    def __init__(self, n: int, preload: Sequence[str] = (), *, fork: bool = False) -> None:
        self.n = int(n)
        self.preload = list(preload)
        self.fork = fork
        self._pool: Any = None
        self._frozen = False
        self._warming: threading.Thread | None = None

    def _create(self) -> Any:
        if self._pool is None:
            if self.fork:
                import gc

                gc.freeze()
                self._frozen = True
            self._pool = _process_pool(self.n, "fork" if self.fork else "forkserver", self.preload)
        return self._pool

    @property
    def map(self) -> Callable[..., Iterator[Any]]:
        """``map(fn, *iterables)`` over the workers (every job submitted at once, the results in
        order), or the built-in ``map`` for ``n <= 1``."""
        if self.n <= 1:
            return map

        def map_fn(fn: Callable[..., Any], *iterables: Iterable[Any]) -> Iterator[Any]:
            pool = self._ready()
            with sigint_blocked():  # submitting starts the workers: none runs this process's Ctrl-C
                return pool.map(fn, *iterables)  # type: ignore[no-any-return]

        return map_fn

    def submit_all(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> list[Any]:
        """One future of ``fn(item)`` per item, all submitted at once (no worker left half-started)."""
        pool = self._ready()
        with sigint_blocked():
            return [pool.submit(fn, item) for item in items]

    def _ready(self) -> Any:
        self._join_warming()
        return self._create()

    def warm_up(self) -> None:
        """Start the processes now, in the background (``n > 1``; a no-op otherwise).

        The forkserver imports the preload list (a second or two) and forks the workers while
        the caller goes on (a session captures), on another core, instead of when the first job
        needs them. Returns at once; :attr:`map`, :meth:`submit_all` and :meth:`close` wait for
        the start to end."""
        if self.n <= 1 or self._pool is not None:
            return
        pool = self._create()  # the forkserver is started here, from this (main) thread

        def spawn() -> None:  # blocks until the forkserver has imported the preload list and forked
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
        """Shut the pool down: the jobs not started are cancelled, the running ones awaited."""
        self._join_warming()
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None
        self._thaw()

    def stop(self) -> None:
        """Terminate the running workers and drop the jobs not started (Ctrl-C); a worker still alive
        :data:`TERMINATE_WAIT_S` after its SIGTERM is killed."""
        pool, self._pool = self._pool, None
        if pool is not None:
            procs = list((getattr(pool, "_processes", None) or {}).values())
            for proc in procs:
                proc.terminate()
            for proc in procs:
                proc.join(TERMINATE_WAIT_S)
                if proc.is_alive():  # deaf to SIGTERM, or hung in a handler of it: SIGKILL is neither
                    proc.kill()
                    proc.join(TERMINATE_WAIT_S)
            manager = getattr(pool, "_executor_manager_thread", None)  # shutdown forgets it
            pool.shutdown(wait=False, cancel_futures=True)
            if manager is not None:
                # the manager thread closes its wake-up pipe as it ends, and Python 3.11's exit hook
                # (concurrent.futures.process._python_exit) writes to that pipe without a lock: a Ctrl-C exit
                # racing the close printed "OSError: [Errno 9] Bad file descriptor" after our one line
                # (CPython gh-125451, fixed in later versions). The workers are dead, so it ends at once.
                manager.join(5)
        self._thaw()

    def _thaw(self) -> None:
        if self._frozen:
            import gc

            gc.unfreeze()  # this process collects them again (a long-lived caller, a test session)
            self._frozen = False

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, exc_type: Any, *_: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.stop()
