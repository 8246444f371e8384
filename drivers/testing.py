"""Byte-exact protocol tests: play the device's side of an expected exchange.

:class:`ScriptedDevice` serves a script ``[(sent, reply), ...]`` on a real
pseudo-terminal (see :mod:`drivers.sim.pty_server`): the driver under test
opens :attr:`ScriptedDevice.port` with pyserial like a real device. For
each step the device waits for exactly the bytes ``sent``, then writes
``reply`` (which may be ``b""``). The script fails (``AssertionError`` when
the ``with`` block ends, or from :meth:`ScriptedDevice.verify`) on

- a **mismatch**: the first wrong byte is reported with the step number, the
  expected message, what was actually sent and the byte offset; the device
  stops answering from then on, so the driver usually times out too — the
  mismatch report is raised in preference to the driver's error;
- a **missing** message: the block ended before every step was sent;
- an **extra** message: bytes arrived after the last step (checked after a
  short settle time).

Example::

    exchange = [(b"/1\\n", b"@01 0 OK IDLE -- 0\\r\\n"),
                (b"/1 1 get pos\\n", b"@01 1 OK IDLE -- 0\\r\\n")]
    with ScriptedDevice(exchange) as dev:
        with ZaberTurntable(dev.port) as tt:
            assert tt.position() == 0.0
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence

from drivers.sim.pty_server import PtyServer


def first_difference(expected: bytes, actual: bytes) -> int | None:
    """Index of the first differing byte (or of the end of the shorter), None if equal."""
    for i, (a, b) in enumerate(zip(expected, actual)):
        if a != b:
            return i
    if len(expected) != len(actual):
        return min(len(expected), len(actual))
    return None


class _ScriptHandler:
    def __init__(self, exchange: list[tuple[bytes, bytes]]):
        self.exchange = exchange
        self.step = 0
        self.buf = bytearray()
        self.failure: str | None = None
        self.failed_at: tuple[int, int] | None = None  # (step, byte offset)
        self.extra = bytearray()
        self.log: list[tuple[bytes, bytes]] = []
        self.lock = threading.Lock()
        self.server: PtyServer | None = None

    def attach(self, server: PtyServer) -> None:
        self.server = server

    def on_bytes(self, data: bytes, now: float) -> None:
        with self.lock:
            if self.failure is not None:
                self.buf += data  # keep collecting for the report
                return
            for b in data:
                if self.step >= len(self.exchange):
                    self.extra.append(b)
                    continue
                self.buf.append(b)
                sent, reply = self.exchange[self.step]
                i = len(self.buf) - 1
                if sent[i] != b:
                    self.failed_at = (self.step, i)
                    self.failure = "mismatch"
                    return
                if len(self.buf) == len(sent):
                    self.log.append((bytes(self.buf), reply))
                    self.buf.clear()
                    self.step += 1
                    if reply and self.server is not None:
                        self.server.write(reply)

    def tick(self, now: float) -> None:
        """Server hook for time passing: a script only answers bytes, so nothing to do."""


class ScriptedDevice:
    """A fake serial device that follows an exact script; see module docstring.

    Parameters
    ----------
    exchange : sequence of (bytes, bytes)
        Each step: what the driver must send, what the device answers.
    name : str
        Used in failure messages.
    settle : float
        Seconds to wait for late extra traffic when the block ends.
    """

    def __init__(self, exchange: Sequence[tuple[bytes, bytes]], name: str = "device", settle: float = 0.1):
        steps = []
        for k, step in enumerate(exchange):
            if not (
                isinstance(step, tuple) and len(step) == 2 and isinstance(step[0], bytes) and isinstance(step[1], bytes)
            ):
                raise TypeError(f"exchange step {k} must be a (bytes, bytes) pair, got {step!r}")
            if not step[0]:
                raise ValueError(f"exchange step {k}: the sent bytes must not be empty")
            steps.append(step)
        self.exchange = steps
        self.name = name
        self.settle = settle
        self._handler = _ScriptHandler(steps)
        self._server = PtyServer(self._handler, name=f"script-{name}")
        self.port: str | None = None

    def start(self) -> str:
        self.port = self._server.start()
        return self.port

    def stop(self) -> None:
        self._server.stop()

    @property
    def steps_done(self) -> int:
        return self._handler.step

    def report(self) -> str | None:
        """The failure message, or None if the exchange so far is correct and complete."""
        h = self._handler
        with h.lock:
            if h.failure == "mismatch" and h.failed_at is not None:
                step, offset = h.failed_at
                expected = self.exchange[step][0]
                got = bytes(h.buf)
                exp_b = expected[offset : offset + 1]
                got_b = got[offset : offset + 1]
                return (
                    f"{self.name}: step {step + 1}/{len(self.exchange)}: expected {expected!r},"
                    f" got {got!r}: first difference at byte {offset}"
                    f" (expected {exp_b!r}, got {got_b!r})"
                )
            if h.step < len(self.exchange):
                expected = self.exchange[h.step][0]
                partial = f" (got only {bytes(h.buf)!r})" if h.buf else ""
                return (
                    f"{self.name}: missing message at step {h.step + 1}/{len(self.exchange)}:"
                    f" expected {expected!r} never sent{partial}"
                )
            if h.extra:
                return f"{self.name}: extra message after the last step ({len(self.exchange)}): {bytes(h.extra)!r}"
            return None

    def verify(self) -> None:
        """Raise ``AssertionError`` unless every step was sent exactly and nothing more."""
        time.sleep(self.settle)
        if self._server.error is not None:
            raise AssertionError(f"{self.name}: script server crashed: {self._server.error!r}")
        message = self.report()
        if message:
            raise AssertionError(message)

    def __enter__(self) -> ScriptedDevice:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object) -> None:
        try:
            if exc is not None:
                message = self.report()
                # a wrong byte explains whatever the driver raised afterwards
                if message and self._handler.failure == "mismatch":
                    raise AssertionError(message) from exc
                return  # let the test's own exception propagate
            self.verify()
        finally:
            self.stop()


def expect_exchange(
    exchange: Sequence[tuple[bytes, bytes]], name: str = "device", settle: float = 0.1
) -> ScriptedDevice:
    """Shorthand: ``with expect_exchange([...]) as dev: ... dev.port ...``."""
    return ScriptedDevice(exchange, name=name, settle=settle)
