"""A GRBL-controlled turntable (common DIY photo turntables), via pyserial.

The turntable is one GRBL axis (``X`` by default) whose units are mapped to
degrees by ``units_per_degree`` (1 when ``$100`` is set in steps per degree).
Bytes on the wire::

    0x18                      \\r\\nGrbl 1.1h ['$' for help]\\r\\n   (soft reset on open)
    $H\\n                      ok                                  (after homing)
    G90 G0 X45.000\\n          ok                                  (buffered only!)
    ?                         <Run|MPos:20.512,0.000,0.000|FS:21600,0>
    ?                         <Idle|MPos:45.000,0.000,0.000|FS:0,0>
    $X\\n                      [MSG:Caution: Unlocked] ok

``ok`` only means the planner took the line, so :meth:`move_to` polls the
realtime status ``?`` until the state is ``Idle`` at the target.

Travel: ``open()`` reads the settings (``$$`` -> ``$0=10`` ... ``$130=360.000``
... ``ok``, kept in :attr:`GrblTurntable.settings`). With soft limits on
(``$20=1``) GRBL accepts machine positions ``[-$13x, 0]`` on the axis (it
homes to the positive end; ``grbl/system.c`` ``system_check_travel_limits``),
which is ``[-$13x, 0] / units_per_degree`` degrees: a turntable that turns
positive when GRBL counts down has a negative ``units_per_degree``.
:meth:`GrblTurntable.travel_range` is the configured ``limits`` within that
travel; a target outside raises :class:`~drivers.errors.OutOfRange` before
anything is sent (GRBL would raise ``ALARM:2``, a critical alarm). Soft limits
off: no device travel, the configured limits apply. (A firmware built with
``HOMING_FORCE_SET_ORIGIN`` counts up from the home switch instead; it is
not detected.)

A second axis may tilt the calibration board (``tilt_axis``, e.g. ``Y``): :attr:`GrblTurntable.tilt` is
that axis, a :class:`GrblAxis` of its own on the same connection (``G90 G0 Y30.000``, its position
from the same status reports; the controller's settings and soft limits read once at ``open()``).
Another may be a linear stage that carries the turntable sideways (``shift_axis``, e.g. ``Z``), so that a
session takes its shots about two places of the turntable axis in the image: :attr:`GrblTurntable.shift`,
the same kind of axis with its positions in millimetres (``shift_units_per_mm``, default 1: GRBL counts
mm; ``G90 G0 Z12.500``).

Errors: ``error:N`` -> :class:`DeviceRejected` with the meaning of ``N``, but ``error:9`` (G-code locked out in
Alarm: the controller's state, not the line; e.g. a restart whose banner came after the line was sent) ->
:class:`DeviceFault` (recover, then home);
``ALARM:N`` or state ``Alarm`` during a move -> :class:`DeviceFault` with the
meaning (recover with :meth:`recover`: soft reset if needed, then ``$X``;
re-home after a hard-limit alarm, position is lost); the controller's banner
unasked (it restarted: a power dip, a USB reset; its position counts from 0
again) -> :class:`DeviceFault` until :meth:`recover` and :meth:`home`; no answer ->
:class:`DeviceTimeout`; unparsable line -> :class:`ProtocolError`; port gone
-> :class:`DeviceDisconnected`.

Suspended moves: state ``Door`` (the safety door opened; ``Door:1`` still ajar, ``Door:0`` shut again and
waiting for cycle start) while a move or homing is awaited -> :class:`DeviceFault` at once ("close it and
resume the session"; the door during homing is GRBL's ``ALARM:7``); nothing is sent to the controller, whose
cycle start is the operator's to give. A feed hold (``Hold:1`` stopping, ``Hold:0`` stopped: someone pressed
the controller's feed-hold button) is waited out for ``hold_timeout`` seconds: cycle start (``~``) within
that time and the move finishes; after it the move is cancelled as :meth:`GrblAxis.stop` does (the hold
kept, then a soft reset flushes the planner; position kept) and :class:`DeviceFault` says so. A session
retries either after ``recover()`` (a soft reset) and homing, and stops with the one-line message if the
door stays open. Before, both waited out ``move_timeout`` and ended in a :class:`DeviceTimeout`.

References
----------
gnea/grbl, "Grbl v1.1 Interface" and "Grbl v1.1 Commands" (doc/markdown),
and the error/alarm code tables (doc/csv/error_codes_en_US.csv,
alarm_codes_en_US.csv).
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Self, TypedDict

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

ERROR_CODES = {
    1: "G-code words consist of a letter and a value; letter was not found",
    2: "numeric value format is not valid or missing an expected value",
    3: "'$' system command was not recognized or supported",
    4: "negative value received for an expected positive value",
    5: "homing cycle is not enabled via settings",
    6: "minimum step pulse time must be greater than 3 us",
    7: "EEPROM read failed; reset and restored to default values",
    8: "'$' command cannot be used unless Grbl is IDLE",
    9: "G-code locked out during alarm or jog state",
    10: "soft limits cannot be enabled without homing also enabled",
    11: "max characters per line exceeded; line was not processed",
    12: "'$' setting value exceeds the maximum step rate supported",
    13: "safety door detected as opened and door state initiated",
    14: "build info or startup line exceeded EEPROM line length limit",
    15: "jog target exceeds machine travel; command ignored",
    16: "jog command with no '=' or contains prohibited g-code",
    17: "laser mode requires PWM output",
    20: "unsupported or invalid g-code command found in block",
    21: "more than one g-code command from the same modal group found in block",
    22: "feed rate has not yet been set or is undefined",
    23: "g-code command in block requires an integer value",
    24: "two g-code commands that both require the use of axis words were detected",
    25: "a g-code word was repeated in the block",
    26: "a g-code command implicitly or explicitly requires axis words but none were detected",
    27: "N line number value is not within the valid range",
    28: "a g-code command was sent, but is missing some required value words",
    33: "the motion command has an invalid target",
}

ALARM_CODES = {
    1: "hard limit triggered; machine position is likely lost, re-homing is recommended",
    2: "soft limit alarm: target exceeds machine travel; position retained",
    3: "reset while in motion; position is likely lost, re-homing is recommended",
    4: "probe fail: probe is not in the expected initial state",
    5: "probe fail: probe did not contact the workpiece",
    6: "homing fail: reset during active homing cycle",
    7: "homing fail: safety door was opened during homing",
    8: "homing fail: pull off failed to clear the limit switch",
    9: "homing fail: could not find the limit switch within the search distance",
}

_STATUS = re.compile(r"^<(?P<state>[A-Za-z]+)(?::(?P<sub>\d+))?\|(?P<fields>.*)>$")
_ERROR = re.compile(r"^error:(\d+)$")
_ALARM = re.compile(r"^ALARM:(\d+)$")
_SETTING = re.compile(r"^\$(\d+)=([-+]?[0-9.]+)$")
_AXES = "XYZABC"
TILT_LIMITS_DEG = (0.0, 60.0)
"""The tilt axis's angles by default (a board tilted further hides its corners from the camera)."""

