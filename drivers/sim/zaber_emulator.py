"""A Zaber ASCII rotary stage (one device, one axis, or more: ``axes=2``, ``axes=3``) that speaks the real bytes.

Commands (``/`` + device + axis + command, ended by ``\\n`` or ``\\r``)::

    /1                      -> @01 0 OK IDLE -- 0
    /1 1 home               -> @01 1 OK BUSY WR 0     (moves to 0, clears WR)
    /1 1 move abs 1000      -> @01 1 OK BUSY -- 0
    /1 1 move rel -50       -> @01 1 OK BUSY -- 0
    /1 1 get pos            -> @01 1 OK BUSY -- 417   (reported while moving)
    /1 1 stop               -> @01 1 OK IDLE -- 0
    /1 warnings             -> @01 0 OK IDLE FS 01 FS
    /1 warnings clear       -> @01 0 OK IDLE FS 01 FS (then cleared)
    /1 1 get limit.max | limit.min | maxspeed | comm.alert
    /1 set comm.alert 1     (alerts ``!01 1 IDLE --`` when a move ends)
    /1 1 move abs 9e9       -> @01 1 RJ IDLE -- BADDATA
    /1 1 fly                -> @01 1 RJ IDLE -- BADCOMMAND
    /1 2 get pos            -> @01 2 RJ IDLE -- BADAXIS   (one axis; with axes=2, axis 2 is the board's
                                                          tilt: home, move abs/rel, stop, get pos,
                                                          get limit.min/limit.max)
    /1 3 move abs 209974    -> @01 3 OK BUSY -- 0     (axes=3: axis 3 is the linear stage that carries
                                                          the turntable sideways, 10 mm; the same commands)

Axes beyond the first (``axes``): ``tilt_axis`` (default 2) tilts the calibration board (degrees, in the
turntable's microsteps per degree, travel 0..:data:`TILT_TRAVEL_DEG`), ``shift_axis`` (default 3) is a
linear stage that carries the turntable sideways (``shift_microsteps_per_mm``, travel
0..:data:`SHIFT_TRAVEL_MM`); a role on an axis beyond ``axes`` or None is absent. An axis with neither
role answers as the tilt axis does and moves nothing of the world. Each role drives the world as the stage does: its motion
model, evaluated at the time asked (:meth:`SimWorld.drive_tilt`, :meth:`SimWorld.drive_shift`).

Replies end with ``\\r\\n``; the warning field shows the most severe active
flag (faults ``F*`` before warnings ``W*`` before notices ``N*``). An
optional message id after the axis is echoed; with ``checksums=True`` every
reply carries ``:XX`` (Zaber's LRC: the bytes after the type character, plus
the checksum, sum to 0 mod 256). Commands addressed to another device get no
reply, as on a daisy chain where that device is absent.

Faults (:meth:`inject`): ``"reject"`` (``RJ ... BADDATA``), ``"no_reply"``,
``"garbage"``, ``"stall"`` (stops mid-move and raises flag ``flag``, default
``FS``; use ``flag="WL"`` for an unexpected limit, ``"FQ"`` encoder error),
``"vanish"``, ``"late_reply"`` (the reply to the next command held back and sent just before the reply
to the command after it: a reply that missed the driver's timeout, arriving while the next command waits;
its message id, if any, is the earlier command's).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from drivers.settings import SEED_MAX, Setting
from drivers.sim.line_emulator import LineEmulator
from drivers.sim.motion import Axis
from drivers.sim.pty_server import serve
from drivers.sim.world import SimWorld
from drivers.zaber import X_LSM_MICROSTEPS_PER_MM

if TYPE_CHECKING:
    from drivers.sim.pty_server import EmulatorHandle

X_RSW60_MICROSTEPS_PER_DEGREE = 1536000 / 360.0  # 0.000234375 deg per microstep
TILT_TRAVEL_DEG = 90.0
"""The tilt axis's travel (``axes=2``): limit.min 0, limit.max 90 degrees (in axis 1's microsteps per degree)."""
SHIFT_TRAVEL_MM = 100.0
"""The shift axis's travel (``axes=3``): limit.min 0, limit.max 100 mm (an X-LSM100A), in its microsteps per mm."""
MAX_AXES = 9

