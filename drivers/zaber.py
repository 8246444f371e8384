"""Zaber rotary stage over the Zaber ASCII protocol (firmware 6/7), via pyserial.

Bytes on the wire (``\\n`` ends a command, ``\\r\\n`` a reply)::

    /1 0 0                  @01 0 00 OK IDLE -- 0
    /1 1 1 home             @01 1 01 OK BUSY WR 0
    /1 1 2 move abs 192000  @01 1 02 OK BUSY -- 0
    /1 1 3 get pos          @01 1 03 OK BUSY -- 96117      (while moving)
    /1 0 4 warnings         @01 0 04 OK IDLE FS 01 FS
    /1 0 5 warnings clear   @01 0 05 OK IDLE FS 01 FS

Every command carries a message id (the number after the axis, 0..99, counting up per connection and
starting again at 0 after 99; a command to the whole device names axis 0), which the device repeats in
its reply. A reply is ``@`` device axis [message id] flag (``OK``/``RJ``) status
(``IDLE``/``BUSY``) warning (``--`` or the most severe flag) data, optionally
followed by ``:XX`` (LRC checksum, verified here). Only the reply with the command's id answers it: a
reply with another id, or none, is a late answer to an earlier command (one that arrived after its
reply timeout) and is dropped, never taken for this command's answer. Info lines (``#...``) and
alerts (``!01 1 IDLE --``, sent when a move ends if ``comm.alert`` is on) are
read and set aside while waiting for a reply.

Angles are converted with ``microsteps_per_degree`` (X-RSW60: 1 536 000
microsteps per turn, 4266.67 per degree). ``move_to`` sends ``move abs`` and
then polls ``get pos`` until the axis is ``IDLE`` at the target.

Travel: ``open()`` reads the axis settings ``limit.min`` and ``limit.max``
(microsteps)::

    /1 1 1 get limit.min    @01 1 01 OK IDLE -- 0
    /1 1 2 get limit.max    @01 1 02 OK IDLE -- 1536000

:meth:`ZaberTurntable.travel_range` is the configured ``limits`` within that
travel; a target outside raises :class:`~drivers.errors.OutOfRange` before
anything is sent (the device would answer ``RJ ... BADDATA``). A device that
rejects the settings (``RJ``) reports no travel: the configured limits apply.

A second axis of the same device may tilt the calibration board (``tilt_axis``, e.g. 2 on a two-axis
controller): :attr:`ZaberTurntable.tilt` is that axis, a :class:`ZaberAxis` of its own on the same
connection (``/1 2 ID move abs N``, ``/1 2 ID get pos``, ID the message id; its travel read at ``open()`` as the first axis's).
Another may be a linear stage that carries the turntable sideways (``shift_axis``, e.g. 3), so that a
session takes its shots about two places of the turntable axis in the image: :attr:`ZaberTurntable.shift`,
the same kind of axis with its positions in millimetres (``shift_microsteps_per_mm``; default
:data:`X_LSM_MICROSTEPS_PER_MM`, ``/1 3 ID move abs 209974`` for 10 mm). The axes of one connection
share its message ids.

Errors: ``RJ`` -> :class:`DeviceRejected` (with the reason, e.g. BADDATA);
a fault flag (``F*``) or an unexpected-limit ``WL`` -> :class:`DeviceFault`
naming the flag and its meaning (clear with :meth:`clear_warnings`, or
:meth:`recover`); no reply -> :class:`DeviceTimeout`; a line that is not a
Zaber message, a bad checksum or a reply from another device ->
:class:`ProtocolError`; port gone -> :class:`DeviceDisconnected`.

References
----------
Zaber Technologies, "ASCII Protocol Manual" (firmware 6.x and 7.x):
message format, reply fields, warning flags, checksums.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Self

from drivers.config_keys import check_config_keys
from drivers.errors import (
    ConfigKeyError,
    DeviceFault,
    DeviceRejected,
    DeviceTimeout,
    DriverError,
    ProtocolError,
    with_unit,
)
from drivers.protocols import Range
from drivers.ranges import SHIFT_LIMITS_MM, UNIT_WORDS, effective_travel
from drivers.settings import REQUIRED, Setting
from drivers.transport import SerialTransport

X_RSW60_MICROSTEPS_PER_DEGREE = 1536000 / 360.0
TILT_LIMITS_DEG = (0.0, 60.0)
"""The tilt axis's angles by default (a board tilted further hides its corners from the camera)."""
X_LSM_MICROSTEPS_PER_MM = 1.0 / 0.047625e-3
"""The shift axis's microsteps per mm by default: 20997.4, a Zaber X-LSM linear stage (0.047625 µm per
microstep: a 0.6096 mm lead screw, 200 full steps of 64 microsteps per turn)."""

