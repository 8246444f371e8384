"""Line-oriented serial transport shared by the turntable drivers.

A :class:`SerialTransport` opens a pyserial port from a device name
(``/dev/ttyUSB0``, ``/dev/pts/3``, ``COM3``) or from any pyserial URL
(``socket://host:port``, ``rfc2217://...``, ``loop://``) through
:func:`serial.serial_for_url`, reads lines against a deadline and turns every
low-level failure into one of the driver errors of :mod:`drivers.errors`:

- no complete line before the deadline -> :class:`~drivers.errors.DeviceTimeout`
- EOF, ``OSError`` or a pyserial ``SerialException`` while reading or
  writing (port closed, cable pulled, pty master gone) ->
  :class:`~drivers.errors.DeviceDisconnected`
- the port cannot be opened -> :class:`~drivers.errors.DeviceDisconnected`; a ``socket://``,
  ``rfc2217://`` or ``loop://`` URL that is malformed says what is wrong with it (:func:`url_problem`),
  before pyserial, whose own checks answer some with a ``KeyError`` or an unrelated text

A device port (not a URL) is opened for this process alone (pyserial's ``exclusive``: an ``flock``):
another program that opens it so too -- a second ``harp session run`` or ``harp live`` of the station,
``harp devices --probe`` -- is told the port is in use instead of taking the replies the first one waits
for.
"""

from __future__ import annotations

import contextlib
import errno
import termios
import threading
import time
from typing import Any
from urllib.parse import parse_qs, urlsplit

import serial

from drivers.errors import DeviceDisconnected, DeviceTimeout

# pyserial read() poll period: read(1) returns as soon as one byte is there,
# so this only bounds how late a deadline is noticed.
_POLL = 0.02
# what pyserial lets through when the device disappears (termios.error is
# not an OSError: tcdrain/tcflush on a hung-up pty raise it)
_IO_ERRORS: tuple[type[Exception], ...] = (serial.SerialException, OSError, termios.error)
# ... and what opening a port raises besides (a malformed URL)
_OPEN_ERRORS: tuple[type[Exception], ...] = (*_IO_ERRORS, ValueError)


_URL_OPTIONS = {
    "socket": ("logging",),
    "loop": ("logging",),
    "rfc2217": ("logging", "ign_set_control", "poll_modem", "timeout"),
}
"""The options each of pyserial's URL handlers takes (``serial/urlhandler``, ``serial/rfc2217.py``)."""
_LOG_LEVELS = ("debug", "info", "warning", "error")


def url_problem(port: str) -> str | None:
    """What is wrong with ``port`` as a ``socket://``, ``rfc2217://`` or ``loop://`` URL (None: nothing, or
    another kind of port, left to pyserial). pyserial's own checks of these formats the message with the
    URL's pattern and fails on its braces: a ``KeyError`` out of ``open()`` (``loop://?logging=bogus``),
    or the text ``'debug|info|warning|error'`` for ``socket://host:http``."""
    scheme = port.partition("://")[0].lower() if "://" in port else ""
    if scheme not in _URL_OPTIONS:
        return None
    form = "loop://[?logging=LEVEL]" if scheme == "loop" else f"{scheme}://HOST:PORT (PORT a number from 0 to 65535)"
    try:
        parts = urlsplit(port)
        number = parts.port
    except ValueError:  # a port that is not a number or beyond 65535, a broken IPv6 address
        return f"expected {form}"
    if scheme != "loop" and number is None:  # (no host: pyserial connects to this machine)
        return f"expected {form}"
    for option, values in parse_qs(parts.query, keep_blank_values=True).items():
        if option not in _URL_OPTIONS[scheme]:
            return f"unknown option {option!r}; a {scheme}:// URL takes {', '.join(_URL_OPTIONS[scheme])}"
        if option == "logging" and values[0] not in _LOG_LEVELS:
            return f"logging={values[0]!r}: expected one of {', '.join(_LOG_LEVELS)}"
    return None