_FLAG_ORDER = {"F": 0, "W": 1, "N": 2}

_LIMIT = (-(2**31), 2**31 - 1)
SETTINGS: dict[str, Setting] = {
    "address": Setting("device address the emulator answers to", "integer", "", 1, 99),
    "microsteps_per_degree": Setting("microsteps per degree (default: the turntable's steps_per_degree)", "number",
                                     "microsteps/deg", 0.0, 1e8, low_open=True),
    "speed_deg_s": Setting("top speed of the emulated stage", "number", "deg/s", 0.0, 100000.0, low_open=True),
    "accel_deg_s2": Setting("acceleration of the emulated stage", "number", "deg/s²", 0.0, 1e7, low_open=True),
    "limit_min": Setting("the device's limit.min (null: 0)", "integer", "microsteps", *_LIMIT, nullable=True),
    "limit_max": Setting("the device's limit.max (null: one turn)", "integer", "microsteps", *_LIMIT, nullable=True),
    "position_deg": Setting("the stage's angle at start", "number", "deg", -360.0, 360.0),
    "homed": Setting("start homed (else the WR flag is up until homing)", "boolean"),
    "alerts": Setting("send alert messages", "boolean"),
    "checksums": Setting("append checksums to replies", "boolean"),
    "seed": Setting("seed of the injected faults' timing", "integer", "", 0, SEED_MAX),
    "axes": Setting("axes of the device: 1, 2 with axis 2 tilting the calibration board (the station's "
                    "turntable tilt_axis: 2), 3 with axis 3 carrying the turntable sideways (shift_axis: 3)",
                    "integer", "", 1, MAX_AXES),
    "shift_microsteps_per_mm": Setting("microsteps per mm of the shift axis (default: the turntable's "
                                       "shift_microsteps_per_mm)", "number", "microsteps/mm", 0.0, 1e9,
                                       low_open=True),
    "shift_speed_mm_s": Setting("top speed of the emulated shift axis", "number", "mm/s", 0.0, 100000.0,
                                low_open=True),
    "shift_accel_mm_s2": Setting("acceleration of the emulated shift axis", "number", "mm/s²", 0.0, 1e7,
                                 low_open=True),
}  # fmt: skip
"""The keyword arguments of :class:`ZaberEmulator` a configuration may set (``simulation.emulator``)."""


@dataclass
class OtherAxis:
    """An axis of the device beyond the first: its motion (microsteps), its travel ``(limit.min, limit.max)``
    (microsteps) and whether it was moving at the last update (for the alert when it stops)."""

    motion: Axis
    limits: tuple[int, int]
    was_busy: bool = False


def axis_roles(axes: int, tilt_axis: int | None, shift_axis: int | None) -> tuple[int | None, int | None]:
    """``(tilt axis, shift axis)`` of a device with ``axes`` axes: each role given, if the device has that
    axis (None: no such axis); ValueError for a role on axis 1 (the turntable's) or both on one axis."""
    for key, n in (("tilt_axis", tilt_axis), ("shift_axis", shift_axis)):
        if n is not None and (isinstance(n, bool) or int(n) != n or n < 2):
            raise ValueError(f"{key} must be an axis from 2 on (axis 1 turns the stage), got {n!r}")
    if tilt_axis is not None and tilt_axis == shift_axis:
        raise ValueError(f"tilt_axis and shift_axis must be different axes, both are {tilt_axis}")
    return tuple(n if n is not None and n <= axes else None for n in (tilt_axis, shift_axis))  # type: ignore[return-value]


def axes_options(tilt_axis: int | None, shift_axis: int | None, axes: int | None = None) -> dict[str, Any]:
    """The emulator options (``axes``, ``tilt_axis``, ``shift_axis``) of a device with the axes a turntable's
    configuration names (its ``tilt_axis``, ``shift_axis``): ``{}`` for neither; ``axes`` defaults to the
    highest axis named. A role on axis 1 (the turntable's) is left out; one beyond ``axes`` is on an axis
    the device does not have, which answers ``BADAXIS`` as a real device would."""
    if tilt_axis is None and shift_axis is None:
        return {} if axes is None else {"axes": axes}
    n_axes = max(n for n in (1, tilt_axis, shift_axis) if n is not None) if axes is None else int(axes)
    roles = {
        k: (n if n is not None and n >= 2 else None) for k, n in (("tilt_axis", tilt_axis), ("shift_axis", shift_axis))
    }
    return {"axes": n_axes, **roles}


