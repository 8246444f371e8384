"""Ctrl-C is the command's: delivered to it once, never lost, never a worker's traceback.

A Ctrl-C at the terminal sends SIGINT to the whole process group: the ``harp`` process and
every worker it started. Only the ``harp`` process answers it (one line, exit 130, what was
kept said); this module holds the pieces that make that hold where CPython alone does not.

* :func:`deliver_dropped_ctrl_c`: CPython raises the ``KeyboardInterrupt`` in whatever Python
  code the main thread runs at that moment. When that is a weakref callback or a ``__del__`` (the
  import system runs one whenever a module lock is dropped), the exception cannot propagate:
  CPython prints "Exception ignored in ..." with a traceback and goes on, and the command runs to
  its end as if the key had not been pressed (seen: ``harp reprocess`` interrupted while it
  imported its pool). The hook installed here keeps such an interrupt off stderr and has it
  delivered again to the main thread once the callback has returned.
* :func:`start_forkserver_deaf_to_ctrl_c`: multiprocessing's forkserver imports its preloaded
  modules (a second or two) before it ignores SIGINT itself, and the workers it forks would
  each print a traceback. It is started with SIGINT *blocked* in the starting thread, a mask
  it and its workers inherit through fork and exec; a Ctrl-C meanwhile stays pending in this
  process and is raised here as soon as the forkserver is started (ignoring SIGINT instead, as
  before, dropped a Ctrl-C pressed in that moment).
* :func:`sigint_blocked`: the same for worker processes forked directly (``harp calibrate``'s
  pool): forked inside it, they never run their parent's Ctrl-C handling; and for a stretch
  that must not be cut in the middle (``harp reprocess`` submitting its jobs: no worker left
  half-started), the Ctrl-C then raised as the stretch ends.
* :func:`forget_handled_ctrl_c`: CPython 3.11 marks a ``KeyboardInterrupt`` that leaves an
  ``exec()`` or ``eval()`` of a string as unhandled even when it is caught further up, and then
  ends the process by SIGINT instead of with its exit code (dataclasses and namedtuples are made
  that way: a Ctrl-C while a module defining one was imported made ``harp calibrate`` print its
  "interrupted" line and then die by SIGINT, -2 for a Python caller, instead of exiting 130).
* :func:`stop_signals_as_ctrl_c`: SIGTERM (``systemctl stop``, ``docker stop``, ``timeout``, a
  ``kill``) and SIGHUP (the terminal or the SSH connection closed) are answered as a Ctrl-C is: the
  command's own line (``stopped by SIGTERM`` where a Ctrl-C says ``interrupted``), what was kept
  kept, a session's resume line, its workers stopped, exit ``128 + signal`` (143, 129). Before,
  either killed the process where it stood: no line, no session record of the stop, and
  multiprocessing's "leaked semaphore objects" warning on stderr.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator
from typing import Any

from station.exit_codes import EXIT_INTERRUPTED


def deliver_dropped_ctrl_c() -> None:
    """Install (once per process) the ``sys.unraisablehook`` that delivers again a Ctrl-C that
    CPython had to drop in a weakref callback or ``__del__``: nothing on stderr, and the
    ``KeyboardInterrupt`` raised in the main thread a moment later (``_thread.interrupt_main``
    from a helper thread, which runs once the main thread lets it, i.e. after the callback).
    Any other unraisable exception goes to the hook that was there before."""
    previous = sys.unraisablehook
    if getattr(previous, "_harp_ctrl_c", False):
        return

    def hook(unraisable: Any) -> None:
        if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
            import _thread

            # a bare thread: threading.Thread.start would wait for it here, and the interrupt
            # would land in this hook again
            _thread.start_new_thread(_thread.interrupt_main, ())
            return
        previous(unraisable)

    hook._harp_ctrl_c = True  # type: ignore[attr-defined]
    sys.unraisablehook = hook


@contextlib.contextmanager
def sigint_blocked() -> Iterator[None]:
    """SIGINT blocked in the calling thread inside the block; a Ctrl-C meanwhile is raised
    (``KeyboardInterrupt``) as soon as the block ends, not dropped. Processes forked or started
    inside it inherit the block: they never see a Ctrl-C, not even before their own set-up has
    run (a forked child runs on its parent's Python stack until then, and a ``KeyboardInterrupt``
    there once made a worker print the parent's "interrupted" line, or hold its pool's queue lock
    forever). Outside the main thread it does nothing (signals are the main thread's)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def start_forkserver_deaf_to_ctrl_c() -> None:
    """Start multiprocessing's forkserver (if it is not running) with SIGINT blocked, so that it
    and every worker it forks never see a Ctrl-C; a Ctrl-C during the start is raised here, in
    the calling (main) thread, right after it.

    The resource tracker is started first: starting it blocks and then *unblocks* SIGINT in the
    calling thread (CPython's own way to start it deaf), which would undo the block. From a
    thread other than the main one SIGINT is not delivered anyway (:func:`sigint_blocked` does
    nothing there): the forkserver is simply started."""
    from multiprocessing import forkserver, resource_tracker

    resource_tracker.ensure_running()
    with sigint_blocked():
        forkserver.ensure_running()  # fork + exec: the blocked mask is inherited


def forget_handled_ctrl_c() -> None:
    """Clear CPython's "unhandled KeyboardInterrupt" mark (``_Py_UnhandledKeyboardInterrupt``), for a
    process whose command has answered the Ctrl-C itself: its exit code (130, or what it decided)
    is then the process's, not a death by SIGINT. The mark is set, wrongly, when a
    ``KeyboardInterrupt`` leaves an ``exec``/``eval`` of a string, however it is caught afterwards.
    A no-op where the interpreter does not expose it."""
    import ctypes

    try:
        flag = ctypes.c_int.in_dll(ctypes.pythonapi, "_Py_UnhandledKeyboardInterrupt")
    except (ValueError, AttributeError):  # not this interpreter's symbol (another version or build)
        return
    flag.value = 0


STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGTERM, signal.SIGHUP)
"""The signals that ask a command to stop, answered as a Ctrl-C (:func:`stop_signals_as_ctrl_c`)."""


