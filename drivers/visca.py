"""A zoom lens driven over serial by a VISCA lens controller (Sony VISCA, the protocol of zoom-block
cameras and their lens controllers), via pyserial.

Packets are bytes ending in ``FF``; a command to device ``x`` (1..7) starts with ``8x``, its replies with
``y0`` (``y = x + 8``)::

    88 30 01 FF                   88 30 02 FF               address set (one device on the chain)
    88 01 00 01 FF                88 01 00 01 FF            IF_Clear (broadcast)
    81 01 04 47 0p 0q 0r 0s FF    90 41 FF ... 90 51 FF     CAM_Zoom Direct: ACK, then completion
    81 09 04 47 FF                90 50 0p 0q 0r 0s FF      CAM_ZoomPosInq
    81 01 04 38 03 FF             90 41 FF  90 51 FF        CAM_Focus Manual
    81 01 04 48 0p 0q 0r 0s FF    90 41 FF ... 90 51 FF     CAM_Focus Direct
    81 09 04 48 FF                90 50 0p 0q 0r 0s FF      CAM_FocusPosInq

A position ``pqrs`` is sent one nibble a byte. Zoom positions run from 0 (wide) to ``zoom_max`` (the
optical tele end, 0x4000 on Sony's FCB blocks); :meth:`ViscaLens.set_zoom` sends the direct command,
waits for its completion (the ACK only means the command was taken into socket ``y``) and reads the
position back. Errors: ``y0 6z 02 FF`` syntax error, ``03`` command buffer full, ``04`` cancelled,
``05`` no socket, ``41`` not executable now -> :class:`~drivers.errors.DeviceRejected` naming it; no
reply -> :class:`~drivers.errors.DeviceTimeout`; a packet that is not VISCA ->
:class:`~drivers.errors.ProtocolError`; port gone -> :class:`~drivers.errors.DeviceDisconnected`.

References
----------
Sony, "FCB-EV7520 Technical Manual" (VISCA command list: CAM_Zoom, CAM_Focus, inquiries, ACK,
completion and error messages) and "EVI-D70 Technical Manual" (VISCA packet format, address set,
IF_Clear).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from typing import Any

from drivers.config_keys import check_config_keys
from drivers.errors import DeviceRejected, DeviceTimeout, ProtocolError
from drivers.protocols import Range
from drivers.settings import REQUIRED, Setting
from drivers.transport import SerialTransport

ZOOM_TELE = 0x4000
"""The optical tele end of Sony's FCB zoom blocks (0 is the wide end)."""

ERRORS = {
    0x01: "message length error",
    0x02: "syntax error",
    0x03: "command buffer full",
    0x04: "command cancelled",
    0x05: "no socket",
    0x41: "command not executable",
}

SETTINGS: dict[str, Setting] = {
    "port": Setting("serial device of the lens controller, or a pyserial URL ('emulator': the simulated "
                    "station's)", "text", default=REQUIRED),
    "baudrate": Setting("serial speed", "integer", "baud", choices=(9600, 19200, 38400)),
    "address": Setting("the controller's VISCA address", "integer", "", 1, 7),
    "zoom_max": Setting("the zoom position of the tele end", "integer", "", 1, 0xFFFF),
    "reply_timeout": Setting("wait for each reply", "number", "s", 0.0, 60.0, low_open=True),
    "move_timeout": Setting("longest zoom or focus move", "number", "s", 0.0, 600.0, low_open=True),
}  # fmt: skip
"""The keys of a VISCA lens controller's configuration, each with its type, unit and range."""


def nibbles(value: int) -> bytes:
    """``0p 0q 0r 0s`` of a 16-bit position."""
    if not 0 <= value <= 0xFFFF:
        raise ValueError(f"a VISCA position is 0..0xFFFF, got {value}")
    return bytes((value >> s) & 0x0F for s in (12, 8, 4, 0))


def from_nibbles(data: bytes) -> int:
    """The position of ``0p 0q 0r 0s`` (each byte's high nibble must be 0)."""
    if len(data) != 4 or any(b & 0xF0 for b in data):
        raise ValueError(f"not four position nibbles: {data.hex(' ')}")
    return (data[0] << 12) | (data[1] << 8) | (data[2] << 4) | data[3]