def zaber_checksum(body: bytes) -> int:
    """LRC of a message body (after the type character, before ``:``)."""
    return (-sum(body)) & 0xFF


class ZaberEmulator(LineEmulator):
    NAME = "Zaber emulator"
    COUNTED = (*LineEmulator.COUNTED, "late_reply")

    def __init__(
        self,
        world: SimWorld | None = None,
        *,
        address: int = 1,
        microsteps_per_degree: float = X_RSW60_MICROSTEPS_PER_DEGREE,
        speed_deg_s: float = 360.0,
        accel_deg_s2: float = 3600.0,
        limit_min: int | None = None,
        limit_max: int | None = None,
        position_deg: float = 0.0,
        homed: bool = False,
        alerts: bool = False,
        checksums: bool = False,
        seed: int = 0,
        axes: int = 1,
        tilt_axis: int | None = 2,
        shift_axis: int | None = 3,
        shift_microsteps_per_mm: float = X_LSM_MICROSTEPS_PER_MM,
        shift_speed_mm_s: float = 100.0,
        shift_accel_mm_s2: float = 1000.0,
    ):
        if isinstance(axes, bool) or int(axes) != axes or not 1 <= axes <= MAX_AXES:
            raise ValueError(f"axes must be 1..{MAX_AXES}, got {axes!r}")
        tilt_n, shift_n = axis_roles(int(axes), tilt_axis, shift_axis)
        super().__init__(world, seed)
        self.address = int(address)
        self.mspd = float(microsteps_per_degree)
        self.axis = Axis(position_deg * self.mspd, speed_deg_s * self.mspd, accel_deg_s2 * self.mspd)
        self.limit_min = 0 if limit_min is None else int(limit_min)
        self.limit_max = round(360 * self.mspd) if limit_max is None else int(limit_max)
        self.homed = bool(homed)
        self.alerts = bool(alerts)
        self.checksums = bool(checksums)
        self.flags: list[str] = [] if homed else ["WR"]
        self._homing = False
        self._was_busy = False
        self._late: list[bytes] = []  # replies held back by the "late_reply" fault
        self._holding = False  # the reply being made is held back
        # the axes beyond the first, each at rest at 0: the tilt (degrees), the shift (mm), others
        self.shift_mspmm = float(shift_microsteps_per_mm)
        self.others: dict[int, OtherAxis] = {}
        for n in range(2, int(axes) + 1):
            if n == shift_n:
                scale, speed, accel, travel = self.shift_mspmm, shift_speed_mm_s, shift_accel_mm_s2, SHIFT_TRAVEL_MM
            else:
                scale, speed, accel, travel = self.mspd, speed_deg_s, accel_deg_s2, TILT_TRAVEL_DEG
            self.others[n] = OtherAxis(Axis(0.0, speed * scale, accel * scale), (0, round(travel * scale)))
        self.tilt: Axis | None = None if tilt_n is None else self.others[tilt_n].motion
        """The tilt axis's motion (microsteps), or None."""
        self.shift: Axis | None = None if shift_n is None else self.others[shift_n].motion
        """The shift axis's motion (microsteps), or None."""
        if world is not None and self.tilt is not None:
            world.drive_tilt(self._tilt_for_world, self.NAME)
        if world is not None and self.shift is not None:
            world.drive_shift(self._shift_for_world, self.NAME)

    # -- helpers --------------------------------------------------------------
    def stage_degrees(self, now: float) -> float:
        return self.axis.peek(now) / self.mspd

    def _tilt_for_world(self, t: float) -> float:
        with self._lock:  # not while a command is half-way through
            return self.tilt.peek(t) / self.mspd if self.tilt is not None else 0.0

    def _shift_for_world(self, t: float) -> float:
        with self._lock:  # not while a command is half-way through
            return self.shift.peek(t) / self.shift_mspmm if self.shift is not None else 0.0

    def position_steps(self, now: float) -> int:
        return int(round(self.axis.position(now)))

    def flag(self) -> str:
        if not self.flags:
            return "--"
        return sorted(self.flags, key=lambda f: _FLAG_ORDER.get(f[0], 3))[0]

    def _send(self, kind: str, body: str) -> None:
        raw = body.encode("ascii")
        if self.checksums:
            raw += b":%02X" % zaber_checksum(raw)
        if self._holding:
            self._late.append(kind.encode() + raw + b"\r\n")
        else:
            self.write(kind.encode() + raw + b"\r\n")

    def _reply(self, axis: int, msg_id: str | None, ok: bool, data: str, now: float, flag: str | None = None) -> None:
        other = self.others.get(axis)
        moving = self.axis if other is None else other.motion
        status = "BUSY" if moving.busy(now) else "IDLE"
        ident = f" {msg_id}" if msg_id is not None else ""
        flag = self.flag() if flag is None else flag
        self._send("@", f"{self.address:02d} {axis}{ident} {'OK' if ok else 'RJ'} {status} {flag} {data}")

    @staticmethod
    def _parse(line: bytes) -> tuple[int, int, str | None, list[str]] | None:
        """(device, axis, id, words) or None if the line is not a command."""
        try:
            text = line.decode("ascii").strip()
        except UnicodeDecodeError:
            return None
        if not text.startswith("/"):
            return None
        if ":" in text:  # checksummed command: verify, drop if wrong
            body, _, cs = text[1:].rpartition(":")
            try:
                if (sum(body.encode()) + int(cs, 16)) & 0xFF:
                    return None
            except ValueError:
                return None
            text = "/" + body
        words = text[1:].split()
        nums: list[int] = []
        while words and words[0].isdigit() and len(nums) < 3:
            nums.append(int(words.pop(0)))
        device = nums[0] if nums else 0
        axis = nums[1] if len(nums) > 1 else 0
        msg_id = f"{nums[2]:02d}" if len(nums) > 2 else None
        return device, axis, msg_id, words

    # -- LineEmulator interface -----------------------------------------------
    def reject(self, line: bytes, spec: dict[str, Any], now: float) -> None:
        parsed = self._parse(line)
        if parsed is None or parsed[0] not in (0, self.address):
            return
        _, axis, msg_id, _ = parsed
        self._reply(axis, msg_id, False, spec.get("reason", "BADDATA"), now)

    def handle_line(self, line: bytes, now: float) -> None:
        parsed = self._parse(line)
        if parsed is None:
            return  # real devices ignore what is not a command
        device, axis, msg_id, words = parsed
        if device not in (0, self.address):
            return
        late, self._late = self._late, []
        for reply in late:  # an earlier command's reply, held back: it arrives now, before this one's
            self.write(reply)
        self._holding = self._take_counted("late_reply") is not None
        try:
            self._answer(axis, msg_id, words, now)
        finally:
            self._holding = False

    def _answer(self, axis: int, msg_id: str | None, words: list[str], now: float) -> None:
        if axis not in (0, 1) and axis not in self.others:
            self._reply(axis, msg_id, False, "BADAXIS", now)
            return
        flag_before = self.flag()
        ok, data = self._execute_other(self.others[axis], words, now) if axis > 1 else self._execute(words, now)
        # "warnings clear" reports the flags as they were before clearing
        self._reply(axis, msg_id, ok, data, now, flag_before if words[:2] == ["warnings", "clear"] else None)

    def _execute(self, words: list[str], now: float) -> tuple[bool, str]:
        cmd = " ".join(words)
        if not words:
            return True, "0"
        if cmd == "home":
            self.axis.start_move(0, now)
            self._homing = True
            self._arm_motion(now)
            return True, "0"
        if words[0] == "move" and len(words) == 3 and words[1] in ("abs", "rel"):
            try:
                value = int(words[2])
            except ValueError:
                return False, "BADDATA"
            target = value if words[1] == "abs" else self.position_steps(now) + value
            if not self.limit_min <= target <= self.limit_max:
                return False, "BADDATA"
            self.axis.start_move(target, now)
            self._homing = False
            self._arm_motion(now)
            return True, "0"
        if cmd == "stop":
            self.axis.halt(now)
            self._homing = False
            return True, "0"
        if cmd == "get pos":
            return True, str(self.position_steps(now))
        if words[0] == "get" and len(words) == 2:
            values = {
                "limit.max": self.limit_max,
                "limit.min": self.limit_min,
                "maxspeed": round(self.axis.vmax * 1.6384),
                "comm.alert": int(self.alerts),
            }
            if words[1] in values:
                return True, str(values[words[1]])
            return False, "BADCOMMAND"
        if words[0] == "set" and len(words) == 3 and words[1] in ("comm.alert", "maxspeed"):
            try:
                value = int(words[2])
            except ValueError:
                return False, "BADDATA"
            if words[1] == "comm.alert" and value in (0, 1):
                self.alerts = bool(value)
                return True, "0"
            if words[1] == "maxspeed" and value > 0:
                self.axis.vmax = value / 1.6384
                return True, "0"
            return False, "BADDATA"
        if words[0] == "warnings" and len(words) <= 2:
            if len(words) == 2 and words[1] != "clear":
                return False, "BADDATA"
            data = " ".join([f"{len(self.flags):02d}"] + self.flags)
            if len(words) == 2:  # WR stays until the stage is homed
                self.flags = [] if self.homed else ["WR"]
            return True, data
        return False, "BADCOMMAND"

    def _execute_other(self, other: OtherAxis, words: list[str], now: float) -> tuple[bool, str]:
        """An axis beyond the first (the tilt, the shift): home, move abs/rel, stop, get pos, get
        limit.min/limit.max."""
        motion = other.motion
        lo, hi = other.limits
        cmd = " ".join(words)
        if cmd == "home":
            motion.start_move(0, now)
            other.was_busy = True
            return True, "0"
        if words[:1] == ["move"] and len(words) == 3 and words[1] in ("abs", "rel"):
            try:
                value = int(words[2])
            except ValueError:
                return False, "BADDATA"
            target = value if words[1] == "abs" else int(round(motion.position(now))) + value
            if not lo <= target <= hi:
                return False, "BADDATA"
            motion.start_move(target, now)
            other.was_busy = True
            return True, "0"
        if cmd == "stop":
            motion.halt(now)
            return True, "0"
        if cmd == "get pos":
            return True, str(int(round(motion.position(now))))
        if cmd in ("get limit.min", "get limit.max"):
            return True, str(lo if cmd.endswith("min") else hi)
        return False, "BADCOMMAND"

    def _arm_motion(self, now: float) -> None:
        self._was_busy = True

    def update(self, now: float) -> None:
        move = self.axis.move
        if move is not None:
            armed = self.motion_fault()
            if armed is not None:
                name, spec = armed
                if move.fraction(now) >= spec["at"]:
                    self.consume(name)
                    if name == "vanish":
                        self.axis.halt(now)
                        self.vanish()
                        return
                    self.axis.halt(now)
                    self._homing = False
                    flag = spec.get("flag", "FS")
                    if flag not in self.flags:
                        self.flags.append(flag)
        busy = self.axis.busy(now)
        if self._was_busy and not busy:
            self._was_busy = False
            if self._homing:
                self._homing = False
                self.homed = True
                self.axis.set_position(0)
                if "WR" in self.flags:
                    self.flags.remove("WR")
            if self.alerts:
                self._send("!", f"{self.address:02d} 1 IDLE {self.flag()}")
        for n, other in self.others.items():
            if other.was_busy and not other.motion.busy(now):
                other.was_busy = False
                if self.alerts:
                    self._send("!", f"{self.address:02d} {n} IDLE {self.flag()}")


def start_zaber_emulator(world: SimWorld | None = None, **opts: Any) -> EmulatorHandle[ZaberEmulator]:
    """Start a :class:`ZaberEmulator` (``opts`` are its keyword arguments) on a
    new pty; returns an :class:`~drivers.sim.pty_server.EmulatorHandle`."""
    return serve(ZaberEmulator(world, **opts), name="zaber")