SETTINGS: dict[str, Setting] = {
    "port": Setting("serial device, socket://host:port or rfc2217://host:port ('emulator': the simulated "
                    "station's)", "text", default=REQUIRED),
    "baudrate": Setting("serial speed", "integer", "baud", choices=(9600, 19200, 38400, 57600, 115200)),
    "axis": Setting("the GRBL axis carrying the turntable", "text", choices=tuple(_AXES + _AXES.lower())),
    "units_per_degree": Setting("GRBL units per table degree (not 0; negative: reversed)", "number", "units/deg",
                                -1e6, 1e6),
    "steps_per_degree": Setting("motor steps per table degree (instead of units_per_degree)", "number",
                                "steps/deg", 0.0, 1e8, low_open=True),
    "steps_per_unit": Setting("GRBL's $10x steps per unit (with steps_per_degree; default: the same)", "number",
                              "steps/unit", 0.0, 1e8, low_open=True),
    "feed": Setting("G1 feed rate (null: rapid G0 moves)", "number", "units/min", 0.0, 1e7, low_open=True,
                    nullable=True),
    "limits": Setting("[min, max] of the angles moves may reach (narrowed to the device's travel at open)",
                      "numbers", "deg", -3600.0, 3600.0, length=(2, 2)),
    "reply_timeout": Setting("wait for each reply", "number", "s", 0.0, 60.0, low_open=True),
    "poll_interval": Setting("between position polls while moving", "number", "s", 0.0, 10.0, low_open=True),
    "move_timeout": Setting("longest move", "number", "s", 0.0, 3600.0, low_open=True),
    "home_timeout": Setting("longest homing", "number", "s", 0.0, 3600.0, low_open=True),
    "startup_timeout": Setting("wait for the banner after a reset", "number", "s", 0.0, 60.0, low_open=True),
    "hold_timeout": Setting("longest feed hold a move waits out for cycle start before it is cancelled", "number",
                            "s", 0.0, 3600.0, low_open=True),
    "tolerance_deg": Setting("how far from the target an idle axis may be", "number", "deg", 0.0, 10.0),
    "name": Setting("how messages name the stage", "text"),
    "tilt_axis": Setting("a second GRBL axis that tilts the calibration board (the session's intrinsics.placement: "
                         "stage); null: none", "text", choices=tuple(_AXES + _AXES.lower()), nullable=True),
    "tilt_units_per_degree": Setting("GRBL units per degree of tilt (not 0)", "number", "units/deg", -1e6, 1e6),
    "tilt_limits": Setting("[min, max] of the tilt axis's angles (narrowed to its soft limits at open)", "numbers",
                           "deg", -90.0, 90.0, length=(2, 2)),
    "shift_axis": Setting("another GRBL axis: a linear stage that carries the turntable sideways between groups of "
                          "shots; null: none", "text", choices=tuple(_AXES + _AXES.lower()), nullable=True),
    "shift_units_per_mm": Setting("GRBL units per mm of the shift axis (1: GRBL counts mm; not 0)", "number",
                                  "units/mm", -1e6, 1e6),
    "shift_limits": Setting("[min, max] of the shift axis's positions (narrowed to its soft limits at open)", "numbers",
                            "mm", -10000.0, 10000.0, length=(2, 2)),
}  # fmt: skip
"""The keys of a GRBL turntable's configuration section, each with its type, unit and range."""
_CONFIG_KEYS = {"driver", *SETTINGS}


