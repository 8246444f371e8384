"""A GRBL 1.1 controller driving one rotary axis, speaking the real bytes.

Realtime bytes (no line end, no ``ok``): ``?`` status report
``<Idle|MPos:45.000,0.000,0.000|FS:0,0>`` (``Run`` while moving, ``Home``
while homing, ``Hold:0`` after ``!``, ``Alarm``), ``!`` feed hold, ``~``
cycle start (resume), Ctrl-X (0x18) soft reset, answered by the banner
``\\r\\nGrbl 1.1h ['$' for help]\\r\\n``.

Lines (ended by ``\\n`` or ``\\r``), each answered by ``ok`` or ``error:N``:
``$H`` homing (``ok`` only when the cycle is over), ``$X`` unlock
(``[MSG:Caution: Unlocked]``), ``G90``/``G91``, ``G0``/``G1`` with ``X``
(degrees, or ``units_per_degree`` units) and ``F``. Moves are queued as in
the real planner: ``ok`` means buffered, not done. With homing enabled
(``homing=True``, the default) the controller starts in ``Alarm`` and
prints ``[MSG:'$H'|'$X' to unlock]``; G-code is then refused with
``error:9``. A target outside the soft limits raises ``ALARM:2``.

Faults (:meth:`inject`): ``"reject"`` (``error:N``, ``code`` default 20),
``"no_reply"``, ``"garbage"``, ``"alarm"`` (hard limit ``ALARM:1`` at
fraction ``at`` of the next move: motion stops, ``[MSG:Reset to continue]``,
every line is ignored until Ctrl-X; then ``$X`` or ``$H``), ``"vanish"``.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

from drivers.sim.line_emulator import LineEmulator
from drivers.sim.motion import Axis
from drivers.sim.world import SimWorld

if TYPE_CHECKING:
    from drivers.sim.pty_server import EmulatorHandle

BANNER = b"\r\nGrbl 1.1h ['$' for help]\r\n"
UNLOCK_MSG = b"[MSG:'$H'|'$X' to unlock]\r\n"

_WORD = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")


class GrblEmulator(LineEmulator):
    NAME = "GRBL emulator"
    MOTION = ("alarm", "vanish")

    def __init__(
        self,
        world: SimWorld | None = None,
        *,
        units_per_degree: float = 1.0,
        speed_deg_s: float = 360.0,
        accel_deg_s2: float = 3600.0,
        soft_limits: tuple[float, float] | None = (-360.0, 720.0),
        homing: bool = True,
        position_deg: float = 0.0,
        axis: str = "X",
        seed: int = 0,
    ):
        super().__init__(world, seed)
        axis = str(axis).upper()
        if axis not in "XYZA" or len(axis) != 1:
            raise ValueError(f"GRBL emulator axis must be X, Y, Z or A, got {axis!r}")
        self.axis_letter = axis
        self.n_axes = 4 if axis == "A" else 3
        self.upd = float(units_per_degree)
        self.axis = Axis(position_deg * self.upd, speed_deg_s * self.upd, accel_deg_s2 * self.upd)
        self.soft_limits = None if soft_limits is None else tuple(v * self.upd for v in soft_limits)
        self.homing_enabled = bool(homing)
        self.state = "Alarm" if homing else "Idle"
        self.critical = False  # waiting for Ctrl-X after a hard/soft limit alarm
        self.absolute = True
        self.feed: float | None = None
        self.queue: list[float] = []
        self._homing = False
        self._held_target: float | None = None

    def stage_degrees(self, now: float) -> float:
        return self.axis.peek(now) / self.upd

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
            if self.state in ("Run", "Home"):
                move = self.axis.move
                self._held_target = move.target if move is not None else None
                self.axis.halt(now)
                self.state = "Hold:0"
            return True
        if byte == b"~":
            if self.state.startswith("Hold") and self._held_target is not None:
                self.axis.start_move(self._held_target, now)
                self._held_target = None
                self.state = "Run"
            return True
        if byte == b"\x18":
            self._reset(now)
            return True
        return False

    def _status(self, now: float) -> None:
        self.update(now)
        coords = [0.0] * self.n_axes
        coords["XYZA".index(self.axis_letter)] = self.axis.position(now)
        speed = 0.0
        move = self.axis.move
        if move is not None:
            dt = 1e-3
            speed = abs(move.position(now + dt) - move.position(now)) / dt * 60.0
        mpos = ",".join(f"{c:.3f}" for c in coords)
        self._line(f"<{self.state}|MPos:{mpos}|FS:{speed:.0f},0>")

    def _reset(self, now: float) -> None:
        moving = self.axis.busy(now) and self.state in ("Run", "Home")
        self.axis.halt(now)
        self.queue.clear()
        self._homing = False
        self._held_target = None
        self._inbuf.clear()
        if moving:
            self._line("ALARM:3")  # reset while in motion: position lost
            self.state = "Alarm"
        elif self.state != "Alarm":
            self.state = "Idle"
        self.critical = False
        self.write(BANNER)
        if self.state == "Alarm":
            self.write(UNLOCK_MSG)

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
            self.state = "Home"
            self._homing = True
            self.axis.start_move(0.0, now)  # ok is sent when the cycle ends
            return
        if text == "$X":
            if self.state == "Alarm":
                self.state = "Idle"
                self._line("[MSG:Caution: Unlocked]")
            self._line("ok")
            return
        self._line("error:3")

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
        if x is not None:
            base = (
                self.queue[-1]
                if self.queue
                else (self.axis.move.target if self.axis.move is not None else self.axis.position(now))
            )
            target = x if absolute else base + x
            if self.soft_limits is not None and not self.soft_limits[0] <= target <= self.soft_limits[1]:
                self.axis.halt(now)
                self.queue.clear()
                self.state = "Alarm"
                self.critical = True
                self._line("ALARM:2")
                self._line("[MSG:Reset to continue]")
                return
            self.queue.append(target)
            self.update(now)
        self._line("ok")

    # -- motion -------------------------------------------------------------------
    def update(self, now: float) -> None:
        move = self.axis.move
        if move is not None:
            armed = self.motion_fault()
            if armed is not None and move.fraction(now) >= armed[1]["at"]:
                name, spec = armed
                self.consume(name)
                self.axis.halt(now)
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
        if self.state.startswith("Hold") or self.state == "Alarm":
            return
        if not self.axis.busy(now):
            if self._homing:
                self._homing = False
                self.axis.set_position(0.0)
                self.state = "Idle"
                self._line("ok")
            elif self.queue:
                self.axis.start_move(self.queue.pop(0), now)
                self.state = "Run"
            elif self.state in ("Run", "Home"):
                self.state = "Idle"


def start_grbl_emulator(world: SimWorld | None = None, **opts: Any) -> EmulatorHandle[GrblEmulator]:
    """Start a :class:`GrblEmulator` (``opts`` are its keyword arguments) on a
    new pty; returns an :class:`~drivers.sim.pty_server.EmulatorHandle`."""
    from drivers.sim.pty_server import serve

    return serve(GrblEmulator(world, **opts), name="grbl")
