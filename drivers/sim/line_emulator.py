"""Common machinery of the line-oriented device emulators (Zaber, GRBL).

Bytes from the driver are cut into lines at ``\\r`` or ``\\n``; a subclass
handles each line (``handle_line``) and may claim single realtime bytes
(``handle_realtime``, used by GRBL's ``?``, ``!``, ``~`` and Ctrl-X).
Faults are injected with :meth:`LineEmulator.inject`:

``"reject"``   the next ``count`` commands are refused (device-specific reply)
``"no_reply"`` the next ``count`` commands get no answer at all
``"garbage"``  the next ``count`` replies are replaced by random bytes
``"stall"``    the next move stops at fraction ``at`` of its way with a fault
``"vanish"``   the device disappears (pty master closed) at fraction ``at``
              of the next move

``count=None`` makes a counted fault permanent.

The shared :class:`~drivers.sim.world.SimWorld`, when given, is driven by
this emulator's motion model (:meth:`SimWorld.drive_stage`): the camera
evaluates :meth:`LineEmulator.stage_degrees` at its exposure time, the very
function the emulator answers position queries from, so a frame taken after
the device replied "idle at θ" is rendered at θ (no copy of the angle that a
descheduled thread could leave stale).
"""

from __future__ import annotations

import abc
import random
import threading
from typing import TYPE_CHECKING, Any

from drivers.sim.world import SimWorld

if TYPE_CHECKING:
    from drivers.sim.pty_server import PtyServer


class LineEmulator(abc.ABC):
    """Base class; see the module docstring. ``world`` is an optional SimWorld."""

    COUNTED: tuple[str, ...] = ("reject", "no_reply", "garbage")
    MOTION: tuple[str, ...] = ("stall", "vanish")
    NAME = "device"

    def __init__(self, world: SimWorld | None = None, seed: int = 0):
        self.world = world
        self.server: PtyServer | None = None
        self._inbuf = bytearray()
        self._rng = random.Random(seed)
        self._faults: dict[str, dict[str, Any]] = {}
        self._lock = threading.RLock()
        self.received: list[bytes] = []  # every complete line / realtime byte, for tests
        if world is not None:
            world.drive_stage(self._stage_for_world, self.NAME)

    # -- server hooks ------------------------------------------------------
    def attach(self, server: PtyServer) -> None:
        self.server = server

    def on_bytes(self, data: bytes, now: float) -> None:
        with self._lock:
            for b in data:
                byte = bytes([b])
                if self.handle_realtime(byte, now):
                    self.received.append(byte)
                    continue
                if byte in (b"\r", b"\n"):
                    line = bytes(self._inbuf)
                    self._inbuf.clear()
                    if line:
                        self.received.append(line)
                        self._dispatch(line, now)
                else:
                    self._inbuf += byte

    def tick(self, now: float) -> None:
        with self._lock:
            self.update(now)

    def _stage_for_world(self, t: float) -> float:
        with self._lock:  # not while a command is half-way through
            return self.stage_degrees(t)

    # -- faults --------------------------------------------------------------
    def inject(self, fault: str, count: int | None = 1, at: float = 0.5, **params: Any) -> None:
        """Arm a fault (see module docstring); extra ``params`` are device-specific."""
        allowed = self.COUNTED + self.MOTION
        if fault not in allowed:
            raise ValueError(f"unknown fault {fault!r} for {self.NAME}; expected one of {', '.join(allowed)}")
        if fault in self.MOTION and not 0.0 <= at <= 1.0:
            raise ValueError(f"fault position 'at' must be in [0, 1], got {at}")
        with self._lock:
            self._faults[fault] = {"count": count, "at": float(at), **params}

    def _take_counted(self, fault: str) -> dict[str, Any] | None:
        spec = self._faults.get(fault)
        if spec is None:
            return None
        if spec["count"] is not None:
            spec["count"] -= 1
            if spec["count"] <= 0:
                del self._faults[fault]
        return spec

    def motion_fault(self) -> tuple[str, dict[str, Any]] | None:
        """The armed motion fault (consumed by the subclass when it fires)."""
        for name in self.MOTION:
            if name in self._faults:
                return name, self._faults[name]
        return None

    def consume(self, fault: str) -> None:
        self._faults.pop(fault, None)

    def garbage(self) -> bytes:
        """A line of random bytes that no driver can parse."""
        body = bytes(self._rng.choice([0x00, 0x07, 0x1B, 0x7F, 0x80, 0xA5, 0xFE, 0xFF, 0x3F, 0x5E]) for _ in range(10))
        return b"\xff" + body + b"\r\n"

    def _dispatch(self, line: bytes, now: float) -> None:
        if self._take_counted("no_reply") is not None:
            return
        spec = self._take_counted("garbage")
        if spec is not None:
            self.write(self.garbage())
            return
        spec = self._take_counted("reject")
        if spec is not None:
            self.reject(line, spec, now)
            return
        self.handle_line(line, now)

    # -- output ----------------------------------------------------------------
    def write(self, data: bytes) -> None:
        if self.server is not None:
            self.server.write(data)

    def vanish(self) -> None:
        if self.server is not None:
            self.server.vanish()

    # -- subclass interface ------------------------------------------------
    def handle_realtime(self, byte: bytes, now: float) -> bool:
        """Claim a single realtime byte (True) or let it into the line (False, the default)."""
        return False

    @abc.abstractmethod
    def handle_line(self, line: bytes, now: float) -> None:
        """Answer one complete command line."""

    @abc.abstractmethod
    def reject(self, line: bytes, spec: dict[str, Any], now: float) -> None:
        """Refuse ``line`` the way the device does (the ``"reject"`` fault)."""

    def update(self, now: float) -> None:  # noqa: B027 (optional hook, default no-op)
        """Advance the device's own state to ``now`` (default: nothing moves by itself)."""

    @abc.abstractmethod
    def stage_degrees(self, now: float) -> float:
        """The stage angle at ``now``, in degrees; must not change the device's state
        (the camera's thread calls it, see the module docstring)."""
