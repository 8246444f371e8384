"""A GRBL 1.1 controller driving one rotary axis, speaking the real bytes.

Realtime bytes (no line end, no ``ok``): ``?`` status report
``<Idle|MPos:45.000,0.000,0.000|FS:0,0>`` (``Run`` while moving, ``Home``
while homing, ``Hold:0`` after ``!``, ``Door:1``/``Door:0`` with the safety door open/shut again,
``Alarm``), ``!`` feed hold (moving or idle; ignored while homing, as GRBL's homing cycle does), ``~``
cycle start (resumes a hold, or a door state once the door is shut: ``Door:0``), 0x84 safety door (as
the door switch opening; with the door itself shut the state is ``Door:0``), Ctrl-X (0x18) soft reset,
answered by the banner ``\\r\\nGrbl 1.1h ['$' for help]\\r\\n`` (with the door still open, GRBL
enters ``Door:1`` again once idle). The motion stops at once (the deceleration states ``Hold:1`` and
``Door:2`` pass within a tick). :meth:`GrblEmulator.open_door` / :meth:`GrblEmulator.close_door` are the
safety-door switch (``ENABLE_SAFETY_DOOR_INPUT_PIN``; opened during homing: ``ALARM:7``),
:meth:`GrblEmulator.feed_hold` / :meth:`GrblEmulator.cycle_start` the controller's buttons.

Lines (ended by ``\\n`` or ``\\r``), each answered by ``ok`` or ``error:N``:
``$H`` homing (``ok`` only when the cycle is over), ``$X`` unlock
(``[MSG:Caution: Unlocked]``), ``G90``/``G91``, ``G0``/``G1`` with ``X``
(degrees, or ``units_per_degree`` units) and ``F``. Moves are queued as in
the real planner: ``ok`` means buffered, not done. With homing enabled
(``homing=True``, the default) the controller starts in ``Alarm`` and
prints ``[MSG:'$H'|'$X' to unlock]``; G-code is then refused with
``error:9``.

Settings, as GRBL 1.1h stores and prints them: ``$$`` lists every setting,
one ``$N=value`` line each (integers, or 3 decimals; ``$30``/``$31`` without
decimals) then ``ok``; ``$N=value`` changes one (``error:3`` for an unknown
``N``, ``error:4`` for a negative value, ``error:10`` for ``$20=1`` while
``$22=0``; ``$22=0`` also clears ``$20``; ``error:8`` while moving). The
generic defaults of ``grbl/defaults.h`` apply, except: ``$20`` = ``soft_limits``,
``$22`` = ``homing``, ``$27=0.000`` (no pull-off: homing ends at machine 0),
and for the turntable's axis ``$11x`` / ``$12x`` from the emulated speed and
acceleration and ``$13x`` = ``max_travel``. Soft limits (``$20=1``), as in
GRBL's ``system_check_travel_limits``: a target outside machine
``[-$13x, 0]`` raises ``ALARM:2`` (critical: reset to continue).

With ``tilt_axis`` (e.g. ``"Y"``) a second axis tilts the calibration board, in degrees (``G90 G0 Y30.000``;
its position in the status report's ``MPos``; homed with the turntable by ``$H``; blocks of both axes run
one after another, as GRBL's planner runs them; not soft-limited here), and drives the simulated world's
board tilt. With ``shift_axis`` (e.g. ``"Z"``) another axis is the linear stage that carries the turntable
sideways, in mm (1 unit = 1 mm: ``G90 G0 Z12.500``; ``$13x`` = :data:`SHIFT_TRAVEL_MM`; at
``shift_speed_mm_s``), the same way, and drives the world's shift (:meth:`SimWorld.drive_shift`).

Faults (:meth:`inject`): ``"reject"`` (``error:N``, ``code`` default 20),
``"no_reply"``, ``"garbage"``, ``"alarm"`` (hard limit ``ALARM:1`` at
fraction ``at`` of the next move: motion stops, ``[MSG:Reset to continue]``,
every line is ignored until Ctrl-X; then ``$X`` or ``$H``), ``"vanish"``, ``"door"`` (the safety door
opens at fraction ``at`` of the next move and stays open until :meth:`GrblEmulator.close_door`),
``"hold"`` (the feed-hold button pressed at fraction ``at``; :meth:`GrblEmulator.cycle_start` or ``~``
resumes); the motion faults wait for a move of the turntable's axis, or of the axis ``axis`` names
(``axis="Z"``: the linear stage's). :meth:`GrblEmulator.restart` starts the controller again as at power-up.
"""

