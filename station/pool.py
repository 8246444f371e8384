"""The worker pools of the station: one policy, written once.

:func:`forkserver_pool` is the pool of a session's fits (:class:`station.session.workers.FitWorkers`)
and of ``harp reprocess`` (:func:`station.reprocess.run_jobs`): the ``forkserver`` start method
(the session process runs device threads, so it must not fork), the forkserver started deaf to
Ctrl-C (:func:`station.ctrl_c.start_forkserver_deaf_to_ctrl_c`: it and every worker it forks have
SIGINT blocked from their first instruction), a preload list the forkserver imports once (each
worker starts warm), and every worker ignoring SIGINT (:func:`ignore_ctrl_c`: Ctrl-C reaches the
whole process group; the command handles it, no worker prints a traceback). ``harp calibrate``
forks its workers instead (:mod:`station.cli.calibrate`: no threads, shots measured while the
fitting is imported) with the same SIGINT policy (:func:`ignore_ctrl_c`, forked inside
:func:`station.ctrl_c.sigint_blocked`).
"""

from __future__ import annotations

import signal
from collections.abc import Callable, Sequence
from typing import Any

from station.ctrl_c import start_forkserver_deaf_to_ctrl_c


def ignore_ctrl_c() -> None:
    """In a worker: SIGINT ignored (Ctrl-C is the command's to handle)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _start_worker(initializer: Callable[..., None] | None, initargs: tuple[Any, ...]) -> None:
    ignore_ctrl_c()
    if initializer is not None:
        initializer(*initargs)


def forkserver_pool(
    n: int,
    preload: Sequence[str],
    initializer: Callable[..., None] | None = None,
    initargs: tuple[Any, ...] = (),
) -> Any:
    """A ``ProcessPoolExecutor`` of ``n`` workers under the station's policy (module docstring);
    ``initializer(*initargs)`` runs in each worker after SIGINT is ignored."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    ctx = mp.get_context("forkserver")  # not fork: the calling process may run threads
    ctx.set_forkserver_preload(list(preload))
    start_forkserver_deaf_to_ctrl_c()
    return ProcessPoolExecutor(
        max_workers=n, mp_context=ctx, initializer=_start_worker, initargs=(initializer, initargs)
    )