# Warning flags of the Zaber ASCII protocol: F* faults, W* warnings, N* notices.
WARNING_FLAGS = {
    "FD": "driver disabled",
    "FQ": "encoder error",
    "FS": "stalled and stopped",
    "FT": "excessive twist",
    "FB": "stream bounds error",
    "FP": "interpolated path deviation",
    "FE": "limit error",
    "FM": "unexpected motion / motor fault",
    "WH": "device not homed",
    "WL": "unexpected limit trigger",
    "WP": "invalid calibration / settings",
    "WV": "voltage out of range",
    "WT": "controller temperature high",
    "WM": "displaced when stationary",
    "WR": "no reference position (home the stage)",
    "NC": "manual control",
    "NI": "command interrupted",
    "ND": "stream discontinuity",
    "NU": "setting update pending",
    "NJ": "joystick calibrating",
}

MAX_MESSAGE_ID = 99
"""Message ids run 0..MAX_MESSAGE_ID (the Zaber ASCII protocol's range), then from 0 again."""

# Flags that stop a move: every fault, and an unexpected limit switch.
FATAL_WARNINGS = ("WL",)

_REPLY = re.compile(
    r"^@(?P<dev>\d+) (?P<axis>\d+)(?: (?P<id>\d+))? (?P<flag>OK|RJ) (?P<status>IDLE|BUSY)"
    r" (?P<warn>--|[A-Z]{2})(?: (?P<data>.*?))?$"
)
_ALERT = re.compile(r"^!(?P<dev>\d+) (?P<axis>\d+) (?P<status>IDLE|BUSY) (?P<warn>--|[A-Z]{2})(?: .*)?$")
_INFO = re.compile(r"^#(?P<dev>\d+) (?P<axis>\d+)(?: .*)?$")

SETTINGS: dict[str, Setting] = {
    "port": Setting("serial device, socket://host:port or rfc2217://host:port ('emulator': the simulated "
                    "station's)", "text", default=REQUIRED),
    "baudrate": Setting("serial speed", "integer", "baud", choices=(9600, 19200, 38400, 57600, 115200)),
    "device": Setting("device address on the chain", "integer", "", 0, 99),
    "device_address": Setting("the same as device", "integer", "", 0, 99),
    "axis": Setting("axis number", "integer", "", 0, 9),
    "microsteps_per_degree": Setting("microsteps per degree of the stage", "number", "microsteps/deg", 0.0, 1e8,
                                     low_open=True),
    "steps_per_degree": Setting("the same as microsteps_per_degree", "number", "microsteps/deg", 0.0, 1e8,
                                low_open=True),
    "limits": Setting("[min, max] of the angles moves may reach (narrowed to the device's travel at open)",
                      "numbers", "deg", -3600.0, 3600.0, length=(2, 2)),
    "reply_timeout": Setting("wait for each reply", "number", "s", 0.0, 60.0, low_open=True),
    "poll_interval": Setting("between position polls while moving", "number", "s", 0.0, 10.0, low_open=True),
    "move_timeout": Setting("longest move", "number", "s", 0.0, 3600.0, low_open=True),
    "home_timeout": Setting("longest homing", "number", "s", 0.0, 3600.0, low_open=True),
    "tolerance_microsteps": Setting("how far from the target an idle axis may be", "integer", "microsteps", 0,
                                    1_000_000),
    "name": Setting("how messages name the stage", "text"),
    "tilt_axis": Setting("a second axis of the same device that tilts the calibration board (the session's "
                         "intrinsics.placement: stage); null: none", "integer", "", 1, 9, nullable=True),
    "tilt_microsteps_per_degree": Setting("microsteps per degree of the tilt axis (default: the turntable's)",
                                          "number", "microsteps/deg", 0.0, 1e8, low_open=True),
    "tilt_limits": Setting("[min, max] of the tilt axis's angles (narrowed to its travel at open)", "numbers",
                           "deg", -90.0, 90.0, length=(2, 2)),
    "shift_axis": Setting("another axis of the same device: a linear stage that carries the turntable sideways "
                          "between groups of shots; null: none", "integer", "", 1, 9, nullable=True),
    "shift_microsteps_per_mm": Setting("microsteps per mm of the shift axis (by default a Zaber X-LSM's: "
                                       "0.047625 µm per microstep)", "number", "microsteps/mm", 0.0, 1e9,
                                       low_open=True),
    "shift_limits": Setting("[min, max] of the shift axis's positions (narrowed to its travel at open)", "numbers",
                            "mm", -10000.0, 10000.0, length=(2, 2)),
}  # fmt: skip
"""The keys of a Zaber turntable's configuration section, each with its type, unit and range."""
_CONFIG_KEYS = {"driver", *SETTINGS}


