"""The simulated physical world shared by the turntable emulator and the camera."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field


@dataclass
class SimWorld:
    """Ground truth of the simulated station, shared between simulators.

    The turntable emulator writes ``stage_deg`` as the stage moves; the
    simulated camera reads it (and writes ``focus`` when the driver locks
    focus). ``harp_offset_deg`` is the angle of the strings in the image
    when the stage is at 0°. Thread-safe.
    """

    stage_deg: float = 0.0
    focus: float = 0.0
    harp_offset_deg: float = 0.0
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def set_stage(self, deg: float) -> None:
        with self._lock:
            self.stage_deg = float(deg)

    def string_angle_deg(self) -> float:
        """Angle of the strings in the ideal image, in [0, 180)."""
        with self._lock:
            return (self.stage_deg + self.harp_offset_deg) % 180.0