class ViscaLens:
    """A VISCA lens controller's zoom (and focus): :class:`drivers.protocols.Zoomable` positions in the
    controller's units.

    Parameters
    ----------
    port : serial device or pyserial URL.
    address : the controller's VISCA address (1; set with ``address set`` at ``open()``).
    zoom_max : the tele end's position (0x4000).
    reply_timeout : seconds to wait for each reply; move_timeout : for a move's completion.
    """

    CONFIG_KEYS: frozenset[str] = frozenset({"driver", *SETTINGS})
    SETTINGS: Mapping[str, Setting] = SETTINGS

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 9600,
        address: int = 1,
        zoom_max: int = ZOOM_TELE,
        reply_timeout: float = 1.0,
        move_timeout: float = 10.0,
        name: str | None = None,
    ):
        if not 1 <= int(address) <= 7:
            raise ValueError(f"VISCA address must be 1..7, got {address!r}")
        if not 1 <= int(zoom_max) <= 0xFFFF:
            raise ValueError(f"zoom_max must be 1..0xFFFF, got {zoom_max!r}")
        self.address = int(address)
        self.zoom_max = int(zoom_max)
        self.reply_timeout = float(reply_timeout)
        self.move_timeout = float(move_timeout)
        self.name = name or f"visca {port} address {address}"
        self.transport = SerialTransport(port, baudrate, name=self.name)
        self._lock = threading.RLock()

    @classmethod
    def from_config(cls, cfg: dict[str, Any], **ctx: Any) -> ViscaLens:
        check_config_keys("visca lens controller", cfg, SETTINGS, {"port": "device name or pyserial URL"})
        kw = {k: v for k, v in cfg.items() if k != "driver"}
        return cls(kw.pop("port"), **kw)

    # -- life cycle -------------------------------------------------------------------------------
    def open(self) -> None:
        """Open the port, set the address (``88 30 01 FF``) and clear the interface (``IF_Clear``)."""
        self.transport.open()
        try:
            with self._lock:
                self.transport.pending()
                got = self._exchange(b"\x88\x30\x01\xff", "address set")
                if got[:2] != b"\x88\x30":
                    raise ProtocolError(f"{self.name}: address set answered {got.hex(' ')}")
                got = self._exchange(b"\x88\x01\x00\x01\xff", "IF_Clear")
                if got != b"\x88\x01\x00\x01\xff":
                    raise ProtocolError(f"{self.name}: IF_Clear answered {got.hex(' ')}")
        except Exception:
            self.transport.close()
            raise

    def close(self) -> None:
        self.transport.close()

    def __enter__(self) -> ViscaLens:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- wire level ------------------------------------------------------------------------------
    def _read_packet(self, timeout: float, what: str) -> bytes:
        packet = self.transport.readline(timeout, what, eol=b"\xff", total=timeout)
        return packet.lstrip(b"\x00") + b"\xff"  # (padding some controllers send between packets)

    def _exchange(self, data: bytes, what: str) -> bytes:
        self.transport.write(data)
        return self._read_packet(self.reply_timeout, f"reply to {what}")

    def _reply_head(self) -> int:
        return (self.address + 8) << 4  # y0 with y = address + 8

    def _check(self, packet: bytes, what: str) -> int:
        """The kind of a reply to our command (4 ACK, 5 completion); DeviceRejected for an error."""
        if len(packet) < 3 or packet[0] != self._reply_head() or packet[-1] != 0xFF:
            raise ProtocolError(f"{self.name}: not a VISCA reply to {what}: {packet.hex(' ')}")
        kind = packet[1] >> 4
        if kind == 6:
            code = packet[2] if len(packet) > 3 else -1
            raise DeviceRejected(f"{self.name}: {what} refused: {ERRORS.get(code, f'error {code:#04x}')}")
        return kind

    def command(self, body: bytes, what: str, timeout: float | None = None) -> None:
        """Send ``8x`` + ``body`` + ``FF`` and wait for its ACK and completion."""
        deadline = time.monotonic() + (self.move_timeout if timeout is None else timeout)
        with self._lock:
            self.transport.write(bytes([0x80 + self.address]) + body + b"\xff")
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeout(f"{self.name}: {what} not completed")
                kind = self._check(self._read_packet(remaining, what), what)
                if kind == 5:
                    return

    def inquire(self, body: bytes, what: str) -> bytes:
        """Send the inquiry ``8x 09`` + ``body`` + ``FF``; the data of its ``y0 50 ... FF`` answer."""
        with self._lock:
            self.transport.write(bytes([0x80 + self.address, 0x09]) + body + b"\xff")
            packet = self._read_packet(self.reply_timeout, f"reply to {what}")
        if self._check(packet, what) != 5:
            raise ProtocolError(f"{self.name}: {what} answered {packet.hex(' ')}")
        return packet[2:-1]

    # -- zoom (drivers.protocols.Zoomable) -------------------------------------------------------
    def zoom_range(self) -> Range:
        return Range(0.0, float(self.zoom_max), "", "VISCA zoom positions, 0 = wide")

    def set_zoom(self, position: float) -> float:
        """Zoom to ``position`` (CAM_Zoom Direct), wait for the completion; the position read back."""
        p = int(round(self.zoom_range().check(self.name, "zoom to", position)))
        self.command(b"\x01\x04\x47" + nibbles(p), f"zoom to {p:#06x}")
        return self.get_zoom()

    def get_zoom(self) -> float:
        try:
            return float(from_nibbles(self.inquire(b"\x04\x47", "CAM_ZoomPosInq")))
        except ValueError as exc:
            raise ProtocolError(f"{self.name}: CAM_ZoomPosInq: {exc}") from None

    # -- focus -----------------------------------------------------------------------------------
    def lock_focus(self, position: float) -> float:
        """Manual focus at ``position`` (CAM_Focus Manual, then Direct); the position read back."""
        p = int(round(position))
        self.command(b"\x01\x04\x38\x03", "CAM_Focus Manual")
        self.command(b"\x01\x04\x48" + nibbles(p), f"focus to {p:#06x}")
        return self.get_focus()

    def get_focus(self) -> float:
        try:
            return float(from_nibbles(self.inquire(b"\x04\x48", "CAM_FocusPosInq")))
        except ValueError as exc:
            raise ProtocolError(f"{self.name}: CAM_FocusPosInq: {exc}") from None

    def __repr__(self) -> str:
        return f"ViscaLens({self.transport.port!r}, address={self.address})"