class Stopped(KeyboardInterrupt):
    """Not a HarpError: a ``KeyboardInterrupt`` (a :data:`STOP_SIGNALS` signal arrived), so that every command's
    Ctrl-C handling (what was kept, a session's resume line, workers stopped) answers it too."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_stopped_by: int | None = None
"""The signal that stopped the command (None: none, or a Ctrl-C): one command per process."""


def stop_signal() -> int | None:
    """The :data:`STOP_SIGNALS` signal that stopped the command; None for a Ctrl-C (or nothing)."""
    return _stopped_by


def stopper() -> str:
    """What stopped the command, for its line: ``"Ctrl-C"``, or the signal's name (``"SIGTERM"``)."""
    return "Ctrl-C" if _stopped_by is None else signal.Signals(_stopped_by).name


def stopped_text() -> str:
    """The first word(s) of the command's line: ``"interrupted"`` (Ctrl-C) or ``"stopped by SIGTERM"``."""
    return "interrupted" if _stopped_by is None else f"stopped by {stopper()}"


def stopped_exit_code() -> int:
    """130 after a Ctrl-C, ``128 + signal`` after a stop signal (143 SIGTERM, 129 SIGHUP), as a shell
    reports a process its signal ended (:mod:`station.exit_codes`)."""
    return EXIT_INTERRUPTED if _stopped_by is None else 128 + _stopped_by


def _raise_stopped(signum: int, _frame: Any) -> None:
    global _stopped_by
    if _stopped_by is not None:  # asked again while stopping: the signal's own action, now
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    _stopped_by = signum
    raise Stopped(signum)


def _default_in_child() -> None:
    """In a process forked from this one (``harp calibrate``'s workers): the stop signals' own action
    again, so that a worker a pool stops with SIGTERM ends at once and never runs the command's handler."""
    for signum in STOP_SIGNALS:  # the handler is installed only over the default action
        with contextlib.suppress(ValueError, OSError):
            if signal.getsignal(signum) is _raise_stopped:
                signal.signal(signum, signal.SIG_DFL)


_at_fork = False


@contextlib.contextmanager
def stop_signals_as_ctrl_c() -> Iterator[None]:
    """Inside the block, each of :data:`STOP_SIGNALS` whose action is the default raises :class:`Stopped` in
    the main thread (a second one while stopping ends the process as before); a signal the caller ignores
    (``nohup``: SIGHUP) or handles stays so. The handlers are restored when the block ends, and processes
    forked inside it get the default action back (:func:`_default_in_child`). Outside the main thread it
    does nothing (signals are the main thread's)."""
    global _stopped_by, _at_fork
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _stopped_by = None
    mine = {}
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) is signal.SIG_DFL:
            mine[signum] = signal.signal(signum, _raise_stopped)
    if not _at_fork:
        os.register_at_fork(after_in_child=_default_in_child)
        _at_fork = True
    try:
        yield
    finally:
        for signum, previous in mine.items():
            signal.signal(signum, previous)