KEPT_LINES = 100
"""How many alert lines, info lines and late replies a :class:`ZaberAxis` keeps of each (the most recent): a
connection held for weeks does not grow without bound."""


def _keep(lines: list[str], text: str) -> None:
    lines.append(text)
    del lines[:-KEPT_LINES]


def describe_flag(flag: str) -> str:
    return f"{flag} ({WARNING_FLAGS.get(flag, 'unknown warning')})"


def is_fatal(flag: str) -> bool:
    return flag.startswith("F") or flag in FATAL_WARNINGS


def strip_checksum(text: str, source: str) -> str:
    """Verify and remove a trailing ``:XX`` checksum, if present."""
    m = re.search(r":([0-9A-Fa-f]{2})$", text)
    if not m:
        return text
    body = text[1 : m.start()]
    if (sum(body.encode("ascii")) + int(m.group(1), 16)) & 0xFF:
        raise ProtocolError(f"{source}: bad checksum in {text!r}")
    return text[: m.start()]


class MessageIds:
    """The message ids of one connection's commands, 0, 1, ..., :data:`MAX_MESSAGE_ID`, 0, ...: shared by the
    axes on it, so that a late reply to one axis's command is not taken for another's answer."""

    def __init__(self) -> None:
        self._next = 0

    def take(self) -> int:
        """The id for the next command."""
        n = self._next
        self._next = (n + 1) % (MAX_MESSAGE_ID + 1)
        return n


@dataclass(frozen=True)
class ZaberReply:
    """One decoded ``@`` reply."""

    device: int
    axis: int
    message_id: int | None
    ok: bool
    busy: bool
    warning: str  # "--" or a flag such as "FS"
    data: str
    raw: str