from __future__ import annotations

import re
import time
from typing import TYPE_CHECKING, Any

from drivers.sim.line_emulator import LineEmulator
from drivers.sim.motion import Axis
from drivers.sim.pty_server import serve
from drivers.sim.world import SimWorld

if TYPE_CHECKING:
    from drivers.sim.pty_server import EmulatorHandle

BANNER = b"\r\nGrbl 1.1h ['$' for help]\r\n"
TILT_TRAVEL_DEG = 90.0
"""The tilt axis's ``$13x`` (``tilt_axis``)."""
SHIFT_TRAVEL_MM = 100.0
"""The shift axis's ``$13x`` (``shift_axis``), mm."""
UNLOCK_MSG = b"[MSG:'$H'|'$X' to unlock]\r\n"

_WORD = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")
_SETTING = re.compile(r"^\$(?P<n>\d+)=(?P<value>.*)$")

# GRBL 1.1h report_grbl_settings: which settings print as integers, which without decimals
_INT_SETTINGS = frozenset({0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 32})
_RPM_SETTINGS = frozenset({30, 31})


def _default_settings(n_axes: int) -> dict[int, float]:
    """GRBL 1.1h ``DEFAULTS_GENERIC`` (grbl/defaults.h), with no homing pull-off."""
    settings: dict[int, float] = {
        0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0,
        20: 0, 21: 0, 22: 0, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 0.0, 30: 1000.0, 31: 0.0, 32: 0,
    }  # fmt: skip
    for i in range(n_axes):
        settings[100 + i] = 250.0  # steps/mm
        settings[110 + i] = 500.0  # max rate, mm/min
        settings[120 + i] = 10.0  # acceleration, mm/s^2
        settings[130 + i] = 200.0  # max travel, mm
    return settings


def _format_setting(n: int, value: float) -> str:
    """One value as GRBL prints it (print_uint8_base10 / printFloat with 0 or 3 decimals)."""
    if n in _INT_SETTINGS:
        return str(int(value))
    return f"{value:.0f}" if n in _RPM_SETTINGS else f"{value:.3f}"


