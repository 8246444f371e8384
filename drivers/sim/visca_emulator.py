"""A VISCA lens controller that speaks the real bytes (:mod:`drivers.visca`), driving the simulated zoom lens.

Packets end in ``FF``. It answers ``address set`` (``88 30 01 FF`` -> ``88 30 02 FF``), ``IF_Clear``
(``88 01 00 01 FF``, echoed), CAM_Zoom Direct (``8x 01 04 47 0p 0q 0r 0s FF``: ACK ``90 41 FF`` at once,
completion ``90 51 FF`` when the zoom arrives, moving at ``zoom_speed`` positions a second), CAM_Focus
Manual / Direct (``8x 01 04 38 03 FF``, ``8x 01 04 48 ... FF``: done at once), the position inquiries
(``8x 09 04 47 FF`` / ``... 48 FF`` -> ``90 50 0p 0q 0r 0s FF``), and with ``90 60 02 FF`` (syntax error)
anything else; a zoom beyond ``zoom_max`` is ``90 61 41 FF`` (not executable). Its address is 1.

The zoom position maps to the simulated zoom lens's focal length linearly over
:data:`drivers.sim.lens.ZOOM_FOCAL_RANGE_MM` (0: the wide end), written into the shared
:class:`~drivers.sim.world.SimWorld` (``world.zoom``) when a move completes, as the simulated camera's own
``set_zoom`` does (the focus position is the controller's own: the world's focus is the camera's).
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

from drivers.sim.lens import ZOOM_FOCAL_RANGE_MM
from drivers.sim.pty_server import serve
from drivers.sim.world import SimWorld
from drivers.visca import ZOOM_TELE, from_nibbles, nibbles

if TYPE_CHECKING:
    from drivers.sim.pty_server import EmulatorHandle, PtyServer

ACK, DONE = b"\x90\x41\xff", b"\x90\x51\xff"
SYNTAX, NOT_EXECUTABLE = b"\x90\x60\x02\xff", b"\x90\x61\x41\xff"


def focal_of(position: float, zoom_max: int = ZOOM_TELE) -> float:
    """The simulated zoom lens's focal length (mm) at a zoom position (linear from the wide end)."""
    wide, tele = ZOOM_FOCAL_RANGE_MM
    return wide + (tele - wide) * float(position) / zoom_max


def position_of(focal_mm: float, zoom_max: int = ZOOM_TELE) -> int:
    """The zoom position of a focal length (the inverse of :func:`focal_of`, rounded)."""
    wide, tele = ZOOM_FOCAL_RANGE_MM
    return int(round((float(focal_mm) - wide) / (tele - wide) * zoom_max))


class ViscaEmulator:
    NAME = "VISCA emulator"

    def __init__(self, world: SimWorld | None = None, *, zoom_max: int = ZOOM_TELE, zoom_speed: float = 32768.0):
        self.world = world
        self.zoom_max = int(zoom_max)
        self.zoom_speed = float(zoom_speed)
        self.zoom = 0.0
        self.focus = 0
        self._target: float | None = None
        self._last = 0.0
        self._buf = bytearray()
        self._lock = threading.Lock()
        self.server: PtyServer | None = None
        self.received: list[bytes] = []
        if world is not None:
            world.zoom = focal_of(0, self.zoom_max)

    def attach(self, server: PtyServer) -> None:
        self.server = server

    def _send(self, data: bytes) -> None:
        if self.server is not None:
            self.server.write(data)

    def on_bytes(self, data: bytes, now: float) -> None:
        with self._lock:
            for b in data:
                self._buf.append(b)
                if b == 0xFF:
                    packet = bytes(self._buf)
                    self._buf.clear()
                    self.received.append(packet)
                    self._packet(packet, now)

    def _packet(self, p: bytes, now: float) -> None:
        if p == b"\x88\x30\x01\xff":
            self._send(b"\x88\x30\x02\xff")  # one device: the next address is 2
        elif p == b"\x88\x01\x00\x01\xff":
            self._send(p)
        elif p[:1] != b"\x81":
            return  # another address: not ours
        elif p[1:4] == b"\x01\x04\x47" and len(p) == 9:
            target = self._position(p[4:8])
            if target is None or target > self.zoom_max:
                self._send(SYNTAX if target is None else NOT_EXECUTABLE)
                return
            self._send(ACK)
            self._advance(now)
            self._target, self._last = float(target), now
        elif p == b"\x81\x01\x04\x38\x03\xff":
            self._send(ACK + DONE)
        elif p[1:4] == b"\x01\x04\x48" and len(p) == 9:
            focus = self._position(p[4:8])
            if focus is None:
                self._send(SYNTAX)
                return
            self.focus = focus  # the controller's own: the simulated camera's lock_focus sets the world's
            self._send(ACK + DONE)
        elif p in (b"\x81\x09\x04\x47\xff", b"\x81\x09\x04\x48\xff"):
            self._advance(now)
            value = int(round(self.zoom)) if p[3] == 0x47 else self.focus
            self._send(b"\x90\x50" + nibbles(value) + b"\xff")
        else:
            self._send(SYNTAX)

    @staticmethod
    def _position(data: bytes) -> int | None:
        try:
            return from_nibbles(data)
        except ValueError:
            return None

    def _advance(self, now: float) -> None:
        """Move the zoom towards its target until ``now``; the completion once there."""
        if self._target is None:
            return
        step = self.zoom_speed * max(0.0, now - self._last)
        self._last = now
        d = self._target - self.zoom
        if abs(d) <= step:
            self.zoom, self._target = self._target, None
            if self.world is not None:
                self.world.zoom = focal_of(self.zoom, self.zoom_max)
            self._send(DONE)
        else:
            self.zoom += step if d > 0 else -step

    def tick(self, now: float) -> None:
        with self._lock:
            self._advance(now)


def start_visca_emulator(world: SimWorld | None = None, **opts: Any) -> EmulatorHandle[ViscaEmulator]:
    """Start a :class:`ViscaEmulator` (``opts``: its keyword arguments) on a new pty."""
    return serve(ViscaEmulator(world, **opts), name="visca")