class ZaberAxis:
    """One axis of a Zaber ASCII device, its positions in ``unit``: degrees (``"°"``) of a rotary stage or
    of the calibration board's tilt, millimetres (``"mm"``) of the linear stage that carries the turntable
    sideways. :class:`ZaberTurntable` is one; its tilt and shift axes are others on its connection.

    Parameters
    ----------
    port : str
        Serial device or pyserial URL.
    baudrate : int
        115200 (Zaber default for ASCII).
    device, axis : int
        Device address on the chain and axis number (1, 1).
    microsteps_per_unit : float
        Microsteps per ``unit`` (per degree, per mm).
    limits : (float, float)
        Allowed range of ``move_to`` in ``unit``, narrowed at ``open()`` to
        the device's ``limit.min``/``limit.max``; outside it,
        :class:`~drivers.errors.OutOfRange` before anything is sent.
    unit : str
        ``"°"`` or ``"mm"``: how positions, ranges and messages are stated.
    config_prefix : str
        The prefix of this axis's configuration keys (``""``, ``"tilt_"``, ``"shift_"``), which the
        messages about a bad scale or bad limits name.
    reply_timeout : float
        Seconds to wait for each reply.
    poll_interval : float
        Seconds between ``get pos`` polls while waiting for a move.
    tolerance_microsteps : int
        How far from the target an idle axis may be and count as arrived.
    """

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 115200,
        device: int = 1,
        axis: int = 1,
        microsteps_per_unit: float = X_RSW60_MICROSTEPS_PER_DEGREE,
        limits: tuple[float, float] = (0.0, 360.0),
        unit: str = "°",
        config_prefix: str = "",
        reply_timeout: float = 1.0,
        poll_interval: float = 0.05,
        move_timeout: float = 60.0,
        home_timeout: float = 120.0,
        tolerance_microsteps: int = 1,
        name: str | None = None,
    ):
        if unit not in UNIT_WORDS:
            raise ValueError(f"unit must be one of {', '.join(UNIT_WORDS)}, got {unit!r}")
        if microsteps_per_unit <= 0:
            key = f"{config_prefix}microsteps_per_{UNIT_WORDS[unit]}"
            raise ConfigKeyError(key, f"{key} must be positive, got {microsteps_per_unit}")
        lo, hi = (float(v) for v in limits)
        if not lo < hi:
            key = f"{config_prefix}limits"
            raise ConfigKeyError(key, f"{key} must be (min, max) with min < max, got {limits}")
        if device < 0 or axis < 0:
            raise ValueError(f"device and axis must be >= 0, got {device}, {axis}")
        self.device = int(device)
        self.axis_number = int(axis)
        self.unit = unit
        self.config_prefix = config_prefix
        self.microsteps_per_unit = float(microsteps_per_unit)
        self._configured = Range(lo, hi, unit, "configured limits")
        self._device_travel: Range | None = None
        self._travel = self._configured
        self.reply_timeout = float(reply_timeout)
        self.poll_interval = float(poll_interval)
        self.move_timeout = float(move_timeout)
        self.home_timeout = float(home_timeout)
        self.tolerance = int(tolerance_microsteps)
        self.name = name or f"zaber {port} device {device} axis {axis}"
        self.transport = SerialTransport(port, baudrate, name=self.name)
        # the last KEPT_LINES of each, most recent last: alert lines, info lines, and replies that answered no
        # command waiting (late ones)
        self.alerts: list[str] = []
        self.infos: list[str] = []
        self.dropped: list[str] = []
        self._ids = MessageIds()
        self._lock = threading.RLock()
        self._target: int | None = None
        self._shared = False  # an axis on another axis's connection (the tilt, the shift axis): opened and closed by it
        self._others: list[ZaberAxis] = []  # the axes on this one's connection, opened with it

    def _another_axis(
        self, role: str, number: int, microsteps_per_unit: float, limits: tuple[float, float], unit: str
    ) -> ZaberAxis:
        """Axis ``number`` of this device on this connection (the ``role`` axis: ``"tilt"``, ``"shift"``),
        opened, closed and locked with this one; ValueError when it is an axis already in use."""
        for other in (self, *self._others):
            if int(number) == other.axis_number:
                raise ConfigKeyError(
                    f"{role}_axis", f"{role}_axis must be another axis than axis {other.axis_number}, got {number}"
                )
        axis = ZaberAxis(
            self.transport.port, baudrate=self.transport.baudrate, device=self.device, axis=int(number),
            microsteps_per_unit=microsteps_per_unit, limits=tuple(limits), unit=unit,  # type: ignore[arg-type]
            config_prefix=f"{role}_", reply_timeout=self.reply_timeout, poll_interval=self.poll_interval,
            move_timeout=self.move_timeout, home_timeout=self.home_timeout, tolerance_microsteps=self.tolerance,
            name=f"{self.name} {role} axis {number}",
        )  # fmt: skip
        axis.transport, axis._lock, axis._shared, axis._ids = self.transport, self._lock, True, self._ids
        self._others.append(axis)
        return axis

    # -- life cycle -----------------------------------------------------------
    def open(self) -> None:
        if not self._shared:
            self.transport.open()
        try:
            reply = self.command("", axis_scope=False)  # "/1 0 ID": is the device there?
            if not reply.ok:  # warnings do not stop opening: recover() needs an open port
                raise DeviceRejected(f"{self.name}: status request rejected: {reply.raw!r}")
            self._target = None
            if self._shared:  # the tilt or shift axis: is it there? (a one-axis device answers RJ ... BADAXIS)
                self._check(self.command("get pos"), "get pos", fault=False)
            self._device_travel = self._read_device_travel()
            self._travel = effective_travel(self.name, self._configured, self._device_travel)
            for other in self._others:
                try:
                    other.open()
                except DriverError as exc:  # the tilt or shift axis: name its key
                    exc.config_key = f"{other.config_prefix}axis"
                    raise
        except Exception:
            if not self._shared:
                self.transport.close()
            raise

    def close(self) -> None:
        if not self._shared:
            self.transport.close()

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- wire level ------------------------------------------------------------
    def _format(self, command: str, axis_scope: bool, message_id: int) -> bytes:
        """``/1 1 7 get pos``: device, axis (0: the whole device), message id, command."""
        parts = [f"/{self.device}", str(self.axis_number if axis_scope else 0), str(message_id)]
        if command:
            parts.append(command)
        return (" ".join(parts) + "\n").encode("ascii")

    def parse_line(self, line: bytes) -> ZaberReply | None:
        """Decode one line: a reply, or None for info/alert lines (recorded)."""
        try:
            text = line.decode("ascii").strip()
        except UnicodeDecodeError:
            raise ProtocolError(f"{self.name}: garbage on the line: {line!r}") from None
        text = strip_checksum(text, self.name) if text else text
        m = _REPLY.match(text)
        if m:
            return ZaberReply(
                int(m["dev"]),
                int(m["axis"]),
                int(m["id"]) if m["id"] else None,
                m["flag"] == "OK",
                m["status"] == "BUSY",
                m["warn"],
                m["data"] or "",
                text,
            )
        if _ALERT.match(text):
            _keep(self.alerts, text)
            return None
        if _INFO.match(text):
            _keep(self.infos, text)
            return None
        raise ProtocolError(f"{self.name}: not a Zaber ASCII message: {line!r}")

    def command(self, command: str, axis_scope: bool = True) -> ZaberReply:
        """Send one command (``"get pos"``, ``"warnings"``, ...) with the next message id and return the
        reply that repeats that id.

        ``axis_scope=False`` addresses the device (``/1 0 7 warnings``) rather
        than the axis (``/1 1 7 get pos``). An ``RJ`` reply is returned, not
        raised; see :meth:`_check`. A reply with another id (or none) is late, an earlier command's: it is
        recorded in :attr:`dropped` and the wait goes on.
        """
        with self._lock:
            message_id = self._ids.take()
            data = self._format(command, axis_scope, message_id)
            what = f"reply to {data.decode().strip()!r}"
            stale = self.transport.pending()
            for line in stale.splitlines():
                if line.strip():
                    try:
                        late = self.parse_line(line)
                    except ProtocolError:
                        continue  # leftovers of an earlier failure
                    if late is not None:
                        _keep(self.dropped, late.raw)
            self.transport.write(data)
            deadline = time.monotonic() + self.reply_timeout
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeout(f"{self.name}: no {what} within {self.reply_timeout:.2f} s")
                line = self.transport.readline(remaining, what, total=self.reply_timeout)
                if not line.strip():
                    continue
                reply = self.parse_line(line)
                if reply is None:
                    continue
                if reply.device != self.device:
                    raise ProtocolError(
                        f"{self.name}: reply from device {reply.device}, expected {self.device}: {reply.raw!r}"
                    )
                if reply.message_id != message_id:  # a late reply to an earlier command
                    _keep(self.dropped, reply.raw)
                    continue
                return reply

    def _check(self, reply: ZaberReply, what: str, fault: bool = True) -> ZaberReply:
        if not reply.ok:
            raise DeviceRejected(f"{self.name}: {what!r} rejected: {reply.data or 'no reason'} (reply {reply.raw!r})")
        if fault and reply.warning != "--" and is_fatal(reply.warning):
            raise DeviceFault(
                f"{self.name}: warning {describe_flag(reply.warning)} during {what!r};"
                f" clear it with clear_warnings() / recover()"
            )
        return reply

    # -- conversions -------------------------------------------------------------
    def to_microsteps(self, position: float) -> int:
        """A position in :attr:`unit` (degrees, mm) as the nearest microstep."""
        return int(round(position * self.microsteps_per_unit))

    def to_units(self, microsteps: int) -> float:
        """A position in microsteps in :attr:`unit` (degrees, mm)."""
        return microsteps / self.microsteps_per_unit

    def _show(self, position: float) -> str:
        """A position in messages: ``45.0000°``, ``12.5000 mm``."""
        return f"{position:.4f}{with_unit(self.unit)}"

    # -- Turntable protocol ----------------------------------------------------
    @property
    def limits(self) -> tuple[float, float]:
        """``(min, max)`` of :meth:`travel_range` (the configured limits before ``open()``)."""
        return (self._travel.minimum, self._travel.maximum)

    def travel_range(self) -> Range:
        """The positions ``move_to`` accepts (in :attr:`unit`): the configured limits within the device's travel."""
        return self._travel

    def device_travel_range(self) -> Range | None:
        """``limit.min`` .. ``limit.max`` as read at ``open()``, in :attr:`unit` (None if not reported)."""
        return self._device_travel

    def _read_device_travel(self) -> Range | None:
        values = []
        for setting in ("limit.min", "limit.max"):
            reply = self.command(f"get {setting}")
            if not reply.ok:
                return None  # no such setting on this device: only the configured limits apply
            try:
                values.append(self.to_units(int(reply.data)))
            except ValueError:
                raise ProtocolError(f"{self.name}: {setting} is not an integer: {reply.raw!r}") from None
        lo, hi = values
        if not lo < hi:
            u = with_unit(self.unit)
            raise ProtocolError(f"{self.name}: device reports limit.min {lo:g}{u} >= limit.max {hi:g}{u}")
        return Range(lo, hi, self.unit, "device limit.min/limit.max")

    def _get_pos(self, fault: bool = True) -> ZaberReply:
        reply = self._check(self.command("get pos"), "get pos", fault)
        try:
            int(reply.data)
        except ValueError:
            raise ProtocolError(f"{self.name}: position is not an integer: {reply.raw!r}") from None
        return reply

    def position(self) -> float:
        return self.to_units(int(self._get_pos(fault=False).data))

    def home(self, timeout: float | None = None) -> None:
        timeout = self.home_timeout if timeout is None else timeout
        with self._lock:
            self._check(self.command("home"), "home")
            self._target = None
            self._wait_idle(timeout, "home", target=None)

    def start_move(self, position: float) -> int:
        """Send ``move abs`` and return the target in microsteps, without waiting (``position`` in :attr:`unit`)."""
        self._travel.check(self.name, "move to", position)
        steps = self.to_microsteps(position)
        with self._lock:
            self._check(self.command(f"move abs {steps}"), f"move abs {steps}")
            self._target = steps
        return steps

    def move_to(self, position: float, timeout: float | None = None) -> float:
        """Move to ``position`` (in :attr:`unit`) and wait until idle there; returns the position read back."""
        timeout = self.move_timeout if timeout is None else timeout
        with self._lock:
            steps = self.start_move(position)
            return self._wait_idle(timeout, f"move to {position}{with_unit(self.unit)}", target=steps)

    def wait_idle(self, timeout: float | None = None) -> float:
        """Wait until the axis stops (at the last target, if any); returns the position in :attr:`unit`."""
        timeout = self.move_timeout if timeout is None else timeout
        return self._wait_idle(timeout, "wait", target=self._target)

    def _wait_idle(self, timeout: float, what: str, target: int | None) -> float:
        deadline = time.monotonic() + timeout
        while True:
            reply = self._get_pos(fault=False)
            pos = int(reply.data)
            if reply.warning != "--" and is_fatal(reply.warning):
                raise DeviceFault(
                    f"{self.name}: {what} stopped at {self._show(self.to_units(pos))}:"
                    f" warning {describe_flag(reply.warning)};"
                    f" clear it with clear_warnings() / recover()"
                )
            if not reply.busy:
                if target is not None and abs(pos - target) > self.tolerance:
                    raise DeviceFault(
                        f"{self.name}: {what} stopped at {self._show(self.to_units(pos))} short of the target"
                        f" {self._show(self.to_units(target))} (warning {reply.warning})"
                    )
                return self.to_units(pos)
            if time.monotonic() >= deadline:
                try:
                    self.stop()
                finally:
                    raise DeviceTimeout(
                        f"{self.name}: {what} not finished within {timeout:.2f} s"
                        f" (at {self._show(self.to_units(pos))}); stage stopped"
                    )
            time.sleep(self.poll_interval)

    def stop(self) -> None:
        with self._lock:
            self._target = None
            reply = self.command("stop")
            if not reply.ok:
                raise DeviceRejected(f"{self.name}: 'stop' rejected: {reply.data}")

    def warnings(self) -> list[str]:
        """Active warning flags (``/1 warnings``), e.g. ``["FS", "WR"]``."""
        return self._parse_warnings(self.command("warnings", axis_scope=False), "warnings")

    def clear_warnings(self) -> list[str]:
        """Clear warnings (``/1 warnings clear``); returns the flags that were set."""
        return self._parse_warnings(self.command("warnings clear", axis_scope=False), "warnings clear")

    def recover(self) -> list[str]:
        """Clear the device's warnings so that it can move again; returns what was cleared."""
        return self.clear_warnings()

    def _parse_warnings(self, reply: ZaberReply, what: str) -> list[str]:
        if not reply.ok:
            raise DeviceRejected(f"{self.name}: {what!r} rejected: {reply.data}")
        words = reply.data.split()
        try:
            count = int(words[0])
        except (IndexError, ValueError):
            raise ProtocolError(f"{self.name}: bad reply to {what!r}: {reply.raw!r}") from None
        flags = words[1:]
        if count != len(flags):
            raise ProtocolError(f"{self.name}: {what!r} announced {count} flags, got {flags}: {reply.raw!r}")
        return flags

    def status(self) -> dict[str, Any]:
        reply = self._get_pos(fault=False)
        flags = self.warnings()
        return {
            "busy": reply.busy,
            "warnings": flags,
            "descriptions": [describe_flag(f) for f in flags],
            "position": self.to_units(int(reply.data)),
            "fault": any(is_fatal(f) for f in flags),
        }

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.transport.port!r}, device={self.device}, axis={self.axis_number})"


