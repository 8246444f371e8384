"""Serve a byte-level device emulator on a real pseudo-terminal.

:class:`PtyServer` opens a pty pair (``os.openpty``), puts it in raw mode
(``tty.setraw``) and runs a background thread that feeds every byte written
to the slave side (``/dev/pts/N``, what the driver opens with pyserial) to a
*handler*, and periodically calls the handler's ``tick(now)`` so it can move
simulated motors and send unsolicited messages.

A handler is any object with

- ``attach(server)``: called once; keep ``server`` to ``server.write(bytes)``
  replies and to ``server.vanish()``;
- ``on_bytes(data: bytes, now: float)``: bytes the driver sent;
- ``tick(now: float)``: called every few milliseconds.

``now`` is ``time.monotonic()``. :meth:`PtyServer.vanish` closes the master
side at once, as if the device had been unplugged: the driver's next read or
write on the slave fails (EIO / EOF).
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import threading
import time
import tty
from typing import Generic, Protocol, TypeVar


class Handler(Protocol):
    """What :class:`PtyServer` serves (see the module docstring)."""

    def attach(self, server: PtyServer) -> None: ...
    def on_bytes(self, data: bytes, now: float) -> None: ...
    def tick(self, now: float) -> None: ...


H = TypeVar("H", bound=Handler)


class PtyServer:
    """A handler served on a fresh pty; :attr:`port` is the slave path."""

    def __init__(self, handler: Handler, name: str = "emulator", tick_s: float = 0.002):
        self.handler = handler
        self.name = name
        self.tick_s = tick_s
        self.port: str | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._wlock = threading.Lock()
        self.vanished = False
        self.error: BaseException | None = None  # exception that ended the loop, if any

    def start(self) -> str:
        """Open the pty, start serving; returns the slave device path."""
        master, slave = os.openpty()
        tty.setraw(slave)
        tty.setraw(master)
        self._master, self._slave = master, slave
        self.port = os.ttyname(slave)
        self.handler.attach(self)
        self._thread = threading.Thread(target=self._run, name=f"pty-{self.name}", daemon=True)
        self._thread.start()
        return self.port

    def write(self, data: bytes) -> None:
        """Send bytes to the driver (no-op once vanished or stopped)."""
        with self._wlock:
            fd = self._master
            if fd is None or not data:
                return
            view = memoryview(bytes(data))
            while view:
                try:
                    n = os.write(fd, view)
                except BlockingIOError:
                    time.sleep(0.001)
                    continue
                except OSError:
                    return
                view = view[n:]

    def vanish(self) -> None:
        """Close the master side now: the device is gone."""
        self.vanished = True
        self._close_fds()

    def _close_fds(self) -> None:
        with self._wlock:
            for attr in ("_master", "_slave"):
                fd = getattr(self, attr)
                setattr(self, attr, None)
                if fd is not None:
                    with contextlib.suppress(OSError):  # already closed (e.g. by a "vanish" fault)
                        os.close(fd)

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                fd = self._master
                if fd is None:
                    return
                try:
                    ready, _, _ = select.select([fd], [], [], self.tick_s)
                except (OSError, ValueError):
                    return
                now = time.monotonic()
                if ready:
                    try:
                        data = os.read(fd, 4096)
                    except OSError as exc:
                        if exc.errno in (errno.EIO, errno.EBADF):
                            # EIO: no slave open at the moment; keep serving
                            time.sleep(self.tick_s)
                            continue
                        raise
                    if data:
                        self.handler.on_bytes(data, now)
                self.handler.tick(time.monotonic())
        except BaseException as exc:  # surfaced through .error for tests
            self.error = exc
        finally:
            self._close_fds()

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the thread and close the pty (idempotent)."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self._close_fds()

    def __enter__(self) -> PtyServer:
        if self.port is None:
            self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class EmulatorHandle(Generic[H]):
    """A running emulator: ``port_path`` (give it to the driver), ``emulator``
    (inject faults, read state), ``server`` and ``stop()``. Context manager."""

    def __init__(self, emulator: H, server: PtyServer):
        self.emulator = emulator
        self.server = server
        self.port_path = server.port

    def stop(self) -> None:
        self.server.stop()

    def __enter__(self) -> EmulatorHandle[H]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def __repr__(self) -> str:
        return f"EmulatorHandle({type(self.emulator).__name__} on {self.port_path})"


def serve(emulator: H, name: str = "emulator") -> EmulatorHandle[H]:
    """Serve ``emulator`` on a new pty; returns its :class:`EmulatorHandle`."""
    server = PtyServer(emulator, name=name)
    server.start()
    return EmulatorHandle(emulator, server)
