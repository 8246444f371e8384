"""A single-axis motor that moves with a trapezoidal velocity profile in real time."""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass


@dataclass(frozen=True)
class TrapezoidMove:
    """Rest-to-rest move from ``start`` to ``target`` beginning at time ``t0``.

    Accelerates at ``accel`` up to ``vmax``, cruises, decelerates at
    ``accel``; a short move never reaches ``vmax`` (triangular profile).
    Units are whatever the caller uses (microsteps, mm, degrees) per second.
    """

    start: float
    target: float
    vmax: float
    accel: float
    t0: float

    @property
    def distance(self) -> float:
        return abs(self.target - self.start)

    def _profile(self) -> tuple[float, float, float]:
        """(peak velocity, acceleration time, cruise time)."""
        d = self.distance
        v, a = self.vmax, self.accel
        if d * a >= v * v:  # reaches vmax
            return v, v / a, d / v - v / a
        vp = math.sqrt(d * a)
        return vp, vp / a, 0.0

    @property
    def duration(self) -> float:
        if self.distance == 0:
            return 0.0
        _, ta, tc = self._profile()
        return 2 * ta + tc

    def travelled(self, t: float) -> float:
        """Distance covered ``t`` seconds after ``t0`` (clamped to the move)."""
        d = self.distance
        if d == 0 or t <= 0:
            return 0.0
        vp, ta, tc = self._profile()
        a = self.accel
        if t < ta:
            return 0.5 * a * t * t
        da = 0.5 * a * ta * ta
        if t < ta + tc:
            return da + vp * (t - ta)
        td = t - ta - tc
        if td >= ta:
            return d
        return min(d, da + vp * tc + vp * td - 0.5 * a * td * td)

    def position(self, now: float) -> float:
        sign = 1.0 if self.target >= self.start else -1.0
        return self.start + sign * self.travelled(now - self.t0)

    def done(self, now: float) -> bool:
        return now - self.t0 >= self.duration

    def fraction(self, now: float) -> float:
        d = self.distance
        return 1.0 if d == 0 else self.travelled(now - self.t0) / d


class Axis:
    """Position of one motor axis over time; thread-safe.

    ``position(now)`` is where the axis is; ``busy(now)`` whether a move is
    under way. ``halt(now)`` freezes the axis where it is (stall, stop,
    reset). ``on_move`` is called as ``on_move(position)`` by ``update``.
    """

    def __init__(self, position: float = 0.0, vmax: float = 1.0, accel: float = 1.0):
        if vmax <= 0 or accel <= 0:
            raise ValueError(f"speed and acceleration must be positive, got {vmax}, {accel}")
        self._pos = float(position)
        self.vmax = float(vmax)
        self.accel = float(accel)
        self.move: TrapezoidMove | None = None
        self._lock = threading.RLock()

    def start_move(self, target: float, now: float) -> TrapezoidMove:
        with self._lock:
            here = self.position(now)
            self.move = TrapezoidMove(here, float(target), self.vmax, self.accel, now)
            return self.move

    def position(self, now: float) -> float:
        with self._lock:
            if self.move is None:
                return self._pos
            if self.move.done(now):
                self._pos = self.move.target
                self.move = None
                return self._pos
            return self.move.position(now)

    def peek(self, now: float) -> float:
        """Where the axis is at ``now``, without changing its state (safe from any thread)."""
        with self._lock:
            move = self.move
            return self._pos if move is None else move.position(now)

    def busy(self, now: float) -> bool:
        with self._lock:
            self.position(now)
            return self.move is not None

    def halt(self, now: float) -> float:
        with self._lock:
            self._pos = self.position(now)
            self.move = None
            return self._pos

    def set_position(self, value: float) -> None:
        with self._lock:
            self.move = None
            self._pos = float(value)