class SerialTransport:
    """A serial port read line by line with deadlines.

    Parameters
    ----------
    port : str
        Device name or pyserial URL.
    baudrate : int
        Line speed (ignored by ptys and sockets, honoured by real UARTs).
    name : str
        Short device description used at the start of every error message.
    serial_options : dict, optional
        Extra pyserial settings (``bytesize``, ``parity``, ``stopbits``,
        ``rtscts``, ...), applied before opening.
    """

    def __init__(
        self, port: str, baudrate: int = 115200, name: str = "device", serial_options: dict[str, Any] | None = None
    ):
        if not port or not isinstance(port, str):
            raise ValueError(f"{name}: port must be a device name or pyserial URL, got {port!r}")
        self.port = port
        self.baudrate = int(baudrate)
        self.name = name
        self.serial_options = dict(serial_options or {})
        self._ser: Any = None  # serial.SerialBase once open (pyserial ships no type information)
        self._buf = bytearray()
        self._lock = threading.RLock()

    # -- life cycle -------------------------------------------------------
    @property
    def is_open(self) -> bool:
        return self._ser is not None and self._ser.is_open

    def open(self) -> None:
        if self.is_open:
            return
        problem = url_problem(self.port)
        if problem is not None:
            raise DeviceDisconnected(f"{self.name}: cannot open {self.port}: not a valid URL: {problem}")
        try:
            ser = serial.serial_for_url(self.port, do_not_open=True)
            ser.baudrate = self.baudrate
            ser.timeout = _POLL
            ser.write_timeout = 2.0
            if "://" not in self.port:
                ser.exclusive = True  # the device's replies are this process's alone (see the module docstring)
            for key, value in self.serial_options.items():
                setattr(ser, key, value)
            ser.open()
        except _OPEN_ERRORS as exc:
            if getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK):
                raise DeviceDisconnected(
                    f"{self.name}: cannot open {self.port}: it is in use by another program (another harp session"
                    " or live view, harp devices --probe, a serial terminal); close that one first"
                ) from exc
            raise DeviceDisconnected(f"{self.name}: cannot open {self.port}: {exc}") from exc
        self._ser = ser
        self._buf.clear()

    def close(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            with contextlib.suppress(*_IO_ERRORS):  # a vanished port may fail to close; it is closed for us either way
                ser.close()

    def _port(self) -> Any:
        if self._ser is None or not self._ser.is_open:
            raise DeviceDisconnected(f"{self.name}: port {self.port} is not open")
        return self._ser

    # -- I/O ----------------------------------------------------------------
    def write(self, data: bytes) -> None:
        ser = self._port()
        try:
            ser.write(data)
            ser.flush()
        except _IO_ERRORS as exc:
            self.close()
            raise DeviceDisconnected(f"{self.name}: write to {self.port} failed, device gone ({exc})") from exc

    def _read_some(self) -> bytes:
        ser = self._port()
        try:
            waiting = ser.in_waiting
            data: bytes = ser.read(max(1, waiting))
            return data
        except _IO_ERRORS as exc:
            self.close()
            raise DeviceDisconnected(f"{self.name}: read from {self.port} failed, device gone ({exc})") from exc

    def readline(self, timeout: float, what: str = "a reply", eol: bytes = b"\n", total: float | None = None) -> bytes:
        """Return the next line, without its terminator (``\\r\\n`` or ``\\n``; another ``eol``, e.g. a
        binary protocol's end byte, is cut alone).

        Raises :class:`DeviceTimeout` naming ``what`` if no complete line
        arrives within ``timeout`` seconds (the message quotes ``total``
        instead, when the caller's deadline started earlier).
        """
        deadline = time.monotonic() + timeout
        with self._lock:
            while True:
                idx = self._buf.find(eol)
                if idx >= 0:
                    line = bytes(self._buf[:idx])
                    del self._buf[: idx + len(eol)]
                    return line.rstrip(b"\r") if eol == b"\n" else line  # a binary packet keeps its 0x0D
                if time.monotonic() >= deadline:
                    partial = f" (got only {bytes(self._buf)!r})" if self._buf else ""
                    raise DeviceTimeout(
                        f"{self.name}: no {what} within {timeout if total is None else total:.2f} s"
                        f" on {self.port}{partial}"
                    )
                self._buf += self._read_some()

    def pending(self) -> bytes:
        """Return and remove whatever has arrived and not been read yet."""
        with self._lock:
            ser = self._port()
            try:
                while ser.in_waiting:
                    self._buf += ser.read(ser.in_waiting)
            except _IO_ERRORS as exc:
                self.close()
                raise DeviceDisconnected(f"{self.name}: read from {self.port} failed, device gone ({exc})") from exc
            data = bytes(self._buf)
            self._buf.clear()
            return data

    def __repr__(self) -> str:
        return f"SerialTransport({self.port!r}, baudrate={self.baudrate})"