class GrblStatus(TypedDict):
    """One decoded realtime status report (``?``)."""

    state: str  # Idle, Run, Hold, Jog, Alarm, Door, Check, Home, Sleep
    substate: int | None  # e.g. 0 of Hold:0
    position: float  # the axis queried, in its unit (degrees, mm)
    fields: dict[str, str]  # every field of the report by name (MPos, FS, Pn, ...)
    raw: str


@dataclass
class _Controller:
    """What the axes on one controller's connection share (the turntable's, its tilt's, its shift's): the
    alarm the controller raised and whether it restarted unasked, whichever axis read it, so that the
    turntable's :meth:`GrblAxis.recover` clears it for all of them."""

    last_alarm: int | None = None
    restarted: bool = False


ALARM_LOCK_ERROR = 9
"""GRBL's ``error:9``: G-code locked out while the controller is in Alarm (or jogging): a :class:`DeviceFault`."""


def error_text(code: int) -> str:
    return f"error:{code} ({ERROR_CODES.get(code, 'unknown error')})"


def alarm_text(code: int) -> str:
    return f"ALARM:{code} ({ALARM_CODES.get(code, 'unknown alarm')})"


class GrblAxis:
    """One axis of a GRBL controller, its positions in ``unit``: degrees (``"°"``) of a turntable or of
    the calibration board's tilt, millimetres (``"mm"``) of the linear stage that carries the turntable
    sideways. :class:`GrblTurntable` is one; its tilt and shift axes are others on its connection.

    Parameters
    ----------
    port : str
        Serial device or pyserial URL.
    baudrate : int
        115200 (GRBL 1.1 default).
    axis : str
        GRBL axis letter (``"X"``).
    units_per_unit : float
        GRBL units (mm as GRBL sees them) per ``unit`` of this axis (not 0; negative: reversed).
    unit : str
        ``"°"`` or ``"mm"``: how positions, ranges and messages are stated.
    config_prefix : str
        The prefix of this axis's configuration keys (``""``, ``"tilt_"``, ``"shift_"``), which the
        messages about a bad scale or bad limits name.
    feed : float or None
        None: rapid moves ``G0``; else ``G1`` at this feed (units/min).
    limits : (float, float)
        Allowed ``move_to`` range in ``unit``, narrowed at ``open()`` to the
        soft-limit travel (:class:`~drivers.errors.OutOfRange` outside).
    reply_timeout, poll_interval, move_timeout, home_timeout, startup_timeout : float
        Seconds.
    hold_timeout : float
        Seconds a move waits out a feed hold (``Hold``) for cycle start before it is cancelled.
    tolerance : float
        How far from the target an idle axis may be, in ``unit`` (status has 3 decimals).
    """

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = 115200,
        axis: str = "X",
        units_per_unit: float = 1.0,
        unit: str = "°",
        config_prefix: str = "",
        feed: float | None = None,
        limits: tuple[float, float] = (0.0, 360.0),
        reply_timeout: float = 1.0,
        poll_interval: float = 0.05,
        move_timeout: float = 60.0,
        home_timeout: float = 120.0,
        startup_timeout: float = 3.0,
        hold_timeout: float = 10.0,
        tolerance: float = 0.002,
        name: str | None = None,
    ):
        axis = str(axis).upper()
        if axis not in _AXES:
            key = f"{config_prefix}axis"
            raise ConfigKeyError(key, f"grbl turntable: {key} must be one of {', '.join(_AXES)}, got {axis!r}")
        if unit not in UNIT_WORDS:
            raise ValueError(f"grbl turntable: unit must be one of {', '.join(UNIT_WORDS)}, got {unit!r}")
        if units_per_unit == 0:
            key = f"{config_prefix}units_per_{UNIT_WORDS[unit]}"
            raise ConfigKeyError(key, f"grbl turntable: {key} must not be 0")
        if feed is not None and feed <= 0:
            raise ValueError(f"grbl turntable: feed must be positive, got {feed}")
        lo, hi = (float(v) for v in limits)
        if not lo < hi:
            key = f"{config_prefix}limits"
            raise ConfigKeyError(key, f"grbl turntable: {key} must be (min, max) with min < max, got {limits}")
        self.axis = axis
        self.unit = unit
        self.config_prefix = config_prefix
        self.units_per_unit = float(units_per_unit)
        self.feed = feed
        self._configured = Range(lo, hi, unit, "configured limits")
        self._device_travel: Range | None = None
        self._travel = self._configured
        self.settings: dict[int, float] = {}  # as read by ``$$`` at open()
        self.reply_timeout = float(reply_timeout)
        self.poll_interval = float(poll_interval)
        self.move_timeout = float(move_timeout)
        self.home_timeout = float(home_timeout)
        self.startup_timeout = float(startup_timeout)
        self.hold_timeout = float(hold_timeout)
        self.tolerance = float(tolerance)
        self.name = name or f"grbl {port} axis {axis}"
        self.transport = SerialTransport(port, baudrate, name=self.name)
        self.messages: list[str] = []  # [MSG:...] and other feedback lines seen
        self.version: str | None = None
        self._controller = _Controller()
        self._lock = threading.RLock()
        self._target: float | None = None
        self._shared = False  # an axis on another axis's connection (the tilt, the shift axis): opened and closed by it
        self._others: list[GrblAxis] = []  # the axes on this one's connection, opened with it

    def _another_axis(
        self, role: str, letter: str, units_per_unit: float, limits: tuple[float, float], unit: str
    ) -> GrblAxis:
        """Axis ``letter`` of this controller on this connection (the ``role`` axis: ``"tilt"``, ``"shift"``),
        opened, closed and locked with this one; ValueError when it is an axis already in use."""
        for other in (self, *self._others):
            if str(letter).upper() == other.axis:
                raise ConfigKeyError(
                    f"{role}_axis",
                    f"grbl turntable: {role}_axis must be another axis than {other.axis}, got {letter!r}",
                )
        axis = GrblAxis(
            self.transport.port, baudrate=self.transport.baudrate, axis=str(letter), units_per_unit=units_per_unit,
            unit=unit, config_prefix=f"{role}_", feed=self.feed, limits=tuple(limits),  # type: ignore[arg-type]
            reply_timeout=self.reply_timeout, poll_interval=self.poll_interval, move_timeout=self.move_timeout,
            home_timeout=self.home_timeout, startup_timeout=self.startup_timeout, hold_timeout=self.hold_timeout,
            tolerance=self.tolerance, name=f"{self.name} {role} axis {str(letter).upper()}",
        )  # fmt: skip
        axis.transport, axis._lock, axis._shared = self.transport, self._lock, True
        axis._controller = self._controller
        self._others.append(axis)
        return axis

    @property
    def last_alarm(self) -> int | None:
        """The alarm code the controller raised (``ALARM:N``) and nobody cleared yet (one for every axis on
        its connection)."""
        return self._controller.last_alarm

    @last_alarm.setter
    def last_alarm(self, code: int | None) -> None:
        self._controller.last_alarm = code

    @property
    def restarted(self) -> bool:
        """The controller printed its banner unasked since it was last homed or recovered: it started again
        (a power dip, a USB reset that rebooted the board) and counts its position from 0 wherever the axes
        stand; every move is refused (:class:`DeviceFault`) until :meth:`recover` and :meth:`home`."""
        return self._controller.restarted

    def _restart_fault(self) -> DeviceFault:
        return DeviceFault(
            f"{self.name}: the controller restarted (its banner came unasked: a power dip or a USB reset),"
            " its position is lost; use recover(), then home()"
        )

    # -- life cycle --------------------------------------------------------------
    def open(self) -> None:
        """Open the port, soft-reset GRBL (Ctrl-X) and wait for its banner (the tilt, the shift axis: the same
        controller's settings and a status report, on the connection its turntable opened)."""
        if self._shared:
            self._device_travel = self._soft_limit_travel()
            self._travel = effective_travel(self.name, self._configured, self._device_travel)
            self.query_status()
            return
        self.transport.open()
        try:
            with self._lock:
                self.last_alarm = None  # the controller's state after the reset is what counts
                self._controller.restarted = False
                self._target = None
                self.transport.pending()
                self.transport.write(b"\x18")
                self._wait_banner(self.startup_timeout)
                self.settings = self.read_settings()
                self._device_travel = self._soft_limit_travel()
                self._travel = effective_travel(self.name, self._configured, self._device_travel)
                for other in self._others:
                    other.settings = self.settings
                    try:
                        other.open()
                    except DriverError as exc:  # the tilt or shift axis: name its key
                        exc.config_key = f"{other.config_prefix}axis"
                        raise
        except Exception:
            self.transport.close()
            raise

    def _wait_banner(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DeviceTimeout(f"{self.name}: no GRBL banner within {timeout:.2f} s after reset")
            line = self.transport.readline(remaining, "GRBL banner after reset", total=timeout).strip()
            text = line.decode("ascii", "replace")
            if text.startswith("Grbl "):
                self.version = text.split()[1]
                return
            if text.startswith("ALARM:"):
                self.last_alarm = int(text[6:]) if text[6:].isdigit() else None

    def close(self) -> None:
        if not self._shared:
            self.transport.close()

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- wire level ----------------------------------------------------------------
    def _decode(self, line: bytes) -> str:
        try:
            return line.decode("ascii").strip()
        except UnicodeDecodeError:
            raise ProtocolError(f"{self.name}: garbage on the line: {line!r}") from None

    def _classify(self, text: str) -> None:
        """Record a feedback line; raise on garbage. Returns None for ignorable lines."""
        if text.startswith("[") and text.endswith("]"):
            self.messages.append(text)
            return
        if text.startswith("Grbl "):  # a banner nobody asked for: the controller started again
            self.messages.append(text)
            self._controller.restarted = True
            raise self._restart_fault()
        m = _ALARM.match(text)
        if m:
            self.last_alarm = int(m.group(1))
            raise DeviceFault(f"{self.name}: {alarm_text(self.last_alarm)}; use recover()")
        raise ProtocolError(f"{self.name}: not a GRBL message: {text!r}")

    def _drain(self) -> None:
        for line in self.transport.pending().splitlines():
            text = line.decode("ascii", "replace").strip()
            if _ALARM.match(text):
                self.last_alarm = int(text[6:])
            elif text.startswith("Grbl "):  # it started again while nobody was listening
                self._controller.restarted = True

    def send(self, line: str, timeout: float | None = None) -> list[str]:
        """Send one line and wait for ``ok``; returns the feedback lines before it.

        Raises :class:`DeviceRejected` on ``error:N`` (:class:`DeviceFault` on ``error:9``, the Alarm lock) and
        :class:`DeviceFault` on ``ALARM:N``.
        """
        timeout = self.reply_timeout if timeout is None else timeout
        what = f"reply to {line!r}"
        with self._lock:
            self._drain()
            self.transport.write(line.encode("ascii") + b"\n")
            deadline = time.monotonic() + timeout
            feedback: list[str] = []
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeout(f"{self.name}: no {what} within {timeout:.2f} s")
                text = self._decode(self.transport.readline(remaining, what, total=timeout))
                if not text or text.startswith("<"):
                    continue
                if text == "ok":
                    return feedback
                m = _ERROR.match(text)
                if m:
                    code = int(m.group(1))
                    if code == ALARM_LOCK_ERROR:  # not the line's fault: the controller waits in Alarm
                        raise DeviceFault(
                            f"{self.name}: {line!r} refused: {error_text(code)}; use recover(), then home()"
                        )
                    raise DeviceRejected(f"{self.name}: {line!r} rejected: {error_text(code)}")
                n_messages = len(self.messages)
                self._classify(text)
                feedback.extend(self.messages[n_messages:])

    def query_status(self) -> GrblStatus:
        """Realtime ``?``: ``{"state", "substate", "position" (in :attr:`unit`), "fields"}``."""
        with self._lock:
            self._drain()
            self.transport.write(b"?")
            deadline = time.monotonic() + self.reply_timeout
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeout(f"{self.name}: no status report within {self.reply_timeout:.2f} s")
                text = self._decode(self.transport.readline(remaining, "status report", total=self.reply_timeout))
                if not text or text == "ok" or _ERROR.match(text):  # a late reply to an earlier line
                    continue
                if text.startswith("<"):
                    return self._parse_status(text)
                self._classify(text)

    def _parse_status(self, text: str) -> GrblStatus:
        m = _STATUS.match(text)
        if not m:
            raise ProtocolError(f"{self.name}: malformed status report {text!r}")
        fields: dict[str, str] = {}
        for part in m["fields"].split("|"):
            key, sep, value = part.partition(":")
            if not sep:
                raise ProtocolError(f"{self.name}: malformed status field {part!r} in {text!r}")
            fields[key] = value
        coords = fields.get("MPos", fields.get("WPos"))
        if coords is None:
            raise ProtocolError(f"{self.name}: status report without MPos/WPos: {text!r}")
        try:
            values = [float(v) for v in coords.split(",")]
            units = values[_AXES.index(self.axis)]
        except (ValueError, IndexError):
            raise ProtocolError(f"{self.name}: bad coordinates in {text!r}") from None
        return {
            "state": m["state"],
            "substate": int(m["sub"]) if m["sub"] else None,
            "position": units / self.units_per_unit,
            "fields": fields,
            "raw": text,
        }

    def read_settings(self) -> dict[int, float]:
        """``$$``: every setting, ``{130: 360.0, ...}``; ``{}`` if the controller refuses ``$$``."""
        with self._lock:
            self._drain()
            self.transport.write(b"$$\n")
            deadline = time.monotonic() + self.reply_timeout
            settings: dict[int, float] = {}
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeout(f"{self.name}: no end of the settings ($$) within {self.reply_timeout:.2f} s")
                text = self._decode(self.transport.readline(remaining, "reply to '$$'", total=self.reply_timeout))
                if not text or text.startswith("<"):
                    continue
                if text == "ok":
                    return settings
                if _ERROR.match(text):
                    return {}  # not a GRBL that lists its settings: no device travel known
                m = _SETTING.match(text)
                if m:
                    settings[int(m.group(1))] = float(m.group(2))
                    continue
                self._classify(text)

    def _soft_limit_travel(self) -> Range | None:
        idx = _AXES.index(self.axis)
        travel = self.settings.get(130 + idx)
        if not self.settings.get(20) or travel is None:
            return None
        ends = sorted((-travel / self.units_per_unit, 0.0))
        return Range(ends[0], ends[1], self.unit, f"GRBL soft limits $20=1, ${130 + idx}={travel:.3f}")

    # -- Turntable protocol ----------------------------------------------------------
    @property
    def limits(self) -> tuple[float, float]:
        """``(min, max)`` of :meth:`travel_range` (the configured limits before ``open()``)."""
        return (self._travel.minimum, self._travel.maximum)

    def travel_range(self) -> Range:
        """The angles ``move_to`` accepts: the configured limits within the soft-limit travel."""
        return self._travel

    def device_travel_range(self) -> Range | None:
        """The soft-limit travel read at ``open()`` in :attr:`unit`; None when ``$20=0`` (no limits)."""
        return self._device_travel

    def position(self) -> float:
        return self.query_status()["position"]

    def _show(self, position: float) -> str:
        """A position in messages: ``45.000°``, ``12.500 mm`` (the status reports 3 decimals)."""
        return f"{position:.3f}{with_unit(self.unit)}"

    def status(self) -> dict[str, Any]:
        st = self.query_status()
        warnings = []
        if st["state"] == "Alarm":
            warnings.append(alarm_text(self.last_alarm) if self.last_alarm else "Alarm (locked: home or unlock)")
        elif st["state"] == "Hold":
            warnings.append(f"Hold:{st['substate']} (feed hold: cycle start ~ resumes)")
        elif st["state"] == "Door":
            warnings.append(f"Door:{st['substate']} (safety door opened)")
        if self.restarted:
            warnings.append("restarted: position lost (home it)")
        return {
            "busy": st["state"] in ("Run", "Home", "Jog"),
            "warnings": warnings,
            "state": st["state"],
            "position": st["position"],
            "fault": st["state"] in ("Alarm", "Door") or self.restarted,
        }

    def home(self, timeout: float | None = None) -> None:
        timeout = self.home_timeout if timeout is None else timeout
        with self._lock:
            self._target = None
            self.send("$H", timeout=timeout)  # GRBL answers ok when the cycle is over
            self.last_alarm = None
            self._controller.restarted = False  # homed: the position is known again
            self._wait_idle(timeout, "home", None)

    def start_move(self, position: float) -> float:
        """Queue the move (``ok`` = buffered) and return without waiting."""
        self._travel.check(self.name, "move to", position)
        units = position * self.units_per_unit
        cmd = f"G90 G0 {self.axis}{units:.3f}" if self.feed is None else f"G90 G1 {self.axis}{units:.3f} F{self.feed:g}"
        with self._lock:
            self._drain()  # an alarm or a restart said while nobody was listening
            if self.restarted:
                raise self._restart_fault()
            if self.last_alarm is not None:
                raise DeviceFault(
                    f"{self.name}: cannot move, controller in {alarm_text(self.last_alarm)};"
                    " call recover() (then home())"
                )
            self.send(cmd)
            self._target = round(units, 3) / self.units_per_unit
        return self._target

    def move_to(self, position: float, timeout: float | None = None) -> float:
        """Move to ``position`` (in :attr:`unit`) and wait until idle there; returns the position read back."""
        timeout = self.move_timeout if timeout is None else timeout
        with self._lock:
            target = self.start_move(position)
            return self._wait_idle(timeout, f"move to {position}{with_unit(self.unit)}", target)

    def wait_idle(self, timeout: float | None = None) -> float:
        timeout = self.move_timeout if timeout is None else timeout
        return self._wait_idle(timeout, "wait", self._target)

    def _wait_idle(self, timeout: float, what: str, target: float | None) -> float:
        deadline = time.monotonic() + timeout
        held_since: float | None = None  # when the feed hold that keeps the move waiting was first seen
        while True:
            st = self.query_status()
            state, pos = st["state"], st["position"]
            if self.restarted:  # its position counts from 0 again: wherever it says it is, it is not known
                raise self._restart_fault()
            if state == "Alarm":
                cause = alarm_text(self.last_alarm) if self.last_alarm else "alarm state"
                raise DeviceFault(f"{self.name}: {what} failed at {self._show(pos)}: {cause}; use recover()")
            if state == "Door":  # nothing moves until the door is shut and cycle start pressed: not a wait
                raise DeviceFault(
                    f"{self.name}: {what} stopped at {self._show(pos)}: safety door opened (Door:{st['substate']});"
                    " close it and resume the session"
                )
            if state == "Hold":  # a feed hold (the controller's button, or '!'): cycle start ('~') lets it go on
                now = time.monotonic()
                held_since = now if held_since is None else held_since
                if now - held_since >= self.hold_timeout:
                    # the planner flushed: nothing moves behind the caller's back (a stop that fails raises its
                    # own error, e.g. the port gone, instead of a fault saying the move was cancelled)
                    self.stop()
                    raise DeviceFault(
                        f"{self.name}: {what} held by a feed hold (Hold:{st['substate']}) at {self._show(pos)}"
                        f" for {self.hold_timeout:g} s without cycle start (~); move cancelled, position kept:"
                        " resume the session"
                    )
            else:
                held_since = None
            if state == "Idle":
                if target is not None and abs(pos - target) > self.tolerance:
                    raise DeviceFault(
                        f"{self.name}: {what} ended idle at {self._show(pos)}, not at {self._show(target)}"
                    )
                return pos
            if time.monotonic() >= deadline:
                try:
                    self.stop()
                finally:
                    raise DeviceTimeout(
                        f"{self.name}: {what} not finished within {timeout:.2f} s"
                        f" (state {state} at {self._show(pos)}); feed hold + reset sent"
                    )
            time.sleep(self.poll_interval)

    def stop(self) -> None:
        """Feed hold, then soft reset to flush the planner (position kept)."""
        with self._lock:
            self._target = None
            self.transport.write(b"!")
            deadline = time.monotonic() + self.reply_timeout
            while time.monotonic() < deadline:
                st = self.query_status()
                if st["state"] in ("Idle", "Alarm") or (st["state"] == "Hold" and st["substate"] == 0):
                    break
                time.sleep(self.poll_interval)
            self.transport.write(b"\x18")
            self._wait_banner(self.startup_timeout)

    def unlock(self) -> None:
        """``$X``: leave the alarm state."""
        self.send("$X")

    def recover(self) -> list[str]:
        """Leave an alarm: soft reset if GRBL waits for one, then ``$X`` (for every axis of the controller:
        whichever of them read the alarm).

        Returns the alarm descriptions that were cleared. After a hard-limit
        alarm the position is lost: call :meth:`home` before moving (after a restart of the controller,
        :attr:`restarted`, moves are refused until then).
        """
        with self._lock:
            self._drain()
            cleared = [alarm_text(self.last_alarm)] if self.last_alarm else []
            if self.restarted:
                cleared.append("restart (position lost: home it)")
            self.transport.write(b"\x18")
            self._wait_banner(self.startup_timeout)
            st = self.query_status()
            if st["state"] == "Alarm":
                self.unlock()
            self.last_alarm = None
            return cleared

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.transport.port!r}, axis={self.axis!r})"