class GrblEmulator(LineEmulator):
    NAME = "GRBL emulator"
    MOTION = ("alarm", "vanish", "door", "hold")

    def __init__(
        self,
        world: SimWorld | None = None,
        *,
        units_per_degree: float = 1.0,
        speed_deg_s: float = 360.0,
        accel_deg_s2: float = 3600.0,
        soft_limits: bool = False,
        max_travel: float = 360.0,
        homing: bool = True,
        position_deg: float = 0.0,
        axis: str = "X",
        seed: int = 0,
        tilt_axis: str | None = None,
        shift_axis: str | None = None,
        shift_speed_mm_s: float = 100.0,
        shift_accel_mm_s2: float = 1000.0,
    ):
        super().__init__(world, seed)
        axis = str(axis).upper()
        if axis not in "XYZA" or len(axis) != 1:
            raise ValueError(f"GRBL emulator axis must be X, Y, Z or A, got {axis!r}")
        taken = [axis]
        letters: list[str | None] = []
        for key, given in (("tilt_axis", tilt_axis), ("shift_axis", shift_axis)):
            letter = None if given is None else str(given).upper()
            if letter is not None and (letter not in "XYZA" or len(letter) != 1 or letter in taken):
                raise ValueError(f"GRBL emulator {key} must be another of X, Y, Z or A, got {given!r}")
            taken.append(letter or "")
            letters.append(letter)
        tilt_letter, shift_letter = letters
        self.axis_letter = axis
        self.n_axes = 4 if "A" in taken else 3
        self.upd = float(units_per_degree)
        if self.upd == 0:
            raise ValueError("GRBL emulator units_per_degree must not be 0")
        if soft_limits and not homing:
            raise ValueError("GRBL emulator: soft limits need homing ($20=1 requires $22=1)")
        if max_travel < 0:
            raise ValueError(f"GRBL emulator max_travel ($13x) must be >= 0, got {max_travel}")
        scale = abs(self.upd)
        self.axis = Axis(position_deg * self.upd, speed_deg_s * scale, accel_deg_s2 * scale)
        self.axis_index = "XYZA".index(axis)
        self.settings = _default_settings(self.n_axes)
        self.settings[20] = int(bool(soft_limits))
        self.settings[22] = int(bool(homing))
        self.settings[110 + self.axis_index] = speed_deg_s * scale * 60.0
        self.settings[120 + self.axis_index] = accel_deg_s2 * scale
        self.settings[130 + self.axis_index] = float(max_travel)
        self.state = "Alarm" if homing else "Idle"
        self.critical = False  # waiting for Ctrl-X after a hard/soft limit alarm
        self.absolute = True
        self.feed: float | None = None
        self.queue: list[tuple[str, float]] = []  # (axis letter, target): blocks run one after another
        self._homing = False
        self._held: tuple[str, float] | None = None
        self.door_open = False  # the safety-door switch
        # the tilt axis (tilt_axis): the calibration board's tilt, in degrees (1 unit = 1 degree), at 0;
        # the shift axis (shift_axis): the linear stage under the turntable, in mm (1 unit = 1 mm), at 0
        self.tilt_letter, self.shift_letter = tilt_letter, shift_letter
        self.tilt: Axis | None = None
        self.shift: Axis | None = None
        self._axes = {axis: self.axis}
        if tilt_letter is not None:
            self.tilt = Axis(0.0, speed_deg_s, accel_deg_s2)
            self._axes[tilt_letter] = self.tilt
            self.settings[130 + "XYZA".index(tilt_letter)] = TILT_TRAVEL_DEG
            if world is not None:
                world.drive_tilt(self._tilt_for_world, self.NAME)
        if shift_letter is not None:
            self.shift = Axis(0.0, shift_speed_mm_s, shift_accel_mm_s2)
            self._axes[shift_letter] = self.shift
            self.settings[130 + "XYZA".index(shift_letter)] = SHIFT_TRAVEL_MM
            if world is not None:
                world.drive_shift(self._shift_for_world, self.NAME)

    @property
    def homing_enabled(self) -> bool:
        return bool(self.settings[22])

    @property
    def soft_limits(self) -> tuple[float, float] | None:
        """The machine range of the turntable axis while ``$20=1`` (GRBL units), else None."""
        if not self.settings[20]:
            return None
        return (-float(self.settings[130 + self.axis_index]), 0.0)

    def stage_degrees(self, now: float) -> float:
        return self.axis.peek(now) / self.upd

    def _tilt_for_world(self, t: float) -> float:
        with self._lock:  # not while a command is half-way through
            return self.tilt.peek(t) if self.tilt is not None else 0.0

    def _shift_for_world(self, t: float) -> float:
        with self._lock:  # not while a command is half-way through
            return self.shift.peek(t) if self.shift is not None else 0.0

    def _busy(self, now: float) -> bool:
        return any(a.busy(now) for a in self._axes.values())

    def _line(self, text: str) -> None:
        self.write(text.encode("ascii") + b"\r\n")

    # -- realtime ----------------------------------------------------------------
    def handle_realtime(self, byte: bytes, now: float) -> bool:
        if byte == b"?":
            if self._take_counted("no_reply") is not None:
                return True
            if self._take_counted("garbage") is not None:
                self.write(self.garbage())
                return True
            self._status(now)
            return True
        if byte == b"!":
            if self.state in ("Run", "Idle"):  # GRBL: IDLE, CYCLE, JOG (not during the homing cycle)
                self._suspend("Hold:0", now)
            return True
        if byte == b"~":
            if self.state.startswith("Hold") or self.state == "Door:0":
                self._resume(now)
            return True
        if byte == b"\x84":  # safety door, as the switch opening: stopped, "ajar" as the switch reads
            self._door(now)
            return True
        if byte == b"\x18":
            self._reset(now)
            return True
        return False

    def _suspend(self, state: str, now: float) -> None:
        """Stop every axis (the move under way kept, to resume) and enter ``state`` (``Hold:0``, ``Door:1``...)."""
        if not self.state.startswith(("Hold", "Door")):
            self._held = None
            for letter, a in self._axes.items():
                if a.move is not None and a.busy(now):
                    self._held = (letter, a.move.target)
        for a in self._axes.values():
            a.halt(now)
        self.state = state

    def _resume(self, now: float) -> None:
        """Cycle start: the held move goes on (the queued blocks after it); nothing held: idle."""
        if self._held is not None:
            letter, target = self._held
            self._axes[letter].start_move(target, now)
            self._held = None
            self.state = "Run"
        else:
            self.state = "Idle"  # update() starts the queued blocks

    def _door(self, now: float) -> None:
        """The safety door opened (or 0x84): homing fails with ``ALARM:7``; an alarm stays; else the motion
        stops in ``Door:1`` (``Door:0`` if the switch reads shut)."""
        if self.state == "Alarm":
            return
        if self.state == "Home":
            for a in self._axes.values():
                a.halt(now)
            self.queue.clear()
            self._homing = False
            self.state = "Alarm"
            self._line("ALARM:7")
            return
        self._suspend("Door:1" if self.door_open else "Door:0", now)

    def open_door(self) -> None:
        """The safety door opens (the door switch): see :meth:`_door`."""
        with self._lock:
            self.door_open = True
            self._door(time.monotonic())

    def close_door(self) -> None:
        """The safety door is shut again: ``Door:1`` becomes ``Door:0`` (cycle start resumes)."""
        with self._lock:
            self.door_open = False
            if self.state.startswith("Door"):
                self.state = "Door:0"

    def feed_hold(self) -> None:
        """The controller's feed-hold button (GRBL's pin): the same as ``!``."""
        with self._lock:
            self.handle_realtime(b"!", time.monotonic())

    def cycle_start(self) -> None:
        """The controller's cycle-start button (GRBL's pin): the same as ``~``."""
        with self._lock:
            self.handle_realtime(b"~", time.monotonic())

    def _status(self, now: float) -> None:
        self.update(now)
        coords = [0.0] * self.n_axes
        for letter, a in self._axes.items():
            coords["XYZA".index(letter)] = a.position(now)
        speed = 0.0
        move = self.axis.move
        if move is not None:
            dt = 1e-3
            speed = abs(move.position(now + dt) - move.position(now)) / dt * 60.0
        mpos = ",".join(f"{c:.3f}" for c in coords)
        self._line(f"<{self.state}|MPos:{mpos}|FS:{speed:.0f},0>")

    def _reset(self, now: float) -> None:
        moving = self._busy(now) and self.state in ("Run", "Home")
        for a in self._axes.values():
            a.halt(now)
        if moving:
            self._line("ALARM:3")  # reset while in motion: position lost
        self._start_over("Alarm" if moving or self.state == "Alarm" else "Idle")

    def _start_over(self, state: str) -> None:
        """What a soft reset (Ctrl-X) and a restart share: the planner, a homing cycle, a feed hold and the line
        being received dropped; then ``state`` and the banner (with the unlock message in ``Alarm``)."""
        self.queue.clear()
        self._homing = False
        self._held = None
        self._inbuf.clear()
        self.critical = False
        self.state = state
        self.write(BANNER)
        if state == "Alarm":
            self.write(UNLOCK_MSG)
        elif self.door_open:  # GRBL checks the door at start: still open, it enters the door state
            self.state = "Door:1"

    def restart(self) -> None:
        """Start again as at power-up (a brown-out, a USB reset that reboots the board, a watchdog): the
        planner and any motion are dropped, the machine position counts from 0 again (this emulator has no
        home switch apart from machine 0: the stage is taken to be there), with homing on the controller
        waits in ``Alarm`` for ``$H`` or ``$X``; it says so with its banner, as at power-up, and nothing
        else (no ``ALARM:`` line)."""
        with self._lock:
            for a in self._axes.values():
                a.set_position(0.0)
            self._start_over("Alarm" if self.homing_enabled else "Idle")

    # -- lines --------------------------------------------------------------------
    def reject(self, line: bytes, spec: dict[str, Any], now: float) -> None:
        if not self.critical:
            self._line(f"error:{spec.get('code', 20)}")

    def handle_line(self, line: bytes, now: float) -> None:
        if self.critical:
            return  # everything but realtime commands is ignored until reset
        try:
            text = line.decode("ascii").strip().upper().replace(" ", "")
        except UnicodeDecodeError:
            self._line("error:1")
            return
        if not text:
            return
        if text.startswith("$"):
            self._system(text, now)
            return
        self._gcode(text, now)

    def _system(self, text: str, now: float) -> None:
        if text == "$H":
            if not self.homing_enabled:
                self._line("error:5")
                return
            if self.state not in ("Idle", "Alarm"):
                self._line("error:8")
                return
            if self.door_open:  # GRBL: blocked while the safety door is ajar
                self._line("error:13")
                return
            self.state = "Home"
            self._homing = True
            for a in self._axes.values():  # every axis to its home switch (machine 0)
                a.start_move(0.0, now)  # ok is sent when the cycle ends
            return
        if text == "$X":
            if self.state == "Alarm":
                self.state = "Idle"
                self._line("[MSG:Caution: Unlocked]")
            self._line("ok")
            return
        if text == "$$":
            if self.state in ("Run", "Home") or self.state.startswith("Hold"):  # GRBL: CYCLE, HOLD
                self._line("error:8")
                return
            for n, value in sorted(self.settings.items()):
                self._line(f"${n}={_format_setting(n, value)}")
            self._line("ok")
            return
        m = _SETTING.match(text)
        if m:
            self._line(self._write_setting(int(m["n"]), m["value"]))
            return
        self._line("error:3")

    def _write_setting(self, n: int, text: str) -> str:
        """``$N=value``: the reply (``ok`` or ``error:N``), as GRBL's settings_store_global_setting."""
        if self.state in ("Run", "Home") or self.state.startswith(("Hold", "Door")):
            return "error:8"
        if n not in self.settings:
            return "error:3"
        try:
            value = float(text)
        except ValueError:
            return "error:2"
        if value < 0:
            return "error:4"
        if n in _INT_SETTINGS:
            value = int(value)
        if n == 20 and value and not self.settings[22]:
            return "error:10"
        self.settings[n] = value
        if n == 22 and not value:
            self.settings[20] = 0  # GRBL: disabling homing forces soft limits off
        if n == 110 + self.axis_index and value > 0:
            self.axis.vmax = value / 60.0
        if n == 120 + self.axis_index and value > 0:
            self.axis.accel = value
        return "ok"

    def _gcode(self, text: str, now: float) -> None:
        words = _WORD.findall(text)
        if "".join(a + b for a, b in words) != text:
            self._line("error:1" if text[:1].isalpha() else "error:2")
            return
        if self.state == "Alarm":
            self._line("error:9")
            return
        motion = None
        absolute = self.absolute
        x = None
        others: dict[str, float] = {}  # the tilt's, the shift's targets
        feed = self.feed
        for letter, value in words:
            v = float(value)
            if letter == "G":
                if v in (0, 1):
                    motion = int(v)
                elif v == 90:
                    absolute = True
                elif v == 91:
                    absolute = False
                else:
                    self._line("error:20")
                    return
            elif letter == self.axis_letter:
                x = v
            elif letter in self._axes:
                others[letter] = v
            elif letter == "F":
                if v <= 0:
                    self._line("error:4")
                    return
                feed = v
            elif letter in "XYZA":
                pass  # other axes: not connected
            else:
                self._line("error:20")
                return
        if motion == 1 and feed is None:
            self._line("error:22")
            return
        self.absolute, self.feed = absolute, feed
        for other in (self.tilt_letter, self.shift_letter):  # not soft-limited here
            if other is not None and other in others:
                queued = [t for letter, t in self.queue if letter == other]
                base = queued[-1] if queued else self._rest(self._axes[other], now)
                self.queue.append((other, others[other] if absolute else base + others[other]))
        if x is not None:
            queued = [t for letter, t in self.queue if letter == self.axis_letter]
            base = queued[-1] if queued else self._rest(self.axis, now)
            target = x if absolute else base + x
            if self.soft_limits is not None and not self.soft_limits[0] <= target <= self.soft_limits[1]:
                self.axis.halt(now)
                self.queue.clear()
                self.state = "Alarm"
                self.critical = True
                self._line("ALARM:2")
                self._line("[MSG:Reset to continue]")
                return
            self.queue.append((self.axis_letter, target))
        self.update(now)
        self._line("ok")

    @staticmethod
    def _rest(axis: Axis, now: float) -> float:
        """Where ``axis`` will be once its current move is done."""
        return axis.move.target if axis.move is not None else axis.position(now)

    # -- motion -------------------------------------------------------------------
    def update(self, now: float) -> None:
        armed = self.motion_fault()
        # the axis whose move the armed fault waits for: the turntable's, or the one its ``axis`` names
        faulty = self._axes.get(str(armed[1].get("axis", self.axis_letter)).upper()) if armed else None
        move = faulty.move if faulty is not None else None
        if armed is not None and faulty is not None and move is not None:
            if move.fraction(now) >= armed[1]["at"]:
                name, spec = armed
                self.consume(name)
                if name == "door":  # someone opens the safety door (it stays open until close_door())
                    self.door_open = True
                    self._door(now)
                    return
                if name == "hold":  # someone presses the feed-hold button
                    self._suspend("Hold:0", now)
                    return
                for a in self._axes.values():
                    a.halt(now)
                if name == "vanish":
                    self.vanish()
                    return
                self.queue.clear()
                self._homing = False
                self.state = "Alarm"
                self.critical = True
                self._line(f"ALARM:{spec.get('code', 1)}")
                self._line("[MSG:Reset to continue]")
                return
        if self.state.startswith(("Hold", "Door")) or self.state == "Alarm":
            return
        if not self._busy(now):
            if self._homing:
                self._homing = False
                for a in self._axes.values():
                    a.set_position(0.0)
                self.state = "Idle"
                self._line("ok")
            elif self.queue:
                letter, target = self.queue.pop(0)
                self._axes[letter].start_move(target, now)
                self.state = "Run"
            elif self.state in ("Run", "Home"):
                self.state = "Idle"


def start_grbl_emulator(world: SimWorld | None = None, **opts: Any) -> EmulatorHandle[GrblEmulator]:
    """Start a :class:`GrblEmulator` (``opts`` are its keyword arguments) on a
    new pty; returns an :class:`~drivers.sim.pty_server.EmulatorHandle`."""
    return serve(GrblEmulator(world, **opts), name="grbl")