class ZaberTurntable(ZaberAxis):
    """Zaber ASCII rotary stage; satisfies :class:`drivers.protocols.Turntable`, with the optional tilt
    (:class:`drivers.protocols.Tilting`) and shift (:class:`drivers.protocols.ShiftingTurntable`) axes.

    Parameters
    ----------
    port : str
        Serial device or pyserial URL.
    baudrate : int
        115200 (Zaber default for ASCII).
    device, axis : int
        Device address on the chain and axis number (1, 1).
    microsteps_per_degree : float
        Conversion of angles (default: X-RSW60, 1536000/360).
    limits : (float, float)
        Allowed range of ``move_to`` in degrees, narrowed at ``open()`` to
        the device's ``limit.min``/``limit.max``; outside it,
        :class:`~drivers.errors.OutOfRange` before anything is sent.
    reply_timeout : float
        Seconds to wait for each reply.
    poll_interval : float
        Seconds between ``get pos`` polls while waiting for a move.
    tolerance_microsteps : int
        How far from the target an idle axis may be and count as arrived.
    tilt_axis, tilt_microsteps_per_degree, tilt_limits
        The axis that tilts the calibration board (:attr:`tilt`), its microsteps per degree (default:
        the turntable's) and its angles (default :data:`TILT_LIMITS_DEG`).
    shift_axis, shift_microsteps_per_mm, shift_limits
        The linear axis that carries the turntable sideways (:attr:`shift`), its microsteps per mm
        (default :data:`X_LSM_MICROSTEPS_PER_MM`) and its positions in mm (default
        :data:`SHIFT_LIMITS_MM`).
    """

    CONFIG_KEYS: frozenset[str] = frozenset(_CONFIG_KEYS)
    """Keys of this driver's configuration section (``driver`` included or implied)."""
    SETTINGS: Mapping[str, Setting] = SETTINGS
    """Each key's type, unit and range (:mod:`drivers.settings`)."""

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 115200,
        device: int = 1,
        axis: int = 1,
        microsteps_per_degree: float = X_RSW60_MICROSTEPS_PER_DEGREE,
        limits: tuple[float, float] = (0.0, 360.0),
        reply_timeout: float = 1.0,
        poll_interval: float = 0.05,
        move_timeout: float = 60.0,
        home_timeout: float = 120.0,
        tolerance_microsteps: int = 1,
        name: str | None = None,
        tilt_axis: int | None = None,
        tilt_microsteps_per_degree: float | None = None,
        tilt_limits: tuple[float, float] = TILT_LIMITS_DEG,
        shift_axis: int | None = None,
        shift_microsteps_per_mm: float = X_LSM_MICROSTEPS_PER_MM,
        shift_limits: tuple[float, float] = SHIFT_LIMITS_MM,
    ):
        super().__init__(
            port, baudrate=baudrate, device=device, axis=axis, microsteps_per_unit=microsteps_per_degree,
            limits=limits, unit="°", reply_timeout=reply_timeout, poll_interval=poll_interval,
            move_timeout=move_timeout, home_timeout=home_timeout, tolerance_microsteps=tolerance_microsteps,
            name=name,
        )  # fmt: skip
        self.tilt: ZaberAxis | None = None
        """The tilt axis (``tilt_axis``): another axis of this device, on this connection, which tilts the
        calibration board (:class:`drivers.protocols.Tilting`), in degrees; None without one."""
        if tilt_axis is not None:
            scale = (
                self.microsteps_per_unit if tilt_microsteps_per_degree is None else float(tilt_microsteps_per_degree)
            )
            self.tilt = self._another_axis("tilt", tilt_axis, scale, tilt_limits, "°")
        self.shift: ZaberAxis | None = None
        """The shift axis (``shift_axis``): another axis of this device, on this connection, a linear stage
        that carries the turntable sideways (:class:`drivers.protocols.ShiftingTurntable`), in millimetres;
        None without one."""
        if shift_axis is not None:
            self.shift = self._another_axis("shift", shift_axis, shift_microsteps_per_mm, shift_limits, "mm")

    @property
    def microsteps_per_degree(self) -> float:
        """Microsteps per degree of the turntable."""
        return self.microsteps_per_unit

    @classmethod
    def from_config(cls, cfg: dict[str, Any], **ctx: Any) -> ZaberTurntable:
        check_config_keys("zaber turntable", cfg, SETTINGS, {"port": "device name or pyserial URL"})
        kw = {k: v for k, v in cfg.items() if k not in ("driver", "steps_per_degree", "device_address")}
        if "device_address" in cfg:
            if "device" in cfg:
                raise ValueError("zaber turntable: give 'device' or 'device_address', not both")
            kw["device"] = int(cfg["device_address"])
        if "steps_per_degree" in cfg:
            if "microsteps_per_degree" in cfg:
                raise ValueError("zaber turntable: give 'microsteps_per_degree' or 'steps_per_degree', not both")
            kw["microsteps_per_degree"] = cfg["steps_per_degree"]
        for key in ("limits", "tilt_limits", "shift_limits"):
            if key in kw:
                kw[key] = tuple(kw[key])
        port = kw.pop("port")
        return cls(port, **kw)