class GrblTurntable(GrblAxis):
    """A turntable on one GRBL axis; satisfies :class:`drivers.protocols.Turntable`.

    Parameters
    ----------
    port : str
        Serial device or pyserial URL.
    baudrate : int
        115200 (GRBL 1.1 default).
    axis : str
        GRBL axis letter carrying the turntable (``"X"``).
    units_per_degree : float
        GRBL units (mm as GRBL sees them) per degree of the table.
    feed : float or None
        None: rapid moves ``G0``; else ``G1`` at this feed (units/min).
    limits : (float, float)
        Allowed ``move_to`` range in degrees, narrowed at ``open()`` to the
        soft-limit travel (:class:`~drivers.errors.OutOfRange` outside).
    reply_timeout, poll_interval, move_timeout, home_timeout, startup_timeout : float
        Seconds.
    hold_timeout : float
        Seconds a move waits out a feed hold (``Hold``) for cycle start before it is cancelled.
    tolerance_deg : float
        How far from the target an idle axis may be (status has 3 decimals).
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
        axis: str = "X",
        units_per_degree: float = 1.0,
        feed: float | None = None,
        limits: tuple[float, float] = (0.0, 360.0),
        reply_timeout: float = 1.0,
        poll_interval: float = 0.05,
        move_timeout: float = 60.0,
        home_timeout: float = 120.0,
        startup_timeout: float = 3.0,
        hold_timeout: float = 10.0,
        tolerance_deg: float = 0.002,
        name: str | None = None,
        tilt_axis: str | None = None,
        tilt_units_per_degree: float = 1.0,
        tilt_limits: tuple[float, float] = TILT_LIMITS_DEG,
        shift_axis: str | None = None,
        shift_units_per_mm: float = 1.0,
        shift_limits: tuple[float, float] = SHIFT_LIMITS_MM,
    ):
        super().__init__(
            port, baudrate=baudrate, axis=axis, units_per_unit=units_per_degree, unit="°", feed=feed, limits=limits,
            reply_timeout=reply_timeout, poll_interval=poll_interval, move_timeout=move_timeout,
            home_timeout=home_timeout, startup_timeout=startup_timeout, hold_timeout=hold_timeout,
            tolerance=tolerance_deg, name=name,
        )  # fmt: skip
        self.tilt: GrblAxis | None = None
        """The tilt axis (``tilt_axis``): another axis of this controller, on this connection, which tilts the
        calibration board (:class:`drivers.protocols.Tilting`), in degrees; None without one."""
        if tilt_axis is not None:
            self.tilt = self._another_axis("tilt", tilt_axis, tilt_units_per_degree, tilt_limits, "°")
        self.shift: GrblAxis | None = None
        """The shift axis (``shift_axis``): another axis of this controller, on this connection, a linear stage
        that carries the turntable sideways (:class:`drivers.protocols.ShiftingTurntable`), in millimetres;
        None without one."""
        if shift_axis is not None:
            self.shift = self._another_axis("shift", shift_axis, shift_units_per_mm, shift_limits, "mm")

    @property
    def units_per_degree(self) -> float:
        """GRBL units per degree of the turntable."""
        return self.units_per_unit

    @classmethod
    def from_config(cls, cfg: dict[str, Any], **ctx: Any) -> GrblTurntable:
        check_config_keys("grbl turntable", cfg, SETTINGS, {"port": "device name or pyserial URL"})
        kw = {k: v for k, v in cfg.items() if k not in ("driver", "steps_per_degree", "steps_per_unit")}
        if "steps_per_unit" in cfg and "steps_per_degree" not in cfg:
            raise ValueError("grbl turntable: 'steps_per_unit' needs 'steps_per_degree'")
        if "steps_per_degree" in cfg:
            # motor steps per table degree, and GRBL's own $10x steps per unit
            # (default: GRBL is set up in degrees, one unit = one degree)
            if "units_per_degree" in cfg:
                raise ValueError("grbl turntable: give 'units_per_degree' or 'steps_per_degree', not both")
            spd = float(cfg["steps_per_degree"])
            spu = float(cfg.get("steps_per_unit", spd))
            if spd <= 0 or spu <= 0:
                raise ValueError("grbl turntable: 'steps_per_degree' and 'steps_per_unit' must be positive")
            kw["units_per_degree"] = spd / spu
        for key in ("limits", "tilt_limits", "shift_limits"):
            if key in kw:
                kw[key] = tuple(kw[key])
        return cls(kw.pop("port"), **kw)
